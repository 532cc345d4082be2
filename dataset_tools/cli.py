"""``python -m dataset_tools``: scene folders from photos or a video (SfM), synthetic scenes, mask
corruption, scene inspection and the HQ dataset."""

from __future__ import annotations

import warnings
from pathlib import Path

import click

from dataset_tools.infra.cli_support import run_cli
from dataset_tools.scene import GT_MASKS


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Scene folders: make synthetic scenes, corrupt their masks, inspect any scene."""


@cli.command()
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Scene folder to create.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--views", type=int, default=24, show_default=True)
@click.option("--res", type=int, default=256, show_default=True, help="Image width and height in pixels.")
@click.option("--objects", type=int, default=6, show_default=True)
@click.option("--path", "path_kind", type=click.Choice(["orbit", "forward"]), default="orbit", show_default=True)
@click.option("--wall/--no-wall", default=None, help="Back wall (default: only for --path forward).")
@click.option(
    "--ground",
    type=click.Choice(["checker", "speckle"]),
    default="checker",
    show_default=True,
    help="Ground texture; speckle (irregular) lets structure from motion match the views.",
)
@click.option(
    "--edit-truth",
    is_flag=True,
    help="Also render the test views without each object and each object alone (edit_truth/).",
)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
def synth(
    out: Path,
    seed: int,
    views: int,
    res: int,
    objects: int,
    path_kind: str,
    wall: bool | None,
    ground: str,
    edit_truth: bool,
    force: bool,
) -> None:
    """Ray-cast a synthetic scene with exact object masks and SfM points."""
    from dataset_tools.synth import SynthConfig, generate_scene
    from dataset_tools.synth.edit_truth import write_edit_truth

    cfg = SynthConfig(views=views, res=res, objects=objects, path=path_kind, seed=seed, wall=wall, ground=ground)
    result = generate_scene(cfg, out, overwrite=force)
    if edit_truth:
        write_edit_truth(result.root)
    click.echo(
        f"wrote {result.root}: {views} views at {res}x{res}, {objects} objects, {len(result.point_object_ids)} points3D"
    )


@cli.command()
@click.argument("photos", type=click.Path(path_type=Path))
@click.option("--out", type=click.Path(path_type=Path), required=True, help="Scene folder to write.")
@click.option("--frames", type=int, default=150, show_default=True, help="Frames to keep from a video.")
@click.option(
    "--matcher",
    type=click.Choice(["auto", "exhaustive", "sequential", "retrieval"]),
    default="auto",
    show_default=True,
    help="auto: exhaustive for up to 80 photos, retrieval (each photo with its --neighbours most alike) for "
    "more, sequential with keyframe loop closure for a video.",
)
@click.option(
    "--neighbours", type=int, default=20, show_default=True, help="Retrieval matching: photos matched with each."
)
@click.option("--mapper", type=click.Choice(["incremental", "global"]), default="incremental", show_default=True)
@click.option("--camera-model", default="SIMPLE_RADIAL", show_default=True, help="COLMAP camera model to fit.")
@click.option(
    "--single-camera/--camera-per-folder",
    default=None,
    help="One camera for every image (default for a video) or one per folder of photos (default).",
)
@click.option(
    "--max-image-size", type=int, default=3200, show_default=True, help="SIFT runs on images at most this large."
)
@click.option(
    "--peak-threshold",
    type=float,
    default=None,
    help="SIFT's peak threshold (default: COLMAP's 0.0067 for images of 1000 px and more, lower for smaller).",
)
@click.option(
    "--scale-thresholds/--colmap-thresholds",
    default=True,
    show_default=True,
    help="The incremental mapper's reprojection-error thresholds scaled to the image size like the peak "
    "threshold, or COLMAP's 4 and 12 px.",
)
@click.option(
    "--deterministic/--parallel-sift",
    default=True,
    show_default=True,
    help="SIFT and mapping on one thread, so that the same photos and --seed give the same model (COLMAP "
    "on several threads varies from run to run); --parallel-sift is faster on many cores.",
)
@click.option(
    "--seed", type=int, default=0, show_default=True, help="Seed of the two-view verification and the mapper."
)
@click.option("--force", is_flag=True, help="Make the scene again where --out already holds one.")
def sfm(photos: Path, out: Path, force: bool, **options) -> None:
    """Camera poses and a sparse model (COLMAP through pycolmap, on the CPU) for a folder of
    PHOTOS or a video; writes a scene folder. A second call continues an interrupted one."""
    from dataset_tools.sfm import SfmConfig, run_sfm

    result = run_sfm(photos, out, SfmConfig(**options), overwrite=force)
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
@click.option("--severity", type=click.Choice(["low", "medium", "high"]), default="medium", show_default=True)
@click.option(
    "--model",
    type=click.Choice(["blobs", "proposer"]),
    default="blobs",
    show_default=True,
    help="blobs: errors drawn in every view independently; proposer: parts, merges and misses over runs "
    "of views, shadow and background fragments, bleeding boundaries.",
)
@click.option("--coarse", is_flag=True, help="Low-resolution boundaries, like SAM against SAM-HQ (--model blobs).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--masks", default=GT_MASKS, show_default=True, help="Exact mask folder to corrupt.")
@click.option("--force", is_flag=True, help="Replace --out-masks if it exists.")
def corrupt(
    scene: Path, out_masks: str, severity: str, model: str, coarse: bool, seed: int, masks: str, force: bool
) -> None:
    """Write realistic imperfect copies of a scene's masks to SCENE/OUT_MASKS/."""
    from dataset_tools.corruption import corrupt_scene

    report = corrupt_scene(
        scene, out_masks, severity, model=model, coarse=coarse, seed=seed, masks=masks, overwrite=force
    )
    click.echo(
        f"wrote {scene / out_masks}: {len(report['error_per_view'])} masks, "
        f"{100 * report['mean_error']:.2f}% of pixels wrong after ID matching"
    )


@cli.command()
@click.argument("scene_dir", type=click.Path(path_type=Path))
@click.option("--images", default="images", show_default=True, help="Image folder (images or images_N).")
@click.option("--masks", default="object_mask", show_default=True, help="Mask folder to show.")
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
@click.option("--masks", default="object_mask", show_default=True, help="Object-mask folder of the scenes.")
@click.option("--revision", default=None, help="Hub revision (branch, tag or commit) to download.")
@click.option("--force", is_flag=True, help="Replace scene folders that exist in --out.")
def hq(out: Path, local: Path | None, scenes: tuple[str, ...], masks: str, revision: str | None, force: bool) -> None:
    """Fetch the 3D-Scene-Segmentation-HQ dataset and write its scenes as scene folders."""
    from dataset_tools.hq_dataset import fetch_hq

    written = fetch_hq(out, local=local, scenes=list(scenes) or None, masks=masks, revision=revision, overwrite=force)
    for path in written:
        click.echo(f"wrote {path}")


main = run_cli(cli, "python -m dataset_tools")
