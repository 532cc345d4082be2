"""The ``hqmask`` command."""

from __future__ import annotations

from pathlib import Path

import click

from dataset_tools.infra.cli_support import Registry, engine_options, field_option, given_fields, run_cli
from hqmask.build_options import ASSOCIATIONS, BuildConfig
from hqmask.sam_hq.model import DEVICES, ModelInfo


@click.group(name="hqmask", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """High-quality, multi-view consistent 2D object masks."""


@cli.command()
@click.argument("scenes", nargs=-1, required=True, type=click.Path(path_type=Path))
@field_option(
    BuildConfig, "proposer", type=Registry("hqmask.proposers.registry:PROPOSERS"), help="How masks are proposed."
)
@field_option(BuildConfig, "from_masks", help="Mask folder read by --proposer existing.")
@field_option(BuildConfig, "model", help="SAM-HQ ONNX model folder (--proposer sam-hq).")
@field_option(
    BuildConfig,
    "associate",
    type=click.Choice(ASSOCIATIONS),
    help="tracks (through SfM points), flow (optical flow and camera poses); auto: tracks where the scene "
    "has SfM observations, flow otherwise.",
)
@field_option(
    BuildConfig,
    "consensus",
    type=int,
    help="Nearest views whose ID maps, carried by optical flow, vote on each view's labels (0: off).",
)
@field_option(
    BuildConfig,
    "min_area",
    type=int,
    help="Components under this many pixels are reassigned (default: the paper's 500 px at 1008x756, "
    "scaled to each view's size).",
)
@field_option(BuildConfig, "out_masks", help="Mask folder to write inside SCENE.")
@field_option(BuildConfig, "images", help="Image folder (images or images_N).")
@field_option(BuildConfig, "dataset", help="Also write a Hugging Face dataset (with parquet shards) here.")
@field_option(BuildConfig, "force", help="Recompute cached proposals and replace existing outputs.")
@field_option(
    BuildConfig,
    "device",
    type=click.Choice(DEVICES),
    help="ONNX Runtime device for sam-hq (auto: CUDA when onnxruntime-gpu sees a GPU).",
)
@field_option(BuildConfig, "threads", type=int, help="ONNX Runtime threads for sam-hq (0: its choice).")
@field_option(
    BuildConfig,
    "points_per_side",
    type=int,
    help="Point grid of the sam-hq generator (default: SAM's).",
)
@field_option(BuildConfig, "cache_embeddings", help="Keep sam-hq image embeddings under SCENE/.hqmask_cache.")
@field_option(
    BuildConfig,
    "depth",
    help="Folder of depth maps (`gsseg render RUN --what depth --split all` writes OUT/depth): "
    "the graph proposer cuts its masks where depth jumps.",
)
@engine_options
def build(scenes: tuple[Path, ...], engine, **_) -> None:
    """Propose, clean and associate consistent object masks for every view of each SCENE.

    With --engine ray, one SCENE has its views' proposals spread over Ray workers (each loads
    the model once); several SCENEs are a task each."""
    from dataset_tools.scene import load_scene
    from hqmask.build import build_masks, build_scene

    cfg = BuildConfig(**given_fields(click.get_current_context(), BuildConfig))
    if len(scenes) > 1:  # every scene is checked before any work: a bad last scene must not cost the first ones
        for scene in scenes:
            load_scene(scene, images=cfg.images)
    if len(scenes) == 1:  # its views' proposals on the engine
        results = [build_masks(scenes[0], cfg, engine=engine)]
    else:  # one task per scene
        results = engine.map(build_scene, [(scene, cfg) for scene in scenes], desc="scenes")
    for result in results:
        click.echo(
            f"wrote {result.out_dir}: {result.views} views, {result.n_objects} objects (associated by "
            f"{result.associate})"
        )


@cli.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--masks", required=True, help="Mask folder to clean.")
@click.option("--out-masks", required=True, help="Mask folder to write.")
@click.option(
    "--min-area",
    type=int,
    default=None,
    help="Components under this many pixels are reassigned (default: 500 px at 1008x756, scaled).",
)
@click.option("--force", is_flag=True, help="Replace --out-masks if it exists.")
def clean(scene: Path, masks: str, out_masks: str, min_area: int, force: bool) -> None:
    """Noise removal alone: 3x3 closing and small-component reassignment."""
    from hqmask.build import clean_scene_masks

    click.echo(f"wrote {clean_scene_masks(scene, masks, out_masks, min_area=min_area, force=force)}")


@cli.command(name="export-onnx")
@click.option("--checkpoint", required=True, type=click.Path(path_type=Path), help="Official SAM-HQ .pth file.")
@click.option("--model-type", required=True, type=Registry("hqmask.sam_hq.export:MODEL_TYPES"))
@click.option("--out", required=True, type=click.Path(path_type=Path), help="Model folder to write.")
@field_option(ModelInfo, "opset", type=int, help="ONNX opset to export to.")
@click.option("--hq-token-only", is_flag=True, help="Use the HQ mask alone instead of adding it to SAM's.")
@click.option("--single-mask", is_flag=True, help="SAM's single-mask output instead of the best of its three.")
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
def export_onnx(
    checkpoint: Path, model_type: str, out: Path, opset: int, hq_token_only: bool, single_mask: bool, force: bool
) -> None:
    """Export an official SAM-HQ checkpoint to encoder.onnx, decoder.onnx and model.json
    (needs `pip install .[export]`)."""
    from hqmask.sam_hq.export import export_checkpoint

    export_checkpoint(
        checkpoint,
        model_type,
        out,
        opset=opset,
        hq_token_only=hq_token_only,
        multimask_output=not single_mask,
        overwrite=force,
    )
    click.echo(f"wrote {out}")


main = run_cli(cli, "hqmask")
