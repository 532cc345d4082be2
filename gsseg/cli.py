"""The ``gsseg`` command."""

from __future__ import annotations

from pathlib import Path
from typing import get_args

import click

from dataset_tools.infra.cli_support import (
    Registry,
    field_option,
    given_fields,
    none_means_off,
    other_scene_option,
    run_cli,
    switched_fields,
)
from dataset_tools.scene import Split
from gsseg.fill_options import FillOptions
from gsseg.segment.label_options import METHODS, MODES, LabelOptions
from gsseg.train.config import SCHEDULES, TrainConfig
from pipeline.demo_options import (
    EMBEDDED_ITERS,
    GAUSSIANS_PER_POINT,
    MAX_SCENE_GAUSSIANS,
    MAX_SCENE_ITERS,
    MIN_SCENE_GAUSSIANS,
    MIN_SCENE_ITERS,
    DemoOptions,
)

BACKEND = Registry("gsseg.render.backends:BACKENDS", ("auto",))
SPLITS = get_args(Split)
SCHEDULE_LENGTHS = ", ".join(f"{s.iters} on {name}" for name, s in SCHEDULES.items())
SCHEDULE_CAPS = ", ".join(f"{s.max_gaussians:,} on {name}" for name, s in SCHEDULES.items())
FILL_STEPS = field_option(
    FillOptions, "steps", "--fill-steps", type=click.IntRange(1), help="Optimisation steps of a removal's fill."
)


