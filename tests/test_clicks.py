"""Selections by several clicks: positive clicks join objects, a negative click splits an
object the masks joined to another (``gsseg edit --click ... --exclude-click ...``)."""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import script
from scipy import ndimage

from dataset_tools.infra.errors import InputError
from gsseg.ply import read_ply
from gsseg.render.pixel_labels import segment_pixels
from gsseg.run import load_run
from gsseg.segment.clicks import select_by_points, split_by_graph
from gsseg.segment.prompts import point_from_click


def test_a_negative_click_splits_two_blobs_along_the_graph_not_across_it():
    """Two clusters of Gaussians, one label, the same features: the excluded cluster leaves
    whole, even where its nearest Gaussian lies closer to the positive click than to the
    negative one in a straight line (an elongated object reaching towards the other)."""
    rng = np.random.default_rng(0)
    rod = np.stack([np.linspace(0, 4, 400), rng.normal(0, 0.05, 400), rng.normal(0, 0.05, 400)], 1)
    blob = rng.normal(0, 0.2, (300, 3)) + [5.0, 0.0, 0.0]
    means = np.concatenate([rod, blob])
    feats = np.zeros((len(means), 16))
    labels = np.full(len(means), 7, np.uint8)
    selected = select_by_points(means, feats, labels, positives=[[0.0, 0, 0]], negatives=[[5.0, 0, 0]])
    assert selected[:400].all() and not selected[400:].any()
    keep = split_by_graph(means, feats, np.array([[0.0, 0, 0]]), np.array([[5.0, 0, 0]]))
    assert keep.sum() == 400
    with pytest.raises(InputError, match="on the background"):
        select_by_points(means, feats, np.zeros(len(means), np.uint8), positives=[[0.0, 0, 0]])
    with pytest.raises(InputError, match="at least one positive click"):
        select_by_points(means, feats, labels, positives=np.zeros((0, 3)))


def _clickable(run, labels: np.ndarray, objects: list[int]) -> dict[int, tuple[str, float, float, np.ndarray]]:
    """For each object, a training view and the pixel deepest inside it there, and the 3D point
    that pixel lifts to."""
    found = {}
    g = run.gaussians
    for view in run.scene().split("train"):
        ids = segment_pixels(
            g, labels, view.camera, torch.as_tensor(view.cam_from_world, dtype=torch.float32), backend="cpu"
        )
        for obj in objects:
            depth = ndimage.distance_transform_edt(ids == obj)
            if obj not in found and depth.max() > 3:
                row, col = np.unravel_index(depth.argmax(), depth.shape)
                point = point_from_click(g, view.camera, view.cam_from_world, col + 0.5, row + 0.5, backend="cpu")
                found[obj] = (view.stem, col + 0.5, row + 0.5, point)
    assert set(found) == set(objects)
    return found


def _joined(segmented: Path, tmp_path: Path):
    """A copy of the test run whose two largest objects a and b share a's label in labels.npz:
    (run folder, run, its original labels, the joined labels (N,), a, b)."""
    run_dir = Path(shutil.copytree(segmented, tmp_path / "run"))
    run = load_run(run_dir)
    seg = run.labels()
    counts = np.bincount(seg.labels, minlength=256)
    a, b = (int(o) for o in np.argsort(-counts[1:])[:2] + 1)
    merged = np.where(seg.labels == b, a, seg.labels).astype(np.uint8)
    objects = np.array([o for o in seg.objects if o != b], np.uint8)
    run.folder.write_labels(replace(seg, labels=merged, objects=objects, selections=merged[None] == objects[:, None]))
    return run_dir, run, seg, merged, a, b


@pytest.mark.slow
def test_exclude_click_splits_an_object_joined_to_another(segmented, tmp_path):
    """The two largest objects of the test run given one label (as the weight-free masks join
    a dark head to the dark bush behind it): one click selects both; an excluding click on the
    second leaves the first alone (IoU > 0.95 with its own Gaussians); two clicks on the
    parts join them again."""
    run_dir, run, seg, merged, a, b = _joined(segmented, tmp_path)
    clicks = _clickable(run, seg.labels, [a, b])

    def edit(*args: str) -> Path:
        r = subprocess.run(
            [script("gsseg"), "edit", str(run_dir), "--op", "extract", "--backend", "cpu", *args],
            capture_output=True,
            text=True,
        )
        assert r.returncode == 0, r.stderr
        return Path(r.stdout.split()[-1])

    def chosen(out: Path) -> np.ndarray:
        kept = {tuple(p) for p in read_ply(out / "gaussians.ply").means.numpy().tolist()}
        return np.array([tuple(p) in kept for p in run.gaussians.means.numpy().tolist()])

    va, ua, wa, _ = clicks[a]
    vb, ub, wb, _ = clicks[b]
    both = chosen(edit("--click", va, str(ua), str(wa), "--name", "both"))
    assert both[seg.labels == a].all() and both[seg.labels == b].all()
    alone = chosen(edit("--click", va, str(ua), str(wa), "--exclude-click", vb, str(ub), str(wb)))
    truth = seg.labels == a
    assert (alone & truth).sum() / (alone | truth).sum() > 0.95
    record = json.loads((run_dir / "edits" / f"extract_{a}_split" / "edit.json").read_text())
    assert [c["positive"] for c in record["clicks"]] == [True, False] and record["object_id"] is None
    exported = tmp_path / "alone.ply"  # the selection is an object like any other for export
    r = subprocess.run(
        [
            script("gsseg"),
            "export",
            str(run_dir),
            "--out",
            str(exported),
            "--click",
            va,
            str(ua),
            str(wa),
            "--exclude-click",
            vb,
            str(ub),
            str(wb),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert len(read_ply(exported)) == alone.sum()  # no environment shell for a selection
    run.folder.write_labels(seg)  # the original labels: two clicks join the two objects
    joined = chosen(edit("--click", va, str(ua), str(wa), "--click", vb, str(ub), str(wb), "--name", "joined"))
    np.testing.assert_array_equal(joined, (seg.labels == a) | (seg.labels == b))


@pytest.mark.slow
def test_the_viewers_shift_click_splits_what_gsseg_edit_exclude_click_splits(segmented, tmp_path):
    """The viewer's click, then shift-click on the second of two joined objects, selects what
    ``gsseg edit --click --exclude-click`` selects; removing it keeps the rest; undo restores."""
    from gsseg.viewer.session import ViewCamera, ViewerSession

    run_dir, run, seg, merged, a, b = _joined(segmented, tmp_path)
    clicks = _clickable(run, seg.labels, [a, b])
    session = ViewerSession(load_run(run_dir), backend="cpu")
    scene = run.scene()

    def at(obj: int, mode: str):
        view = scene.view(clicks[obj][0])
        return session.select_at(ViewCamera(view.camera, view.cam_from_world), clicks[obj][1], clicks[obj][2], mode)

    with pytest.raises(InputError, match="click an object first"):
        at(b, "exclude")
    assert at(a, "select") == a and session.selection().sum() == (merged == a).sum()
    assert at(b, "exclude") is None
    expected = select_by_points(
        run.gaussians.means.numpy(),
        run.gaussians.obj_feat.detach().numpy(),
        merged,
        clicks[a][3][None],
        clicks[b][3][None],
    )
    np.testing.assert_array_equal(session.selection(), expected)
    session.edit("remove")
    assert len(session.current()[0]) == len(run.gaussians) - expected.sum() and session.selection() is None
    assert session.undo().object_id is None and len(session.current()[0]) == len(run.gaussians)
