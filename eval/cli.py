"""The ``gseval`` command."""

from __future__ import annotations

from pathlib import Path
from typing import get_args

import click

from dataset_tools.infra.cli_support import (
    Registry,
    engine_options,
    field_option,
    none_means_off,
    other_scene_option,
    run_cli,
    switched_fields,
)
from dataset_tools.scene import GT_MASKS, Split
from eval.lpips import NETS, export_lpips
from gsseg.fill_options import FillOptions

BACKEND = Registry("gsseg.render.backends:BACKENDS", ("auto",))


@click.group(name="gseval", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Metrics, reports and paper-table benchmarks."""


@cli.command()
@click.argument("run", type=click.Path(path_type=Path))
@click.option("--scene", required=True, type=click.Path(path_type=Path), help="The scene the run was trained on.")
@click.option("--out", required=True, type=click.Path(path_type=Path), help="Report folder to write.")
@click.option(
    "--gt-masks",
    default=GT_MASKS,
    show_default=True,
    callback=none_means_off,
    help="Ground-truth mask folder of SCENE; none: image metrics only.",
)
@click.option(
    "--split", type=click.Choice(get_args(Split)), default="test", show_default=True, help="Views to evaluate."
)
@click.option("--object-id", type=int, default=None, help="Label to edit in the image rows (default: the largest).")
@click.option(
    "--color",
    nargs=3,
    type=click.IntRange(0, 255),
    default=(255, 40, 200),
    show_default=True,
    help="Recolour target, 0..255.",
)
@click.option("--backend", type=BACKEND, default="auto", show_default=True)
@click.option(
    "--lpips",
    type=click.Path(path_type=Path),
    default=None,
    help="LPIPS network (ONNX, from `gseval export-lpips`); without it LPIPS is n/a.",
)
@click.option(
    "--fill/--no-fill",
    default=None,
    help="Whether the removal shown fills what no training view saw behind the object, as `gsseg edit` does "
    "(by default it does).",
)
@field_option(
    FillOptions, "steps", "--fill-steps", type=click.IntRange(1), help="Optimisation steps of the removal's fill."
)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
@other_scene_option
def report(
    run: Path,
    scene: Path,
    out: Path,
    gt_masks: str,
    split: str,
    object_id: int | None,
    color: tuple[int, int, int],
    backend: str,
    lpips: Path | None,
    fill: bool | None,
    steps: int,
    force: bool,
    other_scene: bool,
) -> None:
    """Metrics (visible and extracted mIoU/mAcc, PSNR, SSIM) and a markdown/HTML report of RUN."""
    from eval.report import report_run

    ev = report_run(
        run,
        scene,
        out,
        gt_masks=gt_masks,
        split=split,
        object_id=object_id,
        color=color,
        backend=backend,
        lpips=lpips,
        overwrite=force,
        other_scene=other_scene,
        **switched_fields(click.get_current_context(), FillOptions, "fill"),  # report_run's default decides
    )
    s = ev.summary()
    scores = (
        f"mIoU visible {s['visible']['miou']:.3f}, extracted {s['extracted']['miou']:.3f}; "
        if s["visible"]["miou"] is not None
        else ""
    )
    click.echo(f"{scores}PSNR {s['psnr']:.2f} dB over {s['views']} views")
    click.echo(f"wrote {out / 'report.html'}")


@cli.command()
@click.argument("runs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", default=None, type=click.Path(path_type=Path), help="Also write the table to this .md file.")
def compare(runs: tuple[Path, ...], out: Path | None) -> None:
    """Put the evaluations of several reported runs side by side (markdown)."""
    from dataset_tools.infra.atomic import write_bytes_atomic
    from dataset_tools.infra.overlap import refuse_overlap, run_inputs
    from eval.report import compare_runs

    if out is not None:
        refuse_overlap(out, [p for run in runs for p in run_inputs(run)])
    table = compare_runs(list(runs))
    click.echo(table)
    if out is not None:
        write_bytes_atomic(out, (table + "\n").encode())


@cli.command("paper-tables")
@click.option("--out", required=True, type=click.Path(path_type=Path), help="Folder for the tables and the work.")
@click.option("--quick", is_flag=True, help="Two small scenes and a short schedule (about 10 minutes on 2 cores).")
@click.option("--backend", type=BACKEND, default="auto", show_default=True)
@engine_options
def paper_tables(out: Path, quick: bool, backend: str, engine) -> None:
    """The analogs of the paper's tables on synthetic scenes (markdown and JSON); rerunning
    reuses the finished work in OUT/work."""
    from pipeline.paper_tables import SETUPS
    from pipeline.paper_tables import paper_tables as run_tables

    path = run_tables(out, setup=SETUPS["quick" if quick else "full"], backend=backend, engine=engine)
    click.echo(path.read_text())
    click.echo(f"wrote {path} and {path.with_suffix('.json')}")


@cli.command("export-lpips")
@click.option("--out", required=True, type=click.Path(path_type=Path), help="ONNX file to write.")
@field_option(export_lpips, "net", type=click.Choice(NETS))
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
def export_lpips_cmd(out: Path, net: str, force: bool) -> None:
    """Write the lpips package's network as ONNX for `gseval report --lpips` (needs `pip install lpips`)."""
    from eval.lpips import export_lpips

    click.echo(f"wrote {export_lpips(out, net, overwrite=force)}")


main = run_cli(cli, "gseval")