@click.group(name="gsseg", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Segment-aware 3D Gaussian Splatting: train, segment, edit, render."""


@cli.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--out", "run", required=True, type=click.Path(path_type=Path), help="Run folder to write.")
@field_option(
    TrainConfig,
    "masks",
    callback=none_means_off,
    help="Object-ID map folder (views without a mask train colour only); none: train colour alone.",
)
@field_option(TrainConfig, "images", help="Image folder (images or images_N).")
@field_option(
    TrainConfig,
    "iters",
    type=int,
    help=f"Iterations (default: the schedule's, {SCHEDULE_LENGTHS}); the schedule scales with it.",
)
@field_option(
    TrainConfig,
    "schedule",
    type=click.Choice(["auto", *SCHEDULES]),
    help="cpu: the short laptop schedule; gpu: the paper's 30k schedule; auto: the backend's.",
)
@field_option(TrainConfig, "backend", type=BACKEND)
@field_option(TrainConfig, "gamma_obj", type=float, help="Weight of the object cross-entropy.")
@field_option(
    TrainConfig,
    "geometry_from_masks",
    help="Let the object loss also move, reshape and densify the Gaussians (it then spends the "
    "Gaussian budget on mask noise; off: the masks train the object features alone).",
)
@field_option(
    TrainConfig,
    "opacity_reg",
    type=float,
    help="Weight of the mean opacity in the loss: Gaussians that add little fade and are pruned; 0: off.",
)
@field_option(
    TrainConfig,
    "knn_reg",
    type=float,
    help="Weight of Gaussian Grouping's 3D identity term (nearest Gaussians agree on their object); 0: off.",
)
@field_option(
    TrainConfig,
    "environment_degree",
    "--environment",
    type=click.Choice(["none", "0", "1", "2", "3"]),
    spell=lambda degree: "none" if degree is None else str(degree),
    callback=lambda ctx, param, v: None if v == "none" else int(v),
    help="SH degree of the learned background behind the Gaussians (sky, far ground); none: black.",
)
@field_option(
    TrainConfig,
    "environment_profile",
    "--environment-profile/--no-environment-profile",
    help="Add a colour per elevation angle to the background: a sharp horizon.",
)
@field_option(
    TrainConfig,
    "max_gaussians",
    type=int,
    help=f"Densification stops at this many Gaussians (default: the schedule's, {SCHEDULE_CAPS}).",
)
@field_option(TrainConfig, "seed", type=int)
@click.option(
    "--resume",
    is_flag=True,
    help="Continue the run in --out from its latest checkpoint (options given "
    "must be those it was trained with; --iters may grow).",
)
@click.option("--allow-other-scene", is_flag=True, help="With --resume, continue on another scene than the run's.")
@click.option("--stop-after", type=int, default=None, help="Checkpoint and stop at this step; continue with --resume.")
@click.option(
    "--cache-views",
    type=Registry("gsseg.train.views:CACHE_MODES"),
    default="auto",
    show_default=True,
    help="Keep the views in memory (uint8) or read them from disk a few steps ahead; auto: memory while "
    "they take at most a quarter of the RAM.",
)
def train(
    scene: Path, run: Path, resume: bool, allow_other_scene: bool, stop_after: int | None, cache_views: str, **_
) -> None:
    """Train 3D-GS jointly with 16-d object features on SCENE."""
    from gsseg.train.trainer import train as run_training

    options = given_fields(click.get_current_context(), TrainConfig)
    result = run_training(
        scene,
        run,
        TrainConfig(**options),
        resume=resume,
        given=set(options),
        stop_after=stop_after,
        other_scene=allow_other_scene,
        cache_views=cache_views,
    )
    state = "finished" if result.finished else f"stopped at step {result.step}; continue with --resume"
    click.echo(f"{result.run}: {state}, {result.num_gaussians} Gaussians, {result.seconds:.0f} s")


@cli.command()
@click.argument("run", type=click.Path(path_type=Path))
@click.option(
    "--scene",
    default=None,
    type=click.Path(path_type=Path),
    help="Scene folder whose views to render (default: the one the run was trained on).",
)
@click.option("--out", required=True, type=click.Path(path_type=Path), help="Folder to write.")
@click.option("--split", type=click.Choice(SPLITS), default="test", show_default=True)
@click.option(
    "--what",
    default="rgb,labels",
    show_default=True,
    help="Comma-separated: rgb, labels (classifier argmax), segments (labels.npz, after `gsseg segment`), "
    "depth (float32 .npy, for `hqmask build --depth`).",
)
@click.option("--colorize", is_flag=True, help="Also write colour versions of the label maps.")
@click.option("--images", default=None, help="Image folder defining the cameras (default: the run's).")
@click.option("--backend", type=BACKEND, default="auto", show_default=True)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
@other_scene_option
def render(run: Path, scene: Path, out: Path, what: str, force: bool, **options) -> None:
    """Render RGB, per-pixel classifier labels or Gaussian segments of RUN on SCENE's views."""
    from gsseg.render.views import render_run

    products = tuple(w.strip() for w in what.split(",") if w.strip())
    click.echo(f"wrote {render_run(run, scene, out, what=products, overwrite=force, **options)}")


@cli.command()
@click.argument("run", type=click.Path(path_type=Path))
@click.option(
    "--scene",
    default=None,
    type=click.Path(path_type=Path),
    help="The scene the run was trained on, where it moved (default: the recorded one).",
)
@field_option(LabelOptions, "method", type=click.Choice(METHODS))
@field_option(LabelOptions, "mode", type=click.Choice(MODES))
@field_option(LabelOptions, "gamma_p", type=float, help="Weight of the learned prior (any real).")
@field_option(LabelOptions, "slack", type=float, help="Background bias of --method flashsplat.")
@field_option(
    LabelOptions,
    "smooth",
    type=int,
    help="Gaussians with weak evidence take the label majority of this many nearest Gaussians (0: off).",
)
@field_option(LabelOptions, "fill", "--fill-interiors", help="Objects take the Gaussians they enclose.")
@click.option("--masks", default=None, help="Mask folder that votes (default: the one the run was trained on).")
@click.option("--backend", type=BACKEND, default="auto", show_default=True)
@other_scene_option
def segment(run: Path, scene: Path, masks: str, backend: str, other_scene: bool, **_) -> None:
    """Prior-guided label reassignment of every Gaussian of RUN; writes RUN/labels.npz."""
    from gsseg.run.folder import RunFolder
    from gsseg.segment.segment_run import segment_run

    options = LabelOptions(**given_fields(click.get_current_context(), LabelOptions))
    result = segment_run(run, scene, options=options, masks=masks, backend=backend, other_scene=other_scene)
    counts = {int(o): int(s.sum()) for o, s in zip(result.objects, result.selections)}
    click.echo(f"wrote {RunFolder(run).labels}: {len(result.labels)} Gaussians; per object {counts}")


def _click_options(click_help: str, exclude_help: str):
    """``--click`` and ``--exclude-click`` (VIEW U V, each repeatable), with their helps."""

    def decorate(command):
        exclude = click.option("--exclude-click", type=(str, float, float), multiple=True, help=exclude_help)
        return click.option("--click", "click_", type=(str, float, float), multiple=True, help=click_help)(
            exclude(command)
        )

    return decorate


def _clicks(click_: tuple, exclude_click: tuple) -> list:
    """The :class:`gsseg.segment.clicks.Click` list of ``--click`` and ``--exclude-click``."""
    from gsseg.segment.clicks import Click

    return [Click(v, u, w) for v, u, w in click_] + [Click(v, u, w, positive=False) for v, u, w in exclude_click]


@cli.command()
@click.argument("run", type=click.Path(path_type=Path))
@click.option("--point", type=float, nargs=3, default=None, help="X Y Z of a point on the object.")
@_click_options(
    "VIEW U V: a pixel of a view on the object; repeat it to join objects (the parts of one).",
    "VIEW U V: a pixel on what must not be selected; inside the selection it splits it.",
)
@click.option("--object-id", type=int, default=None, help="The object's label.")
@click.option("--op", type=Registry("gsseg.edits:OPS"), required=True)
@click.option("--color", type=click.IntRange(0, 255), nargs=3, default=None, help="R G B (0..255) for --op recolor.")
@click.option("--name", default=None, help="Edit folder name (default: <op>_<id>).")
@click.option(
    "--scene", default=None, type=click.Path(path_type=Path), help="Scene whose views to render (default: the run's)."
)
@click.option("--split", type=click.Choice(SPLITS), default="test", show_default=True)
@click.option(
    "--fill/--no-fill",
    default=None,
    help="Whether a removal fills what no training view saw behind the object (by default it does).",
)
@FILL_STEPS
@click.option("--backend", type=BACKEND, default="auto", show_default=True)
@click.option("--force", is_flag=True, help="Replace the edit folder if it exists.")
@other_scene_option
def edit(run: Path, point, click_, exclude_click, scene, force: bool, fill, steps, **options) -> None:
    """Select an object by a 3D point, clicks or its ID; remove, extract or recolour it."""
    from gsseg.edits import edit_run

    clicks = _clicks(click_, exclude_click)
    filling = switched_fields(click.get_current_context(), FillOptions, "fill")  # edit_run's default decides
    out = edit_run(run, point=point or None, clicks=clicks, scene_dir=scene, overwrite=force, **filling, **options)
    click.echo(f"wrote {out}")


@cli.command()
@click.argument("run", type=click.Path(path_type=Path))
@click.option("--scene", default=None, type=click.Path(path_type=Path), help="The run's scene, where it moved.")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to serve on (0.0.0.0: every interface).")
@click.option("--port", type=click.IntRange(0, 65535), default=8080, show_default=True, help="Port (0: any free one).")
@click.option(
    "--max-size",
    type=click.IntRange(16),
    default=640,
    show_default=True,
    help="Frames are rendered at most this many pixels on their long side.",
)
@FILL_STEPS
@click.option("--backend", type=BACKEND, default="auto", show_default=True)
@other_scene_option
def view(run: Path, scene: Path | None, steps: int, **options) -> None:
    """Open RUN in the browser: click an object to select it, remove / extract / recolour it, save the edit."""
    try:
        from gsseg.viewer.server import serve
    except ImportError as e:
        raise click.UsageError(f"the viewer needs viser ({e}); install it with `pip install -e .[viewer]`.") from None

    fill = FillOptions(**given_fields(click.get_current_context(), FillOptions))
    serve(run, scene_dir=scene, fill=fill, on_ready=click.echo, **options)


def _object_option(ctx: click.Context, param: click.Parameter, value: str | None) -> int | None:
    """``--object``: an object's number (1..255), or ``background`` for object 0."""
    if value is None or value == "background":
        return None if value is None else 0
    if not value.isdigit() or not 1 <= int(value) <= 255:
        hint = "; object 0 is the background: ask for it by name, --object background" if value == "0" else ""
        raise click.BadParameter(f"{value!r} is not an object number 1..255 or 'background'{hint}")
    return int(value)


@cli.command()
@click.argument("run", type=click.Path(path_type=Path))
@click.option("--out", required=True, type=click.Path(path_type=Path), help="File to write (.ply or .splat).")
@click.option(
    "--object",
    "object_id",
    default=None,
    callback=_object_option,
    help="Export this object's Gaussians alone: its number in labels.npz, or 'background'.",
)
@click.option("--point", type=float, nargs=3, default=None, help="Export the object under X Y Z alone.")
@_click_options(
    "VIEW U V: export the object clicked alone; repeat to join objects (as gsseg edit).",
    "VIEW U V: split the clicked selection there (as gsseg edit).",
)
@click.option("--edit", default=None, help="Export the model of the edit RUN/edits/EDIT (a removal with its fill).")
@click.option("--scene", default=None, type=click.Path(path_type=Path), help="The run's scene, where it moved.")
@click.option(
    "--format",
    "fmt",
    type=Registry("gsseg.export:FORMATS"),
    default=None,
    help="ply: 3D-GS PLY + a label property; splat: 32-byte records for web viewers (default: from --out).",
)
@click.option(
    "--environment/--no-environment",
    default=None,
    help="Add the learned background as a shell of Gaussians far outside the scene, so that other "
    "viewers show what `gsseg render` shows [default: for the whole model, not for one object].",
)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
def export(
    run: Path,
    out: Path,
    object_id: int | None,
    point,
    click_,
    exclude_click,
    edit: str | None,
    scene: Path | None,
    fmt: str | None,
    environment: bool | None,
    force: bool,
) -> None:
    """Write RUN's model, one object or clicked selection of it, or one of its edits, for other 3D-GS viewers."""
    from gsseg.export import export_run

    clicks = _clicks(click_, exclude_click)
    path = export_run(
        run,
        out,
        object_id=object_id,
        point=point or None,
        clicks=clicks,
        edit=edit,
        scene_dir=scene,
        fmt=fmt,
        environment=environment,
        overwrite=force,
    )
    click.echo(f"wrote {path}")


@cli.command()
@click.option("--out", default="demo", show_default=True, type=click.Path(path_type=Path), help="Folder to write.")
@field_option(
    DemoOptions,
    "scene",
    type=click.Path(path_type=Path),
    help="Your scene folder, folder of photos or video instead of the synthetic scene (photos and video "
    "go through `python -m dataset_tools sfm` first).",
)
@field_option(
    DemoOptions,
    "images",
    help=f"Image folder of --scene (default: the largest copy at most {DemoOptions.max_side} px).",
)
@field_option(
    DemoOptions,
    "iters",
    type=int,
    help=f"Training iterations [default: {EMBEDDED_ITERS} on the embedded scene; on --scene "
    f"{MIN_SCENE_ITERS}-{MAX_SCENE_ITERS}, fewer for larger views].",
)
@field_option(
    DemoOptions,
    "max_gaussians",
    type=int,
    help=f"Densification stops at this many Gaussians [default: {MIN_SCENE_GAUSSIANS:,} on the embedded "
    f"scene; on --scene {GAUSSIANS_PER_POINT}x its SfM points, {MIN_SCENE_GAUSSIANS:,}-{MAX_SCENE_GAUSSIANS:,}].",
)
@field_option(DemoOptions, "backend", type=BACKEND)
@click.option("--force", is_flag=True, help="Replace the outputs in --out.")
def demo(out: Path, force: bool, **_) -> None:
    """The whole pipeline: scene, masks, training, segmentation, a 3D-point edit, the report."""
    from pipeline.demo import run_demo

    options = DemoOptions(**given_fields(click.get_current_context(), DemoOptions))
    result = run_demo(out, options, overwrite=force)
    score = "" if result.miou is None else f"mIoU {result.miou:.3f} (visible); "
    match = "" if result.match is None else f" (ground-truth match: object {result.match})"
    click.echo(
        f"{result.edited}{match} ({result.gaussians:,} Gaussians) removed, extracted and "
        f"recoloured in {result.out / 'run' / 'edits'}; {score}{result.seconds / 60:.1f} min"
    )
    click.echo("stages: " + ", ".join(f"{stage} {seconds / 60:.1f} min" for stage, seconds in result.stages.items()))
    click.echo(f"report: {result.report}")
    click.echo(f"in the browser: gsseg view {result.out / 'run'}")
    if result.warning:
        click.echo(f"warning: {result.warning}", err=True)


main = run_cli(cli, "gsseg")
