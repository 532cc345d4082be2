"""The ``gsseg`` command."""

from __future__ import annotations

from pathlib import Path

import click
from click.core import ParameterSource

from dataset_tools.infra.cli_support import none_means_off, other_scene_option, run_cli
from gsseg.train_config import DEMO_ITERS, DEMO_MAX_GAUSSIANS, DEMO_SCENE_ITERS


@click.group(name="gsseg", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Segment-aware 3D Gaussian Splatting: train, segment, edit, render."""


@cli.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--out", "run", required=True, type=click.Path(path_type=Path), help="Run folder to write.")
@click.option(
    "--masks",
    default="object_mask",
    show_default=True,
    callback=none_means_off,
    help="Object-ID map folder (views without a mask train colour only); none: train colour alone.",
)
@click.option("--images", default="images", show_default=True, help="Image folder (images or images_N).")
@click.option(
    "--iters",
    type=int,
    default=None,
    help="Iterations (default: 3000 on cpu, 30000 with gsplat); the schedule scales with it.",
)
@click.option(
    "--schedule",
    type=click.Choice(["auto", "cpu", "gpu"]),
    default="auto",
    show_default=True,
    help="cpu: the short laptop schedule; gpu: the paper's 30k schedule; auto picks by backend.",
)
@click.option("--backend", type=click.Choice(["auto", "cpu", "torch", "gsplat"]), default="auto", show_default=True)
@click.option("--gamma-obj", type=float, default=1.0, show_default=True, help="Weight of the object cross-entropy.")
@click.option(
    "--geometry-from-masks",
    is_flag=True,
    help="Let the object loss also move, reshape and densify the Gaussians (it then spends the "
    "Gaussian budget on mask noise; off: the masks train the object features alone).",
)
@click.option(
    "--knn-reg",
    type=float,
    default=0.0,
    show_default=True,
    help="Weight of Gaussian Grouping's 3D identity term (nearest Gaussians agree on their object); 0: off.",
)
@click.option(
    "--environment",
    "environment_degree",
    type=click.Choice(["none", "0", "1", "2", "3"]),
    default="3",
    show_default=True,
    callback=lambda ctx, param, v: None if v == "none" else int(v),
    help="SH degree of the learned background behind the Gaussians (sky, far ground); none: black.",
)
@click.option(
    "--environment-profile/--no-environment-profile",
    default=True,
    show_default=True,
    help="Add a colour per elevation angle to the background: a sharp horizon.",
)
@click.option(
    "--max-gaussians",
    type=int,
    default=None,
    help="Densification stops at this many Gaussians (default: 150 000 on the cpu schedule, 6 000 000 on gpu).",
)
@click.option("--seed", type=int, default=0, show_default=True)
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
    type=click.Choice(["auto", "memory", "disk"]),
    default="auto",
    show_default=True,
    help="Keep the views in memory (uint8) or read them from disk a few steps ahead; auto: memory while "
    "they take at most a quarter of the RAM.",
)
def train(
    scene: Path,
    run: Path,
    schedule: str,
    resume: bool,
    allow_other_scene: bool,
    stop_after: int | None,
    cache_views: str,
    **options,
) -> None:
    """Train 3D-GS jointly with 16-d object features on SCENE."""
    from gsseg.render import get_backend
    from gsseg.train import TrainConfig
    from gsseg.train import train as run_training

    ctx = click.get_current_context()
    given = {name for name in ("schedule", *options) if ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE}
    if schedule == "auto":
        schedule = get_backend(options["backend"]).default_schedule
    result = run_training(
        scene,
        run,
        TrainConfig(schedule=schedule, **options),
        resume=resume,
        given=given,
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
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option(
    "--what",
    default="rgb,labels",
    show_default=True,
    help="Comma-separated: rgb, labels (classifier argmax), segments (labels.npz, after `gsseg segment`), "
    "depth (float32 .npy, for `hqmask build --depth`).",
)
@click.option("--colorize", is_flag=True, help="Also write colour versions of the label maps.")
@click.option("--images", default=None, help="Image folder defining the cameras (default: the run's).")
@click.option("--backend", type=click.Choice(["auto", "cpu", "torch", "gsplat"]), default="auto", show_default=True)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
@other_scene_option
def render(run: Path, scene: Path, out: Path, what: str, force: bool, **options) -> None:
    """Render RGB, per-pixel classifier labels or Gaussian segments of RUN on SCENE's views."""
    from gsseg.render_views import render_run

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
@click.option("--method", type=click.Choice(["prior", "flashsplat", "classifier"]), default="prior", show_default=True)
@click.option("--mode", type=click.Choice(["multi", "binary"]), default="multi", show_default=True)
@click.option("--gamma-p", type=float, default=0.2, show_default=True, help="Weight of the learned prior (any real).")
@click.option("--slack", type=float, default=0.0, show_default=True, help="Background bias of --method flashsplat.")
@click.option(
    "--smooth",
    type=int,
    default=0,
    show_default=True,
    help="Gaussians with weak evidence take the label majority of this many nearest Gaussians (0: off).",
)
@click.option("--fill-interiors", "fill", is_flag=True, help="Objects take the Gaussians they enclose.")
@click.option("--masks", default=None, help="Mask folder that votes (default: the one the run was trained on).")
@click.option("--backend", type=click.Choice(["auto", "cpu", "torch", "gsplat"]), default="auto", show_default=True)
@other_scene_option
def segment(run: Path, scene: Path, masks: str, backend: str, other_scene: bool, **options) -> None:
    """Prior-guided label reassignment of every Gaussian of RUN; writes RUN/labels.npz."""
    from gsseg.run_folder import RunFolder
    from gsseg.segment.segment_run import LabelOptions, segment_run

    result = segment_run(
        run, scene, options=LabelOptions(**options), masks=masks, backend=backend, other_scene=other_scene
    )
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
@click.option("--op", type=click.Choice(["remove", "extract", "recolor"]), required=True)
@click.option("--color", type=click.IntRange(0, 255), nargs=3, default=None, help="R G B (0..255) for --op recolor.")
@click.option("--name", default=None, help="Edit folder name (default: <op>_<id>).")
@click.option(
    "--scene", default=None, type=click.Path(path_type=Path), help="Scene whose views to render (default: the run's)."
)
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--backend", type=click.Choice(["auto", "cpu", "torch", "gsplat"]), default="auto", show_default=True)
@click.option("--force", is_flag=True, help="Replace the edit folder if it exists.")
@other_scene_option
def edit(run: Path, point, click_, exclude_click, scene, force: bool, **options) -> None:
    """Select an object by a 3D point, clicks or its ID; remove, extract or recolour it."""
    from gsseg.edits import edit_run

    clicks = _clicks(click_, exclude_click)
    out = edit_run(run, point=point or None, clicks=clicks, scene_dir=scene, overwrite=force, **options)
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
@click.option("--backend", type=click.Choice(["auto", "cpu", "torch", "gsplat"]), default="auto", show_default=True)
@other_scene_option
def view(run: Path, scene: Path | None, **options) -> None:
    """Open RUN in the browser: click an object to select it, remove / extract / recolour it, save the edit."""
    try:
        from gsseg.viewer.server import serve
    except ImportError as e:
        raise click.UsageError(f"the viewer needs viser ({e}); install it with `pip install -e .[viewer]`.") from None

    serve(run, scene_dir=scene, on_ready=click.echo, **options)


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
@click.option("--scene", default=None, type=click.Path(path_type=Path), help="The run's scene, where it moved.")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["ply", "splat"]),
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
    scene: Path | None,
    fmt: str | None,
    environment: bool | None,
    force: bool,
) -> None:
    """Write RUN's model, or one object or clicked selection of it, for other 3D-GS viewers."""
    from gsseg.export import export_run

    clicks = _clicks(click_, exclude_click)
    path = export_run(
        run,
        out,
        object_id=object_id,
        point=point or None,
        clicks=clicks,
        scene_dir=scene,
        fmt=fmt,
        environment=environment,
        overwrite=force,
    )
    click.echo(f"wrote {path}")


