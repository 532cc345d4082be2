"""``python -m dataset_tools``: scene folders from photos or a video (SfM), synthetic scenes, mask
corruption, scene inspection and the HQ dataset."""

from __future__ import annotations

import warnings
from pathlib import Path

import click

from dataset_tools.corruption import FAMILIES, SEVERITY_NAMES, corrupt_scene
from dataset_tools.infra.cli_support import field_option, given_fields, run_cli
from dataset_tools.scene import IMAGES, MASKS
from dataset_tools.sfm.pipeline import (
    CAMERA_MODELS,
    EXHAUSTIVE_UP_TO,
    MAPPERS,
    MATCHERS,
    REFERENCE_SIDE,
    SIFT_PEAK_THRESHOLD,
    SfmConfig,
)
from dataset_tools.synth.generator import GROUNDS, PATHS, SynthConfig


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Scene folders: make synthetic scenes, corrupt their masks, inspect any scene."""


@cli.command()
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Scene folder to create.")
@field_option(SynthConfig, "seed", type=int)
@field_option(SynthConfig, "views", type=int)
@field_option(SynthConfig, "res", type=int, help="Image width and height in pixels.")
@field_option(SynthConfig, "objects", type=int)
@field_option(SynthConfig, "path", type=click.Choice(PATHS))
@field_option(SynthConfig, "wall", "--wall/--no-wall", help="Back wall (default: only for --path forward).")
@field_option(
    SynthConfig,
    "ground",
    type=click.Choice(GROUNDS),
    help="Ground texture; speckle (irregular) lets structure from motion match the views.",
)
@click.option(
    "--edit-truth",
    is_flag=True,
    help="Also render the test views without each object and each object alone (edit_truth/).",
)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
def synth(out: Path, edit_truth: bool, force: bool, **_) -> None:
    """Ray-cast a synthetic scene with exact object masks and SfM points."""
    from dataset_tools.synth import generate_scene
    from dataset_tools.synth.edit_truth import write_edit_truth

    cfg = SynthConfig(**given_fields(click.get_current_context(), SynthConfig))
    result = generate_scene(cfg, out, overwrite=force)
    if edit_truth:
        write_edit_truth(result.root)
    click.echo(
        f"wrote {result.root}: {cfg.views} views at {cfg.res}x{cfg.res}, {cfg.objects} objects, "
        f"{len(result.point_object_ids)} points3D"
    )


@cli.command()
@click.argument("photos", type=click.Path(path_type=Path))
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Scene folder to write.")
@field_option(SfmConfig, "frames", type=int, help="Frames to keep from a video.")
@field_option(
    SfmConfig,
    "matcher",
    type=click.Choice(MATCHERS),
    help=f"auto: exhaustive for up to {EXHAUSTIVE_UP_TO} photos, retrieval (each photo with its --neighbours "
    "most alike) for more, sequential with keyframe loop closure for a video.",
)
@field_option(SfmConfig, "neighbours", type=int, help="Retrieval matching: photos matched with each.")
@field_option(SfmConfig, "mapper", type=click.Choice(MAPPERS))
@field_option(SfmConfig, "camera_model", type=click.Choice(CAMERA_MODELS), help="COLMAP camera model to fit.")
@field_option(
    SfmConfig,
    "single_camera",
    "--single-camera/--camera-per-folder",
    help="One camera for every image (default for a video) or one per folder of photos (default).",
)
@field_option(SfmConfig, "max_image_size", type=int, help="SIFT runs on images at most this large.")
@field_option(
    SfmConfig,
    "peak_threshold",
    type=float,
    help=f"SIFT's peak threshold (default: COLMAP's {SIFT_PEAK_THRESHOLD:.4f} for images of "
    f"{REFERENCE_SIDE} px and more, lower for smaller).",
)
@field_option(
    SfmConfig,
    "scale_thresholds",
    "--scale-thresholds/--colmap-thresholds",
    help="The incremental mapper's reprojection-error thresholds scaled to the image size like the peak "
    "threshold, or COLMAP's 4 and 12 px.",
)
@field_option(
    SfmConfig,
    "deterministic",
    "--deterministic/--parallel-sift",
    help="SIFT and mapping on one thread, so that the same photos and --seed give the same model (COLMAP "
    "on several threads varies from run to run); --parallel-sift is faster on many cores.",
)
@field_option(SfmConfig, "seed", type=int, help="Seed of the two-view verification and the mapper.")
@click.option("--force", is_flag=True, help="Make the scene again where --out already holds one.")
def sfm(photos: Path, out: Path, force: bool, **_) -> None:
    """Camera poses and a sparse model (COLMAP through pycolmap, on the CPU) for a folder of
    PHOTOS or a video; writes a scene folder. A second call continues an interrupted one."""
    from dataset_tools.sfm import run_sfm

    options = SfmConfig(**given_fields(click.get_current_context(), SfmConfig))
    result = run_sfm(photos, out, options, overwrite=force)
    others = f"; other models: {result.other_models}" if result.other_models else ""
    click.echo(
        f"wrote {result.scene}: {result.registered} of {result.images} images registered in "
        f"{result.seconds:.0f} s{others}"
    )
    if result.warning():
        click.echo(f"warning: {result.warning()}", err=True)


@cli.command()
@click.option("--scene", type=click.Path(path_type=Path), required=True, help="Scene folder with exact masks.")
@click.option("--out-masks", required=True, help="Name of the mask folder to write inside the scene.")
@field_option(corrupt_scene, "severity", type=click.Choice(SEVERITY_NAMES))
@field_option(
    corrupt_scene,
    "model",
    type=click.Choice(FAMILIES),
    help="blobs: errors drawn in every view independently; proposer: parts, merges and misses over runs "
    "of views, shadow and background fragments, bleeding boundaries.",
)
@field_option(corrupt_scene, "coarse", help="Low-resolution boundaries, like SAM against SAM-HQ (--model blobs).")
@field_option(corrupt_scene, "seed", type=int)
@field_option(corrupt_scene, "masks", help="Exact mask folder to corrupt.")
@click.option("--force", is_flag=True, help="Replace --out-masks if it exists.")
def corrupt(scene: Path, out_masks: str, force: bool, **_) -> None:
    """Write realistic imperfect copies of a scene's masks to SCENE/OUT_MASKS/."""
    options = given_fields(click.get_current_context(), corrupt_scene)
    report = corrupt_scene(scene, overwrite=force, **options)  # --out-masks among them
    click.echo(
        f"wrote {scene / out_masks}: {len(report['error_per_view'])} masks, "
        f"{100 * report['mean_error']:.2f}% of pixels wrong after ID matching"
    )


