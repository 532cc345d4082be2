"""eval: metrics on hand-made masks, the two protocols on a hand-made occlusion, reports,
compare, the demo (plumbing) and the user errors."""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from helpers import QUICK_FILL, script

from dataset_tools import InputError
from dataset_tools.cameras import PinholeCamera
from dataset_tools.image_files import read_image
from dataset_tools.scene import load_scene
from eval.evaluate import score_views
from eval.metrics import binary_scores, psnr, ssim
from eval.renders import ViewRenders, render_view
from gsseg.model.gaussians import Gaussians, make_classifier
from gsseg.render.pixel_labels import segment_pixels
from gsseg.render.views import render_run
from gsseg.run.folder import RunFolder
from gsseg.run.loaded import Run
from gsseg.run.record import RunRecord
from gsseg.segment.reassign import Segmentation
from gsseg.train.config import TrainConfig


def test_binary_scores_known_values():
    pred = np.zeros((4, 4), bool)
    target = np.zeros((4, 4), bool)
    pred[0, :2] = True  # 2 px
    target[0, 1:4] = True  # 3 px, 1 shared
    iou, acc = binary_scores(pred, target)
    assert iou == pytest.approx(1 / 4) and acc == pytest.approx(13 / 16)
    assert binary_scores(np.zeros((2, 2), bool), np.zeros((2, 2), bool)) == (1.0, 1.0)


def test_psnr_and_ssim_known_values():
    a = np.full((16, 16, 3), 100, np.uint8)
    assert psnr(a + 1, a) == pytest.approx(10 * np.log10(255**2), abs=1e-9)
    rng = np.random.default_rng(0)
    b = rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)
    assert ssim(b, b) == pytest.approx(1.0, abs=1e-6)
    assert ssim(b, 255 - b) < 0


def renders(stem, truth, visible, extracted):
    blank = np.zeros((16, 16, 3), np.uint8)  # the image metrics need at least SSIM's 11x11 window
    return ViewRenders(stem, blank, truth, blank, visible, extracted)


def test_scores_rename_predicted_labels_by_matching():
    truth = np.zeros((4, 6), np.uint8)
    truth[:, :2], truth[:, 4:] = 1, 2
    visible = np.zeros_like(truth)
    visible[:, :2], visible[:, 3:] = 7, 9  # label 7 is object 1; label 9 is object 2 plus a column
    extracted = {7: truth == 1, 9: np.ones_like(truth, bool)}
    ev = score_views([renders("a", truth, visible, extracted)], run="r", scene="s", split="test")
    assert ev.id_map == {7: 1, 9: 2}
    rows = {(r["object"], r["protocol"]): (r["iou"], r["acc"]) for r in ev.objects}
    assert rows[1, "visible"] == (1.0, 1.0)
    assert rows[2, "visible"] == pytest.approx((8 / 12, 20 / 24))
    assert rows[2, "extracted"] == pytest.approx((8 / 24, 8 / 24))
    s = ev.summary()
    assert s["visible"]["miou"] == pytest.approx((1 + 8 / 12) / 2) and s["extracted"]["pairs"] == 2


def test_unmatched_object_scores_zero_in_both_protocols():
    truth = np.zeros((4, 4), np.uint8)
    truth[:2] = 1
    ev = score_views([renders("a", truth, np.zeros_like(truth), {})], run="r", scene="s", split="test")
    assert ev.id_map == {} and all(r["iou"] == 0.0 for r in ev.objects)


@dataclass
class HandView:
    stem: str
    camera: PinholeCamera
    cam_from_world: np.ndarray

    def load_image(self) -> np.ndarray:
        return np.zeros((self.camera.height, self.camera.width, 3), np.uint8)


def two_walls() -> tuple[Gaussians, Segmentation, HandView]:
    """Two opaque walls of Gaussians facing the camera: object 1 in front, covering the left
    part of object 2 behind it."""
    xs, ys = np.meshgrid(np.linspace(-0.6, 0.0, 13), np.linspace(-0.4, 0.4, 17))
    front = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 2.0)], 1)
    xs, ys = np.meshgrid(np.linspace(-0.6, 0.6, 25), np.linspace(-0.4, 0.4, 17))
    back = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 4.0)], 1) * [2, 2, 1]
    means = torch.tensor(np.concatenate([front, back]), dtype=torch.float32)
    n = len(means)
    g = Gaussians(
        means=means,
        log_scales=torch.full((n, 3), np.log(0.05)).float() + torch.tensor([0, 0, -2.0]),
        quats=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        opacity_logits=torch.full((n,), 6.0),
        sh_dc=torch.zeros(n, 3),
        sh_rest=torch.zeros(n, 15, 3),
        obj_feat=torch.zeros(n, 16),
    )
    labels = np.array([1] * len(front) + [2] * len(back), np.uint8)
    seg = Segmentation.of_labels(labels, "hand")
    view = HandView("v", PinholeCamera(64, 48, 50.0, 50.0, 32.0, 24.0), np.eye(4)[:3])
    return g, seg, view


