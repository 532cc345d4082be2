"""The census of bad inputs and faults: every mistake a user can make with the four commands
(damaged COLMAP models, images, masks and run files made here, bad options, outputs that are
paths, stale or foreign inputs) ends in exit code 2 and one line ``error: ...``, without a
traceback, and leaves every file of the test's world as it was. Cases run in-process through
each command's real entry point; the interruption and two-writer cases run real processes."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import scene_with_exact_masks, script
from PIL import Image

import dataset_tools.cli
import eval.cli
import gsseg.cli
import hqmask.cli
from dataset_tools.image_files import read_image, read_mask, write_png
from dataset_tools.synth import SynthConfig

pytestmark = pytest.mark.slow  # 128 commands run in-process: about 3 minutes on 2 cores

ENTRY = {
    "dataset_tools": dataset_tools.cli.main,
    "hqmask": hqmask.cli.main,
    "gsseg": gsseg.cli.main,
    "gseval": eval.cli.main,
}


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, symlinks=True)
    return dst


def _damage_scenes(world: Path) -> None:
    scene = world / "scene"
    first = sorted((scene / "images").iterdir())[1]  # a train view ([0] is the test view)
    sparse = Path("sparse") / "0"

    def variant(name: str) -> Path:
        return _copy(scene, world / name)

    (variant("no_sparse") / "sparse").rename(world / "no_sparse" / "elsewhere")
    cams = variant("cut_cameras") / sparse / "cameras.bin"
    cams.write_bytes(cams.read_bytes()[: len(cams.read_bytes()) // 2])
    (variant("no_images_bin") / sparse / "images.bin").unlink()
    (variant("junk_points") / sparse / "points3D.bin").write_bytes(os.urandom(300))
    (variant("empty_points") / sparse / "points3D.bin").write_bytes(b"")
    (variant("missing_image") / "images" / first.name).unlink()
    png = variant("cut_image") / "images" / first.name
    png.write_bytes(png.read_bytes()[: len(png.read_bytes()) // 2])
    (variant("text_image") / "images" / first.name).write_text("not an image")
    write_png(variant("wide_image") / "images" / first.name, read_image(first)[:40])
    mask = first.stem + ".png"
    write_png(variant("rgb_mask") / "object_mask" / mask, np.zeros((64, 64, 3), np.uint8))
    Image.fromarray(np.full((64, 64), 300, np.uint16)).save(variant("wide_mask") / "object_mask" / mask)
    write_png(variant("small_mask") / "object_mask" / mask, np.zeros((30, 30), np.uint8))
    cut = variant("cut_mask") / "object_mask" / mask
    cut.write_bytes(cut.read_bytes()[:40])
    (variant("bad_json") / "scene.json").write_text("{ not json")
    (variant("bad_split") / "scene.json").write_text(json.dumps({"split": {"test": ["nope.png"]}}))
    (variant("string_split") / "scene.json").write_text(json.dumps({"split": {"test": "./0.png"}}))
    other = scene_with_exact_masks(SynthConfig(views=5, res=64, objects=2, seed=9), world / "other").root
    assert other.is_dir()
    same_names = variant("same_names")  # the same views, one photo changed
    image = read_image(first)
    write_png(same_names / "images" / first.name, 255 - image)
    moved = variant("moved_camera")  # the same photos, one camera's focal length changed
    _scale_focal(moved / sparse)
    (variant("all_test") / "scene.json").write_text(
        json.dumps({"split": {"test": sorted(p.name for p in (scene / "images").iterdir())}})
    )
    short = variant("short_cameras") / sparse / "cameras.bin"
    short.write_bytes(short.read_bytes()[:-8])  # the last parameter cut: pycolmap still reads it


def _scale_focal(sparse: Path) -> None:
    import pycolmap

    model = pycolmap.Reconstruction(str(sparse))
    camera = next(iter(model.cameras.values()))
    params = camera.params.copy()
    params[0] *= 1.1
    camera.params = params
    model.write(str(sparse))


def _damage_runs(world: Path) -> None:
    run = world / "run"

    def variant(name: str) -> Path:
        return _copy(run, world / name)

    (variant("cut_config") / "config.json").write_text('{"schedule": ')
    (variant("junk_classifier") / "classifier.pt").write_bytes(b"garbage" * 10)
    ply = variant("cut_ply") / "gaussians.ply"
    ply.write_bytes(ply.read_bytes()[:300])
    from gsseg.model.ply import read_ply, write_ply

    g = read_ply(run / "gaussians.ply")
    g.means[0, 0] = float("nan")
    write_ply(g, variant("nan_ply") / "gaussians.ply")
    (variant("no_labels") / "labels.npz").unlink()
    (variant("junk_labels") / "labels.npz").write_bytes(b"PK\x03\x04 not a zip")
    stale = variant("stale_labels") / "labels.npz"
    with np.load(stale) as f:
        data = dict(f)
    data["labels"] = data["labels"][:-3]
    data["selections"] = data["selections"][:, :-3]
    np.savez(stale, **data)
    (variant("cut_evaluation") / "evaluation.json").write_text('{"summary": ')
    (variant("odd_evaluation") / "evaluation.json").write_text(json.dumps({"format_version": 1, "views": 3}))
    metrics = variant("odd_metrics") / "metrics.json"
    metrics.write_text(json.dumps({**json.loads(metrics.read_text()), "train": {"history": [1, 2]}}))
    moved = variant("moved_scene") / "config.json"
    moved.write_text(json.dumps({**json.loads(moved.read_text()), "scene": str(world / "gone")}))
    no_checkpoints = variant("no_checkpoints")
    shutil.rmtree(no_checkpoints / "checkpoints")
    import torch

    keyless = variant("keyless_checkpoint")
    for path in (keyless / "checkpoints").glob("*.pt"):
        torch.save({"step": 3}, path)
    unfinished = world / "unfinished"
    unfinished.mkdir()
    shutil.copy(run / "config.json", unfinished / "config.json")
    (unfinished / "checkpoints").mkdir()
    (unfinished / "checkpoints" / "step_0000003.pt").write_bytes(b"")
    model = world / "model"
    model.mkdir()
    for name in ("encoder.onnx", "decoder.onnx"):
        (model / name).write_bytes(b"")
    (model / "model.json").write_text(json.dumps({"model_type": "vit_b", "image_size": -5}))
    (world / "a_file").write_text("a file where a folder is needed")
    (world / "lpips.onnx").write_bytes(b"not onnx")


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    """A tiny scene, a run trained on it for a few steps and segmented and reported, and a
    damaged copy of each for every way a file can be wrong."""
    from eval.report import report_run
    from gsseg.segment.segment_run import segment_run
    from gsseg.train.config import TrainConfig
    from gsseg.train.trainer import train

    world = tmp_path_factory.mktemp("world")
    scene = scene_with_exact_masks(SynthConfig(views=6, res=64, objects=3, seed=2), world / "scene").root
    train(scene, world / "run", TrainConfig(iters=5, backend="cpu"), progress=False)
    segment_run(world / "run", scene, backend="cpu", progress=False)
    report_run(world / "run", scene, world / "report", backend="cpu", fill=None, progress=False)
    _damage_scenes(world)
    _damage_runs(world)
    return world


CASES = [
    # python -m dataset_tools
    ("dataset_tools", "synth --out {w}/new --objects 0", "1..255 objects"),
    ("dataset_tools", "synth --out {w}/new --objects 300", "1..255 objects"),
    ("dataset_tools", "synth --out {w}/new --views 1", "at least 2 views"),
    ("dataset_tools", "synth --out {w}/new --res 8", "16..4096"),
    ("dataset_tools", "synth --out {w}/scene", "already exists"),
    ("dataset_tools", "synth --out {w}/a_file", "already exists"),
    ("dataset_tools", "synth --out {w}/new --path sideways", "sideways"),
    ("dataset_tools", "corrupt --scene {w}/nowhere --out-masks n", "scene folder not found"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks ../escape", "plain folder name"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks .", "plain folder name"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks gt_mask", "which this command reads"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks n --severity extreme", "extreme"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks n --model random", "random"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks n --model proposer --coarse", "--coarse"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks n --masks nothing", "no masks to corrupt"),
    ("dataset_tools", "inspect {w}/nowhere", "scene folder not found"),
    ("dataset_tools", "inspect {w}/no_sparse", "COLMAP model folder not found"),
    ("dataset_tools", "inspect {w}/cut_cameras", "the model is damaged"),
    ("dataset_tools", "inspect {w}/no_images_bin", "not a readable COLMAP model"),
    ("dataset_tools", "inspect {w}/junk_points", "too short for the records its header counts"),
    ("dataset_tools", "inspect {w}/empty_points", "too short for the records its header counts"),
    ("dataset_tools", "inspect {w}/string_split", "split.test is str, not a list of view names"),
    ("dataset_tools", "synth --out {w}/new --seed -1", "give a seed of 0 or more"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks n --seed -1", "give a seed of 0 or more"),
    ("dataset_tools", "corrupt --scene {w}/scene --masks object_mask --out-masks gt_mask --force", "ground truth"),
    ("dataset_tools", "inspect {w}/missing_image", "missing on disk"),
    ("dataset_tools", "inspect {w}/text_image", "not a readable image"),
    ("dataset_tools", "inspect {w}/bad_json", "not valid JSON"),
    ("dataset_tools", "inspect {w}/bad_split", "split.test names views that do not exist"),
    ("dataset_tools", "inspect {w}/scene --images images_9", "image folder not found"),
    ("dataset_tools", "hq --out {w}/hq --local {w}/nowhere", "no such"),
    ("dataset_tools", "hq --out {w}/hq --local {w}/a_file", ""),
    # hqmask
    ("hqmask", "build {w}/nowhere", "scene folder not found"),
    ("hqmask", "build {w}/scene {w}/nowhere --out-masks n", "scene folder not found"),
    ("hqmask", "build {w}/scene --engine spark", "spark"),
    ("hqmask", "build {w}/scene --address 10.0.0.1:6379", "with --engine ray"),
    ("hqmask", "build {w}/scene --proposer nope", "nope"),
    ("hqmask", "build {w}/scene --out-masks gt_mask --force", "holds ground truth"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks gt_mask --force", "holds ground truth"),
    ("hqmask", "build {w}/scene --out-masks n --depth {w}/nowhere", "depth folder not found"),
    ("hqmask", "build {w}/scene --out-masks n --depth {w}/run", "depth map not found"),
    (
        "hqmask",
        "build {w}/scene --out-masks n --proposer existing --from-masks object_mask --depth {w}/run",
        "only the graph proposer",
    ),
    ("hqmask", "build {w}/scene --associate nope", "nope"),
    ("hqmask", "build {w}/scene --min-area -5", "--min-area -5"),
    ("hqmask", "build {w}/scene --min-area 0", "--min-area 0"),
    ("hqmask", "build {w}/scene --consensus -1", "--consensus -1"),
    ("hqmask", "build {w}/scene --points-per-side 0", "--points-per-side 0"),
    ("hqmask", "build {w}/scene --threads -1", "--threads -1"),
    ("hqmask", "build {w}/scene --proposer existing", "needs --from-masks"),
    ("hqmask", "build {w}/scene --proposer existing --from-masks nothing --out-masks n", "mask folder not found"),
    ("hqmask", "build {w}/scene --proposer existing --from-masks object_mask", "which this command reads"),
    ("hqmask", "build {w}/scene --out-masks ../escape", "plain folder name"),
    ("hqmask", "build {w}/scene --out-masks .", "plain folder name"),
    ("hqmask", "build {w}/scene --out-masks images", "which this command reads"),
    ("hqmask", "build {w}/scene --out-masks n --dataset {w}/run", "already exists"),
    ("hqmask", "build {w}/scene --out-masks n --proposer sam-hq", "needs --model"),
    ("hqmask", "build {w}/scene --out-masks n --proposer sam-hq --model {w}/nowhere", "nowhere"),
    ("hqmask", "build {w}/scene --out-masks n --proposer sam-hq --model {w}/model", "image_size"),
    ("hqmask", "build {w}/scene --out-masks n --images images_9", "image folder not found"),
    ("hqmask", "build {w}/cut_image --out-masks n", "cannot read this image"),
    ("hqmask", "build {w}/wide_image --out-masks n", "does not match the model"),
    ("hqmask", "build {w}/rgb_mask --out-masks n --proposer existing --from-masks object_mask", "3 channels"),
    ("hqmask", "build {w}/wide_mask --out-masks n --proposer existing --from-masks object_mask", "more than the 255"),
    ("hqmask", "build {w}/small_mask --out-masks n --proposer existing --from-masks object_mask", "masks must have"),
    (
        "hqmask",
        "build {w}/cut_mask --out-masks n --proposer existing --from-masks object_mask",
        "cannot read this mask",
    ),
    ("hqmask", "build {w}/no_sparse --out-masks n", "COLMAP model folder not found"),
    ("hqmask", "clean {w}/scene --masks nothing --out-masks n", "mask folder not found"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks ../escape", "plain folder name"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks n --min-area -5", "--min-area -5"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks images", "which this command reads"),
    ("hqmask", "export-onnx --checkpoint {w}/nowhere.pth --model-type vit_b --out {w}/exported", ""),
    # gsseg train
    ("gsseg", "train {w}/nowhere --out {w}/new", "scene folder not found"),
    ("gsseg", "train {w}/scene --out {w}/new --iters 0", "--iters 0: give 1 to 10,000,000 iterations"),
    ("gsseg", "train {w}/scene --out {w}/new --iters 99999999999999999999", "give 1 to 10,000,000 iterations"),
    ("gsseg", "train {w}/scene --out {w}/new --seed -1", "--seed -1: give a seed of 0 or more"),
    ("gsseg", "train {w}/scene --out {w}/new/sub/run --masks objectmask", "mask folder not found"),
    ("gsseg", "train {w}/scene --out {w}/no_checkpoints --iters 10 --resume", "a finished model but no checkpoints"),
    ("gsseg", "train {w}/scene --out {w}/keyless_checkpoint --iters 10 --resume", "damaged checkpoint (KeyError"),
    ("gsseg", "render {w}/run --out {w}/new --what ,", "(none given)"),
    ("gsseg", "train {w}/scene --out {w}/new --stop-after 0", "--stop-after 0"),
    ("gsseg", "train {w}/scene --out {w}/new --stop-after -5", "--stop-after -5"),
    ("gsseg", "train {w}/scene --out {w}/new --max-gaussians 0", "--max-gaussians"),
    ("gsseg", "train {w}/scene --out {w}/new --gamma-obj nan", "--gamma-obj nan"),
    ("gsseg", "train {w}/scene --out {w}/new --gamma-obj -1", "--gamma-obj -1"),
    ("gsseg", "train {w}/scene --out {w}/new --masks objectmask", "mask folder not found"),
    ("gsseg", "train {w}/scene --out {w}/new --backend opengl", "opengl"),
    ("gsseg", "train {w}/scene --out {w}/new --backend gsplat", "gsplat"),
    ("gsseg", "train {w}/scene --out {w}/new --environment 5", "5"),
    ("gsseg", "train {w}/scene --out {w}/a_file", "a file stands there"),
    ("gsseg", "train {w}/scene --out {w}/run", "already holds a run"),
    ("gsseg", "train {w}/scene --out {w}/new --resume", "holds no run to resume"),
    ("gsseg", "train {w}/other --out {w}/unfinished --resume", "was trained on"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume", "damaged checkpoint"),
    ("gsseg", "train {w}/cut_image --out {w}/new", "cannot read this image"),
    ("gsseg", "train {w}/cut_cameras --out {w}/new", "the model is damaged"),
    ("gsseg", "train {w}/small_mask --out {w}/new", "masks must have"),
    # gsseg render
    ("gsseg", "render {w}/nowhere --out {w}/new", "has no config.json"),
    ("gsseg", "render {w}/unfinished --out {w}/new", "has no gaussians.ply"),
    ("gsseg", "render {w}/run --out {w}/new --what normals", "--what normals: unknown products normals"),
    ("gsseg", "render {w}/run --out {w}/report", "exists"),
    ("gsseg", "render {w}/run --out {w}/new --split half", "half"),
    ("gsseg", "render {w}/cut_config --out {w}/new", "damaged run file"),
    ("gsseg", "render {w}/junk_classifier --out {w}/new", "damaged run file"),
    ("gsseg", "render {w}/cut_ply --out {w}/new", "not a readable PLY"),
    ("gsseg", "render {w}/nan_ply --out {w}/new", "NaN or infinite"),
    ("gsseg", "render {w}/run --scene {w}/other --out {w}/new", "not the scene"),
    ("gsseg", "render {w}/no_labels --out {w}/new --what segments", "run `gsseg segment`"),
    ("gsseg", "render {w}/stale_labels --out {w}/new --what segments", "labels another model"),
    # gsseg segment
    ("gsseg", "segment {w}/run --gamma-p nan", "finite"),
    ("gsseg", "segment {w}/run --method voting", "voting"),
    ("gsseg", "segment {w}/run --mode pairs", "pairs"),
    ("gsseg", "segment {w}/run --masks nothing", "holds no masks"),
    ("gsseg", "segment {w}/run --scene {w}/other", "not the scene"),
    ("gsseg", "segment {w}/nowhere", "has no config.json"),
    # gsseg edit
    ("gsseg", "edit {w}/run --op remove", "give --object-id, or --point"),
    ("gsseg", "edit {w}/run --op remove --object-id 1 --point 0 0 0", "give --object-id, or --point"),
    ("gsseg", "edit {w}/run --op remove --object-id 1 --exclude-click 0001 5 5", "give those instead"),
    ("gsseg", "edit {w}/run --op remove --exclude-click 0001 5 5", "give --object-id, or --point"),
    ("gsseg", "edit {w}/run --op remove --point nan nan nan", "finite"),
    ("gsseg", "edit {w}/run --op remove --point 99 99 99", "outside the scene bounds"),
    ("gsseg", "edit {w}/run --op recolor --object-id 1 --color 300 0 0", "300"),
    ("gsseg", "edit {w}/run --op recolor --object-id 1", "needs --color"),
    ("gsseg", "edit {w}/run --op explode --object-id 1", "explode"),
    ("gsseg", "edit {w}/run --op remove --object-id 1 --name ../../escape", "plain folder name"),
    ("gsseg", "edit {w}/run --op remove --object-id 1 --name .", "plain folder name"),
    ("gsseg", "edit {w}/run --op remove --object-id 1 --name .hidden", "plain folder name"),
    ("gsseg", "edit {w}/run --op remove --click 0000 500 500", "outside the"),
    ("gsseg", "edit {w}/run --op remove --click nowhere 5 5", "no view named"),
    ("gsseg", "edit {w}/run --op remove --object-id 99", "not among the segmented objects"),
    ("gsseg", "edit {w}/no_labels --op remove --object-id 1", "run `gsseg segment`"),
    ("gsseg", "edit {w}/stale_labels --op remove --object-id 1", "labels another model"),
    ("gsseg", "edit {w}/junk_labels --op remove --object-id 1", "damaged labels"),
    # gsseg view (a port in use: tests/test_viewer.py)
    ("gsseg", "view {w}/nowhere", "has no config.json"),
    ("gsseg", "view {w}/cut_ply", "not a readable PLY"),
    ("gsseg", "view {w}/stale_labels", "labels another model"),
    ("gsseg", "view {w}/run --port 70000", "70000"),
    ("gsseg", "view {w}/run --scene {w}/other", "not the scene"),
    # gsseg export
    ("gsseg", "export {w}/run --out {w}/new.obj", "cannot tell the format"),
    ("gsseg", "export {w}/run --out {w}/report", "is a folder"),
    ("gsseg", "export {w}/run --out {w}/new.ply --object 99", "holds no Gaussian"),
    ("gsseg", "export {w}/no_labels --out {w}/new.splat --object 1", "run `gsseg segment`"),
    ("gsseg", "export {w}/nan_ply --out {w}/new.ply", "NaN or infinite"),
    ("gsseg", "export {w}/run --out {w}/new.ply --format obj", "obj"),
    # gsseg demo
    ("gsseg", "demo --out {w}/new --iters 0", "--iters 0: give 1 to 10,000,000 iterations"),
    ("gsseg", "demo --out {w}/new --max-gaussians 0", "--max-gaussians"),
    ("gsseg", "demo --out {w}/new --scene {w}/nowhere", "not found; pass a scene folder"),
    ("gsseg", "demo --out {w}/a_file", "a file stands there"),
    ("gsseg", "demo --out {w}/run", "already exists and is not empty"),
    # gseval
    ("gseval", "report {w}/nowhere --out {w}/new", "has no config.json"),
    ("gseval", "report {w}/no_labels --out {w}/new", "run `gsseg segment`"),
    ("gseval", "report {w}/run --out {w}/new --gt-masks nothing", "no ground-truth masks"),
    ("gseval", "report {w}/run --out {w}/report", "already exists"),
    ("gseval", "report {w}/run --out {w}/new --lpips {w}/lpips.onnx", "lpips.onnx"),
    ("gseval", "report {w}/run --out {w}/new --color 0 0 256", "256"),
    ("gseval", "report {w}/run --out {w}/new --split sideways", "sideways"),
    ("gseval", "report {w}/run --scene {w}/other --out {w}/new", "not the scene"),
    ("gseval", "compare {w}/unfinished", "evaluation.json: missing"),
    ("gseval", "compare {w}/cut_evaluation", "damaged"),
    ("gseval", "compare {w}/odd_evaluation", "does not hold a report's scores"),
    ("gsseg", "segment {w}/moved_scene", "no longer there; pass where it moved as --scene"),
    ("gseval", "report {w}/odd_metrics --out {w}/new --gt-masks none", "damaged run file"),
    ("gseval", "compare {w}/run --out {w}/run", ""),
    ("gseval", "paper-tables --out {w}/a_file --quick", "a file stands there"),
    ("gseval", "paper-tables --out {w}/new --quick --address 10.0.0.1:6379", "with --engine ray"),
]

# No command writes over what it reads: every writing command aimed at one of its inputs
# (is, contains or lies inside it) is refused, with or without --force.
OVERLAPS = [
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks images"),
    ("dataset_tools", "corrupt --scene {w}/scene --out-masks sparse"),
    ("dataset_tools", "sfm {w}/scene/images --out {w}/scene/images"),
    ("dataset_tools", "sfm {w}/scene/images --out {w}/scene/images/scene"),
    ("dataset_tools", "sfm {w}/scene/images --out {w}/scene"),
    ("dataset_tools", "inspect {w}/scene --sheet {w}/scene/images/0001.png"),
    ("dataset_tools", "hq --out {w}/scene --local {w}/scene/images"),
    ("hqmask", "build {w}/scene --out-masks images"),
    ("hqmask", "build {w}/scene --out-masks sparse"),
    ("hqmask", "build {w}/scene --proposer existing --from-masks object_mask --out-masks object_mask"),
    ("hqmask", "build {w}/scene --out-masks n --dataset {w}/scene/images"),
    ("hqmask", "build {w}/scene --out-masks n --dataset {w}"),
    ("hqmask", "build {w}/scene --out-masks n --dataset {w}/scene/object_mask"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks images"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks sparse"),
    ("hqmask", "clean {w}/scene --masks object_mask --out-masks object_mask"),
    ("hqmask", "export-onnx --checkpoint {w}/lpips.onnx --model-type vit_b --out {w}"),
    ("gsseg", "train {w}/scene --out {w}/scene/images"),
    ("gsseg", "train {w}/scene --out {w}/scene/sparse/0"),
    ("gsseg", "train {w}/scene --out {w}/scene"),
    ("gsseg", "train {w}/scene --out {w}"),
    ("gsseg", "render {w}/run --out {w}/run"),
    ("gsseg", "render {w}/run --out {w}/run/checkpoints"),
    ("gsseg", "render {w}/run --out {w}/run/renders"),
    ("gsseg", "render {w}/run --out {w}"),
    ("gsseg", "render {w}/run --scene {w}/scene --out {w}/scene/images"),
    ("gsseg", "render {w}/run --scene {w}/scene --out {w}/scene/object_mask"),
    ("gsseg", "render {w}/run --out {w}/scene"),
    ("gsseg", "export {w}/run --out {w}/run/gaussians.ply --object 1"),
    ("gsseg", "export {w}/run --out {w}/run/model.splat"),
    ("gsseg", "export {w}/run --out {w}/scene/images/0001.png --format ply"),
    ("gsseg", "demo --scene {w}/scene --out {w}/scene"),
    ("gsseg", "demo --scene {w}/scene --out {w}"),
    ("gsseg", "demo --scene {w}/scene/images --out {w}/scene/images/demo"),
    ("gseval", "report {w}/run --out {w}/run"),
    ("gseval", "report {w}/run --out {w}/run/report"),
    ("gseval", "report {w}/run --out {w}/scene/object_mask"),
    ("gseval", "report {w}/run --out {w}/scene"),
    ("gseval", "report {w}/run --out {w}/report --lpips {w}/report/report.md"),
    ("gseval", "compare {w}/run --out {w}/run/evaluation.json"),
]
CASES += [
    (c, a + force, "which this command reads")
    for c, a in OVERLAPS
    for force in ("", " --force")
    if not (force and a.split()[0] in ("inspect", "compare", "train"))
]  # these have no --force
CASES += [
    # a run knows its scene: another scene with the same view names is refused
    ("gsseg", "segment {w}/run --scene {w}/same_names", "the image of view"),
    ("gsseg", "render {w}/run --scene {w}/same_names --out {w}/new", "the image of view"),
    ("gsseg", "edit {w}/run --scene {w}/same_names --op remove --object-id 1", "the image of view"),
    ("gsseg", "edit {w}/run --scene {w}/same_names --op remove --click 0001 5 5", "not the scene"),
    ("gsseg", "view {w}/run --scene {w}/same_names", "the image of view"),
    ("gseval", "report {w}/run --scene {w}/same_names --out {w}/new", "the image of view"),
    ("gsseg", "render {w}/run --scene {w}/moved_camera --out {w}/new", "the camera of view"),
    ("gsseg", "train {w}/same_names --out {w}/unfinished --resume", "the image of view"),
    # resume keeps its options
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --seed 3", "trained with --seed 0, not 3"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --gamma-obj 2", "--gamma-obj 1.0, not 2.0"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --masks none", "--masks object_mask, not None"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --images images_9", "--images images, not 'images_9'"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --knn-reg 1", "--knn-reg 0.0"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --max-gaussians 9", "--max-gaussians"),
    ("gsseg", "train {w}/scene --out {w}/unfinished --resume --iters 2", "only lengthen"),
    ("gsseg", "train {w}/scene --out {w}/cut_config --resume", "damaged run file"),
    # the rest of the census
    ("gsseg", "train {w}/all_test --out {w}/new", "none is left to train on"),
    ("dataset_tools", "inspect {w}/short_cameras", "not the length its camera records declare"),
    ("gsseg", "view {w}/run --host 256.1.1.1", "cannot serve on 256.1.1.1"),
    ("gsseg", "view {w}/run --host no.such.host.invalid --port 0", "cannot serve on"),
    ("gsseg", "export {w}/run --out {w}/lpips.onnx --format ply", "already exists"),
    ("gsseg", "export {w}/run --out {w}/new.ply --object 0", "object 0 is the background"),
    ("gsseg", "export {w}/run --out {w}/new.ply --object chair", "not an object number"),
    ("hqmask", "build {w}/scene --out-masks n --engine ray --address 127.0.0.1:1", "no Ray cluster answers"),
]


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    """Size and time of every file and the set of folders; a run's ``.lock`` (the OS lock a
    command takes on a run folder, which stays there by design) is left out."""
    files = {
        str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in root.rglob("*")
        if p.is_file() and not p.is_symlink() and p.name != ".lock"
    }
    return {**files, **{str(p.relative_to(root)): (-1, -1) for p in root.rglob("*") if p.is_dir()}}


def _message_lines(err: str) -> list[str]:
    """The lines of ``err`` that are not progress-bar frames (tqdm's ``[00:00<?, ...]``)."""
    return [line for line in err.splitlines() if line.strip() and not re.search(r"\[\d+:\d\d[<,]", line)]


@pytest.mark.parametrize(
    "command, args, message", CASES, ids=[f"{c} {a.split()[0]}-{i}" for i, (c, a, _) in enumerate(CASES)]
)
def test_a_bad_input_is_one_line_exit_2_and_changes_nothing(world, monkeypatch, capsys, command, args, message):
    argv = [a.format(w=world) for a in args.split()]
    scene = (
        ["--scene", str(world / "scene")]
        if command in ("gsseg", "gseval") and argv[0] in ("report",) and "--scene" not in argv
        else []
    )
    before = _snapshot(world)
    monkeypatch.setattr(sys, "argv", [command, *argv, *scene])
    with pytest.raises(SystemExit) as exit_:
        ENTRY[command]()
    err = capsys.readouterr().err
    assert exit_.value.code == 2, err
    lines = _message_lines(err)
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    assert message in lines[0], err
    assert _snapshot(world) == before, "the command changed or left files"


def test_the_census_covers_every_command_and_at_least_80_cases():
    assert len(CASES) >= 80
    assert {c for c, _, _ in CASES} == set(ENTRY)
    subcommands = {(c, a.split()[0]) for c, a, _ in CASES}
    assert {("gsseg", s) for s in ("train", "render", "segment", "edit", "view", "export", "demo")} <= subcommands
    assert {("hqmask", s) for s in ("build", "clean")} <= subcommands
    assert {("gseval", s) for s in ("report", "compare", "paper-tables")} <= subcommands


def test_a_palette_mask_is_a_valid_mask(tmp_path):
    ids = np.zeros((20, 30), np.uint8)
    ids[5:15, 5:12], ids[5:15, 15:25] = 3, 7
    image = Image.fromarray(ids, mode="P")
    image.putpalette([v for k in range(256) for v in (k, 255 - k, (7 * k) % 256)])
    image.save(tmp_path / "m.png")
    assert np.array_equal(read_mask(tmp_path / "m.png"), ids)


def _train_command(scene: Path, run: Path, *extra: str) -> list[str]:
    return [
        script("gsseg"),
        "train",
        str(scene),
        "--out",
        str(run),
        "--iters",
        "40",
        "--backend",
        "cpu",
        "--max-gaussians",
        "3000",
        *extra,
    ]


def test_ctrl_c_then_resume_gives_the_bytes_of_an_uninterrupted_run(world, tmp_path):
    """SIGINT during training: the step in progress finishes, its checkpoint is written, the
    command says how to continue and exits 130; --resume then ends on the same PLY bytes as a
    run never interrupted (one thread, so that the sums are reproducible)."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    env.pop("TQDM_DISABLE", None)
    whole = subprocess.run(_train_command(world / "scene", tmp_path / "whole"), env=env, capture_output=True, text=True)
    assert whole.returncode == 0, whole.stderr
    proc = subprocess.Popen(
        _train_command(world / "scene", tmp_path / "cut"),
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    checkpoints = tmp_path / "cut" / "checkpoints"
    seen = ""
    while "training:" not in seen and proc.poll() is None:  # the loop's bar: steps are under way
        seen += proc.stderr.read(1)
    time.sleep(0.05)  # a step or so in
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    err = seen + err
    assert proc.returncode == 130 and "--resume" in err, err
    saved = sorted(checkpoints.glob("step_*.pt"))
    assert saved and not (tmp_path / "cut" / "gaussians.ply").exists()
    resumed = subprocess.run(
        _train_command(world / "scene", tmp_path / "cut", "--resume"), env=env, capture_output=True, text=True
    )
    assert resumed.returncode == 0, resumed.stderr
    assert (tmp_path / "cut" / "gaussians.ply").read_bytes() == (tmp_path / "whole" / "gaussians.ply").read_bytes()


def _training_started(command: list[str], run: Path, env: dict) -> subprocess.Popen:
    """``command`` (a training into ``run``) started in the background, once it has written
    ``run/config.json`` (or two minutes have passed)."""
    training = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not (run / "config.json").exists() and time.time() < deadline:
        time.sleep(0.05)
    return training


def test_a_second_writer_is_refused_while_the_first_trains(world, tmp_path):
    env = {**os.environ, "TQDM_DISABLE": "1"}
    first = _training_started(
        _train_command(world / "scene", tmp_path / "run", "--iters", "400"), tmp_path / "run", env
    )
    second = subprocess.run(
        _train_command(world / "scene", tmp_path / "run", "--resume"), env=env, capture_output=True, text=True
    )
    first.send_signal(signal.SIGTERM)
    first.communicate(timeout=120)
    assert second.returncode == 2 and "another command" in second.stderr, second.stderr
    assert len(second.stderr.strip().splitlines()) == 1
    assert first.returncode == 130  # SIGTERM, like Ctrl-C, stops after a checkpoint


def test_the_masks_a_training_reads_are_not_rewritten_under_it(world, tmp_path):
    """A training holds the scene's masks: rewriting them (``corrupt --force``, ``hqmask clean
    --force``) is refused in one line while it runs, and the masks stay as they were."""
    scene = _copy(world / "scene", tmp_path / "scene")
    env = {**os.environ, "TQDM_DISABLE": "1"}
    training = _training_started(
        [*_train_command(scene, tmp_path / "run", "--iters", "400"), "--cache-views", "disk"], tmp_path / "run", env
    )
    before = _snapshot(scene)
    writers = [
        [sys.executable, "-m", "dataset_tools", "corrupt", "--scene", str(scene), "--masks", "gt_mask"]
        + ["--out-masks", "object_mask", "--force"],
        [script("hqmask"), "clean", str(scene), "--masks", "gt_mask", "--out-masks", "object_mask", "--force"],
    ]
    refusals = [subprocess.run(w, env=env, capture_output=True, text=True) for w in writers]
    training.send_signal(signal.SIGTERM)
    training.communicate(timeout=120)
    for r in refusals:
        assert r.returncode == 2 and "training on masks" in r.stderr, r.stderr
        assert len(_message_lines(r.stderr)) == 1, r.stderr
    assert _snapshot(scene) == before


def test_an_error_after_a_progress_bar_starts_on_its_own_line(world, tmp_path):
    shutil.copytree(world / "cut_image", tmp_path / "s")
    r = subprocess.run(
        [script("hqmask"), "build", str(tmp_path / "s"), "--out-masks", "n"],
        capture_output=True,
        text=True,
        env={k: v for k, v in os.environ.items() if k != "TQDM_DISABLE"},
    )
    assert r.returncode == 2
    assert any(line.startswith("error: ") for line in r.stderr.split("\n")), r.stderr
    assert not (tmp_path / "s" / "n").exists()


def test_a_first_run_on_an_empty_kernel_cache_gives_the_bits_of_every_later_run(world, tmp_path):
    """numba's kernels compiled in a process round unlike the same kernels loaded from its
    cache; the trainer fills an empty cache from a child process and loads from it, so a
    machine's first run equals the runs after it: a run stopped on an empty cache and resumed
    equals an uninterrupted run on the cache it filled."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "TQDM_DISABLE": "1"}
    first = _train_command(world / "scene", tmp_path / "first")
    for command in (
        [*first, "--stop-after", "20"],
        [*first, "--resume"],
        _train_command(world / "scene", tmp_path / "later"),
    ):
        done = subprocess.run(command, env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    assert (tmp_path / "first" / "gaussians.ply").read_bytes() == (tmp_path / "later" / "gaussians.ply").read_bytes()


def test_the_viewer_answers_a_malformed_frame_and_sigterm_with_a_line_each(world, tmp_path):
    """A browser connection sending a frame that is no message is one warning line, and the
    viewer keeps serving; pycolmap's logging library installs a handler that prints a native
    stack trace and kills the process, but the commands keep Python's: SIGTERM to the viewer
    (which has read the scene through pycolmap) is one line and exit code 130."""
    viser = pytest.importorskip("viser")
    import asyncio

    import websockets

    run = _copy(world / "run", tmp_path / "run")
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    env = {**os.environ, "TQDM_DISABLE": "1", "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [script("gsseg"), "view", str(run), "--port", str(port), "--backend", "cpu"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    seen = ""
    while "http://" not in seen and proc.poll() is None:
        seen += proc.stdout.readline()

    async def malformed() -> None:
        protocol = [f"viser-v{viser.__version__}"]
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=protocol) as ws:
            await ws.send(b"\x93 not a message")
            await asyncio.sleep(1)

    try:
        asyncio.run(malformed())
    except websockets.exceptions.ConnectionClosed:
        pass  # the server may close it before the client is done
    time.sleep(1)
    assert proc.poll() is None  # still serving
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, (seen, err)
    lines = _message_lines(err)
    assert "stack trace" not in err and "Traceback" not in err and len(lines) == 2, err
    assert lines[0].startswith("warning: a browser connection ended") and lines[1].startswith("interrupted"), err


def test_inspect_says_when_the_mask_folder_asked_for_is_missing(world, tmp_path, monkeypatch, capsys):
    sheet = tmp_path / "sheet.png"
    monkeypatch.setattr(
        sys, "argv", ["dataset_tools", "inspect", str(world / "scene"), "--masks", "nomask", "--sheet", str(sheet)]
    )
    ENTRY["dataset_tools"]()
    err = capsys.readouterr().err
    assert "nomask: no such mask folder" in err and sheet.is_file(), err
