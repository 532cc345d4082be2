"""The ``hqmask`` command."""

from __future__ import annotations

from pathlib import Path

import click

from dataset_tools.cli_support import add_planned_command, run_cli


@click.group(name="hqmask", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """High-quality, multi-view consistent 2D object masks."""


@cli.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--proposer", default="graph", show_default=True, help="graph, sam-hq or existing.")
@click.option("--from-masks", default=None, help="Mask folder read by --proposer existing.")
@click.option("--model", default=None, help="SAM-HQ ONNX model folder (--proposer sam-hq).")
@click.option("--associate", default="flow", show_default=True, help="flow (sequences) or tracks (SfM points).")
@click.option("--min-area", type=int, default=500, show_default=True, help="Components under this many pixels are reassigned.")
@click.option("--out-masks", default="object_mask", show_default=True, help="Mask folder to write inside SCENE.")
@click.option("--images", default="images", show_default=True, help="Image folder (images or images_N).")
@click.option("--dataset", default=None, help="Also write a Hugging Face dataset (with parquet shards) here.")
@click.option("--force", is_flag=True, help="Recompute cached proposals and replace existing outputs.")
def build(scene: Path, **options) -> None:
    """Propose, clean and associate consistent object masks for every view of SCENE."""
    from hqmask.build import BuildConfig, build_masks

    result = build_masks(scene, BuildConfig(**options))
    click.echo(f"wrote {result.out_dir}: {result.views} views, {result.n_objects} objects")


@cli.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--masks", required=True, help="Mask folder to clean.")
@click.option("--out-masks", required=True, help="Mask folder to write.")
@click.option("--min-area", type=int, default=500, show_default=True)
@click.option("--force", is_flag=True, help="Replace --out-masks if it exists.")
def clean(scene: Path, masks: str, out_masks: str, min_area: int, force: bool) -> None:
    """Noise removal alone: 3x3 closing and small-component reassignment."""
    from hqmask.build import clean_scene_masks

    click.echo(f"wrote {clean_scene_masks(scene, masks, out_masks, min_area=min_area, force=force)}")


add_planned_command(cli, "export-onnx", "Export an official SAM-HQ checkpoint to ONNX")

main = run_cli(cli, "hqmask")