def test_visible_and_extracted_differ_only_for_the_occluded_object():
    g, seg, view = two_walls()
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32)
    truth = segment_pixels(g, seg.labels, view.camera, pose, backend="cpu")  # what the camera sees
    record = RunRecord(TrainConfig(sh_degree=0), "scene", "cpu", 1.0, None, ())
    run = Run(RunFolder("unused"), record, g, make_classifier(256), environment=None)
    r = render_view(run, seg, view, backend="cpu", truth=truth)
    ev = score_views([r], run="r", scene="s", split="test")
    per = ev.per_object()
    assert per[1]["visible_iou"] == 1.0 and per[2]["visible_iou"] == 1.0
    assert per[1]["extracted_iou"] > 0.95  # nothing hides the front wall
    hidden = np.count_nonzero(r.extracted[2] & (truth == 1))
    assert hidden > 100 and per[2]["extracted_iou"] < 0.9  # alone, the back wall shows its hidden part


def test_report_writes_tables_images_and_a_self_contained_page(segmented, small_scene, tmp_path):
    out = tmp_path / "report"
    r = subprocess.run(
        [
            script("gseval"),
            "report",
            str(segmented),
            "--scene",
            str(small_scene.root),
            "--out",
            str(out),
            "--fill-steps",
            str(QUICK_FILL.steps),
            "--backend",
            "cpu",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert f"wrote {out / 'report.html'}" in r.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["summary"]) >= {"visible", "extracted", "psnr", "ssim", "lpips"}
    assert metrics["summary"]["lpips"] == "n/a: weights not available"
    test_views = [v["view"] for v in metrics["views"]]
    assert test_views and all((out / "images" / f"{v}.png").is_file() for v in test_views)
    md = (out / "report.md").read_text()
    assert "| object | ground-truth match |" in md and "images/training.png" in md
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == len(test_views) + 1 and "src='images/" not in page
    r = subprocess.run([script("gseval"), "compare", str(segmented), str(segmented)], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.count(str(segmented)) == 2


def test_report_scores_edits_where_the_scene_has_edit_truth(segmented, small_scene, tmp_path):
    """With ``edit_truth/`` in the scene, the report scores every matched object's removal and
    extraction and shows the selected object's edits beside their truth."""
    from dataset_tools.synth.edit_truth import write_edit_truth
    from eval.report import report_run

    scene = tmp_path / "scene"
    shutil.copytree(small_scene.root, scene)
    write_edit_truth(scene, progress=False)
    ev = report_run(segmented, scene, tmp_path / "report", backend="cpu", fill=None, progress=False)
    test_views = load_scene(scene).split("test")
    assert {r["object"] for r in ev.edits} == set(ev.id_map.values())
    assert len(ev.edits) == len(ev.id_map) * len(test_views)
    edits = ev.summary()["edits"]
    assert 0 < edits["extraction_iou"] <= 1 and 0 <= edits["leak"] <= 1 and edits["removal_psnr"] > 10
    assert 0 <= edits["ghost_share_after"] <= edits["ghost_share_before"] <= 1  # what served it alone goes too
    assert all(-1 <= r["removal"]["ssim_region"] <= 1 for r in ev.edits)
    md = (tmp_path / "report" / "report.md").read_text()
    assert "## Edits against ground truth" in md and "## Edits beside their truth" in md
    table = md.split("## Edits against ground truth")[1].split("##")[0].strip().splitlines()
    head, rows = table[0], [line for line in table[2:] if line.startswith("|")]
    assert len(rows) == len(ev.id_map) and all(row.count("|") == head.count("|") for row in rows)
    for view in test_views:
        row = read_image(tmp_path / "report" / "images" / f"{view.stem}_truth.png")
        assert row.shape == (view.camera.height, 4 * view.camera.width + 12, 3)
    plain = report_run(segmented, small_scene.root, tmp_path / "plain", backend="cpu", fill=None, progress=False)
    assert not plain.edits and "edits" not in plain.summary()


@pytest.mark.skipif(shutil.which("chromium") is None, reason="headless Chromium (Debian's chromium) is not installed")
def test_report_page_renders_in_chromium(segmented, small_scene, tmp_path):
    from eval.report import report_run

    report_run(segmented, small_scene.root, tmp_path / "report", backend="cpu", fill=None, progress=False)
    shot = tmp_path / "shot.png"
    subprocess.run(
        [
            "chromium",
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            f"--screenshot={shot}",
            "--window-size=1200,1600",
            (tmp_path / "report" / "report.html").as_uri(),
        ],
        capture_output=True,
        timeout=120,
    )
    import cv2

    image = cv2.imread(str(shot))
    assert image is not None and image.std() > 10  # not a blank page


@pytest.mark.parametrize(
    "case, message",
    [
        ("no-labels", "labels.npz does not exist; run `gsseg segment`"),
        ("no-gt", "no ground-truth masks for the metrics; pass the scene's ground-truth mask folder as --gt-masks"),
        ("no-evaluation", "evaluation.json: missing; run `gseval report"),
    ],
)
def test_bad_input_is_one_sentence_and_exit_2(case, message, trained, segmented, small_scene, tmp_path):
    scene, out = str(small_scene.root), str(tmp_path / "out")
    args = {
        "no-labels": ["report", str(trained), "--scene", scene, "--out", out],
        "no-gt": ["report", str(segmented), "--scene", scene, "--out", out, "--gt-masks", "nothing"],
        "no-evaluation": ["compare", str(trained)],
    }[case]
    r = subprocess.run([script("gseval"), *args], capture_output=True, text=True)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not Path(out).exists()


def _standin_lpips(path: Path) -> None:
    """An ONNX graph with LPIPS's inputs and output that returns the mean squared difference of
    its [-1, 1] inputs: a stand-in for the real network, to test the plumbing and the scaling."""

    class MeanSquared(torch.nn.Module):
        def forward(self, image0, image1):
            return ((image0 - image1) ** 2).mean().reshape(1, 1, 1, 1)

    x = torch.zeros(1, 3, 8, 8)
    torch.onnx.export(
        MeanSquared(),
        (x, x),
        str(path),
        input_names=["image0", "image1"],
        output_names=["d"],
        dynamic_axes={"image0": {2: "h", 3: "w"}, "image1": {2: "h", 3: "w"}},
        dynamo=False,
    )


def test_lpips_plumbing_reports_the_networks_value_per_view(segmented, small_scene, tmp_path):
    from eval.report import report_run

    net = tmp_path / "lpips.onnx"
    _standin_lpips(net)
    ev = report_run(
        segmented, small_scene.root, tmp_path / "report", backend="cpu", fill=None, lpips=net, progress=False
    )
    renders = render_run(
        segmented, small_scene.root, tmp_path / "renders", what=("rgb",), backend="cpu", progress=False
    )
    for row, view in zip(ev.views, load_scene(small_scene.root).split("test"), strict=True):
        rgb = read_image(renders / "rgb" / f"{view.stem}.png").astype(np.float64)
        assert row["lpips"] == pytest.approx(np.mean(((rgb - view.load_image()) / 127.5) ** 2), rel=1e-4)
    assert ev.summary()["lpips"] == pytest.approx(np.mean([v["lpips"] for v in ev.views]))
    assert "n/a" not in (tmp_path / "report" / "report.md").read_text().split("## Objects")[0]


def test_unusable_lpips_file_is_one_sentence(segmented, small_scene, tmp_path):
    bad = tmp_path / "lpips.onnx"
    bad.write_bytes(b"not onnx")
    r = subprocess.run(
        [
            script("gseval"),
            "report",
            str(segmented),
            "--scene",
            str(small_scene.root),
            "--out",
            str(tmp_path / "out"),
            "--lpips",
            str(bad),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and "ONNX Runtime cannot load it" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_edit_quality_never_writes_its_json_over_the_lpips_network(tmp_path, monkeypatch):
    from benchmarks import edit_quality

    net = tmp_path / "lpips.onnx"
    _standin_lpips(net)
    before = net.read_bytes()
    monkeypatch.setattr("sys.argv", ["edit_quality", "--lpips", str(net), "--out", str(net)])
    with pytest.raises(InputError, match="would replace the LPIPS network"):
        edit_quality.main()
    assert net.read_bytes() == before


@pytest.mark.parametrize("benchmark", ["click_quality", "real_scenes"])
def test_a_benchmark_never_writes_its_json_into_the_runs_it_reads(benchmark, tmp_path, monkeypatch, capsys):
    import importlib

    run = tmp_path / "work" / "orbit-0" / "run"
    run.mkdir(parents=True)
    (run / "gaussians.ply").write_bytes(b"model")
    out = run / "gaussians.ply"
    monkeypatch.setattr("sys.argv", [benchmark, "--work", str(tmp_path / "work"), "--out", str(out)])
    with pytest.raises(SystemExit) as exit_:
        importlib.import_module(f"benchmarks.{benchmark}").main()
    assert exit_.value.code != 0 and out.read_bytes() == b"model"
    assert "lies inside the work folder" in capsys.readouterr().err


@pytest.mark.slow
def test_demo_plumbing_runs_every_stage_with_few_iterations(tmp_path):
    """Plumbing only: 20 training iterations, so the scores mean nothing; every stage runs and
    the report is where the demo says."""
    r = subprocess.run(
        [script("gsseg"), "demo", "--out", str(tmp_path / "demo"), "--iters", "20", "--backend", "cpu"],
        capture_output=True,
        text=True,
    )
    if r.returncode == 2 and "lies on the background" in r.stderr:
        pytest.fail("the demo's prompt point found no object: " + r.stderr)
    assert r.returncode == 0, r.stderr
    report = tmp_path / "demo" / "report" / "report.html"
    assert f"report: {report}" in r.stdout and report.is_file()
    assert "training 20 steps, at most 30,000 Gaussians (steps as asked)" in r.stderr
    stages = next(line for line in r.stdout.splitlines() if line.startswith("stages: "))
    named = [part.rsplit(" ", 2)[0] for part in stages.removeprefix("stages: ").split(", ")]
    assert named == ["synthetic scene", "masks", "training", "masks at depth jumps", "segmentation", "edits", "report"]
    edits = sorted(p.name for p in (tmp_path / "demo" / "run" / "edits").iterdir())
    assert [e.split("_")[0] for e in edits] == ["extract", "recolor", "remove"]


def test_matched_miou_renames_before_scoring():
    truth = np.zeros((4, 4), np.uint8)
    truth[:2], truth[2:, :2] = 1, 2
    pred = np.where(truth == 1, 7, np.where(truth == 2, 3, 0)).astype(np.uint8)
    from eval.metrics import matched_miou

    assert matched_miou([pred], [truth]) == 1.0
    pred[3, 1] = 7  # one pixel of object 2 (4 px) taken by object 1 (8 px)
    assert matched_miou([pred], [truth]) == pytest.approx((8 / 9 + 3 / 4) / 2)


@pytest.mark.slow
def test_paper_tables_plumbing_writes_every_table_and_reuses_its_work(tmp_path):
    """Plumbing only (a tiny scene and 30 iterations): every table is produced, the JSON holds
    every number the markdown shows, and a second run retrains nothing."""
    from pipeline.paper_tables import GAMMAS, METHODS, TRAINING_MASKS, TableSetup, paper_tables

    setup = TableSetup(
        paths=("orbit",), seeds=(3,), res=128, views=8, objects=2, iters=30, images="images_4", min_area=20
    )
    md = paper_tables(tmp_path, setup=setup, backend="cpu", progress=False).read_text()
    for title in ("Table 1", "Table 2", "Table 3", "Table 4"):
        assert title in md
    scene = json.loads((tmp_path / "paper_tables.json").read_text())["scenes"]["orbit-3"]
    assert set(scene["training"]) == set(TRAINING_MASKS) and set(scene["methods"]) == {m for m, _ in METHODS}
    assert set(scene["gamma_p"]) == {f"{g:g}" for g in GAMMAS}
    assert f"| exact | {scene['training']['exact']['psnr']:.2f} |" in md
    assert all(0 <= scene["masks"][k]["consistency"] <= 1 for k in scene["masks"])

    paper_tables(tmp_path, setup=setup, backend="cpu", progress=False)
    again = json.loads((tmp_path / "paper_tables.json").read_text())["scenes"]["orbit-3"]
    assert all(again["training"][k]["train_seconds"] is None for k in TRAINING_MASKS)
    assert again["training"]["exact"]["psnr"] == scene["training"]["exact"]["psnr"]


def test_without_truth_the_label_panel_shows_every_object_in_its_own_colour():
    from eval.renders import ViewRenders
    from eval.report import image_row

    visible = np.zeros((4, 6), np.uint8)
    visible[:, 2:4], visible[:, 4:] = 3, 7
    image = np.zeros((4, 6, 3), np.uint8)
    row = image_row(
        ViewRenders("v", image, None, image, visible, {}),
        {},
        {op: [image] for op in ("remove", "extract", "recolor")},
        0,
    )
    labels = row[:, 10:16]  # the second panel, after the photo and a 4 px gap
    assert (labels[:, 2] != labels[:, 4]).any() and (labels[:, 0] == 0).all()


def test_the_two_view_clicks_turn_to_the_view_that_looks_from_farthest_away():
    from benchmarks.real_scenes import farthest_view

    def view(degrees: float) -> SimpleNamespace:  # a camera turned about the vertical axis
        a = np.radians(degrees)
        rotation = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
        return SimpleNamespace(cam_from_world=np.hstack([rotation, np.zeros((3, 1))]))

    views = [view(10), view(70), view(-170), view(130), view(-80)]
    assert farthest_view(views) is views[2]
    assert farthest_view(views[:2] + views[3:]) is views[3]