@cli.command()
@click.argument("scene_dir", type=click.Path(path_type=Path))
@click.option("--images", default=IMAGES, show_default=True, help="Image folder (images or images_N).")
@click.option("--masks", default=MASKS, show_default=True, help="Mask folder to show.")
@click.option(
    "--sheet",
    type=click.Path(path_type=Path),
    default=None,
    help="Contact sheet PNG to write [default: SCENE_DIR/contact_sheet.png].",
)
def inspect(scene_dir: Path, images: str, masks: str, sheet: Path | None) -> None:
    """Print a summary of a scene folder and write a contact sheet PNG."""
    from dataset_tools.infra.overlap import refuse_overlap, scene_inputs
    from dataset_tools.inspect_scene import contact_sheet, summarize
    from dataset_tools.scene import load_scene

    sheet = sheet or scene_dir / "contact_sheet.png"
    refuse_overlap(sheet, scene_inputs(scene_dir, [masks]))
    scene = load_scene(scene_dir, images=images, masks=masks)
    if scene.mask_dir is None:
        warnings.warn(f"{scene_dir / masks}: no such mask folder; the summary shows no masks.", stacklevel=1)
    click.echo(str(summarize(scene)))
    path = contact_sheet(scene, sheet)
    click.echo(f"contact sheet {path}")


@cli.command()
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Folder for the scene folders.")
@click.option(
    "--local",
    type=click.Path(path_type=Path),
    default=None,
    help="A local copy (folder or archive) instead of downloading from the Hub.",
)
@click.option("--scene", "scenes", multiple=True, help="Convert only this scene (repeatable).")
@click.option("--masks", default=MASKS, show_default=True, help="Object-mask folder of the scenes.")
@click.option("--revision", default=None, help="Hub revision (branch, tag or commit) to download.")
@click.option("--force", is_flag=True, help="Replace scene folders that exist in --out.")
def hq(out: Path, local: Path | None, scenes: tuple[str, ...], masks: str, revision: str | None, force: bool) -> None:
    """Fetch the 3D-Scene-Segmentation-HQ dataset and write its scenes as scene folders."""
    from dataset_tools.hq_dataset import fetch_hq

    written = fetch_hq(out, local=local, scenes=list(scenes) or None, masks=masks, revision=revision, overwrite=force)
    for path in written:
        click.echo(f"wrote {path}")


main = run_cli(cli, "python -m dataset_tools")