@cli.command()
@click.option("--out", default="demo", show_default=True, type=click.Path(path_type=Path), help="Folder to write.")
@click.option(
    "--scene",
    default=None,
    type=click.Path(path_type=Path),
    help="Your scene folder, folder of photos or video instead of the synthetic scene (photos and video "
    "go through `python -m dataset_tools sfm` first).",
)
@click.option("--images", default=None, help="Image folder of --scene (default: the largest copy at most 640 px).")
@click.option(
    "--iters",
    type=int,
    default=None,
    help=f"Training iterations [default: {DEMO_ITERS} on the embedded scene, {DEMO_SCENE_ITERS} on --scene].",
)
@click.option(
    "--max-gaussians",
    type=int,
    default=DEMO_MAX_GAUSSIANS,
    show_default=True,
    help="Densification stops at this many Gaussians.",
)
@click.option("--backend", type=click.Choice(["auto", "cpu", "torch", "gsplat"]), default="auto", show_default=True)
@click.option("--force", is_flag=True, help="Replace the outputs in --out.")
def demo(
    out: Path, scene: Path | None, images: str | None, iters: int | None, max_gaussians: int, backend: str, force: bool
) -> None:
    """The whole pipeline: scene, masks, training, segmentation, a 3D-point edit, the report."""
    from pipeline.demo import run_demo

    result = run_demo(
        out, scene=scene, images=images, iters=iters, max_gaussians=max_gaussians, backend=backend, overwrite=force
    )
    score = "" if result.miou is None else f"mIoU {result.miou:.3f} (visible); "
    match = "" if result.match is None else f" (ground-truth match: object {result.match})"
    click.echo(
        f"{result.edited}{match} ({result.gaussians:,} Gaussians) removed, extracted and "
        f"recoloured in {result.out / 'run' / 'edits'}; {score}{result.seconds / 60:.1f} min"
    )
    click.echo(f"report: {result.report}")
    click.echo(f"in the browser: gsseg view {result.out / 'run'}")
    if result.warning:
        click.echo(f"warning: {result.warning}", err=True)


main = run_cli(cli, "gsseg")
