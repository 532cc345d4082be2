"""``gsseg view`` and ``gsseg export``: the viewer's session without a browser, the viewer in
a real headless Chromium, and the exported files."""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import subprocess
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import QUICK_FILL, random_gaussians, script
from plyfile import PlyData
from scipy import ndimage
from scipy.spatial.transform import Rotation

from dataset_tools.image_files import read_image
from dataset_tools.infra.errors import InputError
from dataset_tools.scene import load_scene
from eval.standard_render import read_splats, render_reference
from gsseg.export import export_run, read_splat, splat_records
from gsseg.model.ply import read_ply
from gsseg.model.sh import C0
from gsseg.run.loaded import load_run
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.segment_run import segment_run
from gsseg.segment.served import complete_selection
from gsseg.viewer.session import ViewCamera, ViewerSession, browser_camera

CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")


def _copy(run: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(run, tmp_path / "run"))


def _inside_pixel(mask: np.ndarray, label: int) -> tuple[float, float]:
    """(u, v) of the pixel of ``label`` farthest from any other label: a click that cannot
    land on an edge."""
    depth = ndimage.distance_transform_edt(mask == label)
    row, col = np.unravel_index(depth.argmax(), depth.shape)
    return col + 0.5, row + 0.5


# --- the browser's camera --------------------------------------------------------------------


def test_the_browser_camera_of_a_training_view_is_that_view(small_scene):
    view = load_scene(small_scene.root).views[2]
    world_from_cam = view.cam_from_world[:3, :3].T
    wxyz = Rotation.from_matrix(world_from_cam).as_quat(scalar_first=True)
    centre = -world_from_cam @ view.cam_from_world[:3, 3]
    fov_y = 2 * math.atan(view.camera.height / 2 / view.camera.fy)
    for size, scale in ((view.camera.width, 1.0), (view.camera.width // 2, 0.5)):
        got = browser_camera(wxyz, centre, fov_y, view.camera.width, view.camera.height, max_size=size, near=0.1)
        np.testing.assert_allclose(got.cam_from_world, view.cam_from_world, atol=1e-6)
        assert (got.camera.width, got.camera.height) == (
            round(view.camera.width * scale),
            round(view.camera.height * scale),
        )
        np.testing.assert_allclose([got.camera.fy, got.camera.cy], [view.camera.fy * scale, view.camera.cy * scale])


# --- exports ---------------------------------------------------------------------------------


def test_splat_records_decode_to_the_gaussians():
    g = random_gaussians(300, 3)
    records = splat_records(g)
    assert records.itemsize == 32
    volume = (g.scales.prod(1) * g.opacities).numpy()
    order = np.argsort(-volume, kind="stable")
    assert np.all(np.diff(volume[order]) <= 0)
    np.testing.assert_array_equal(records["position"], g.means.numpy()[order])
    np.testing.assert_allclose(records["scale"], g.scales.numpy()[order], rtol=1e-6)
    rgb = np.clip(g.sh_dc.numpy() * C0 + 0.5, 0, 1)[order]
    np.testing.assert_allclose(records["rgba"][:, :3] / 255, rgb, atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(records["rgba"][:, 3] / 255, g.opacities.numpy()[order], atol=0.5 / 255 + 1e-6)
    q = torch.nn.functional.normalize(g.quats, dim=-1).numpy()[order]
    np.testing.assert_allclose((records["rotation"].astype(float) - 128) / 128, q, atol=1 / 128)


@pytest.mark.slow
def test_export_ply_keeps_the_3dgs_layout_and_adds_the_labels(segmented, tmp_path):
    out = tmp_path / "model.ply"
    r = subprocess.run([script("gsseg"), "export", str(segmented), "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    names = PlyData.read(str(out))["vertex"].data.dtype.names
    expected = (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(45)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )
    assert list(names[: len(expected)]) == expected and names[-1] == "label"
    run = load_run(segmented)
    back, n = read_ply(out), len(run.gaussians)
    for name, value in run.gaussians.tensors().items():
        assert torch.equal(getattr(back, name)[:n], value), name
    labels = PlyData.read(str(out))["vertex"]["label"]
    np.testing.assert_array_equal(labels[:n], run.labels().labels)
    assert len(back) > n and (labels[n:] == 0).all()  # the environment's shell, background


@pytest.mark.slow
def test_an_export_in_a_standard_renderer_looks_like_gsseg_render(trained, small_scene, tmp_path):
    """The exported PLY rendered by an independent implementation of the 3D-GS conventions
    (eval/standard_render.py), on black, against the project's render over its learned
    environment, on every view: the shell that carries the environment brings it within 30
    dB; without the shell the background is missing."""
    run = load_run(trained)
    psnr = {}
    for environment in (True, False):
        out = export_run(trained, tmp_path / f"{environment}.ply", environment=environment)
        splats = read_splats(out)
        errors = []
        for view in run.scene().views:
            c = view.camera
            ours = run.render(view).rgb.clamp(0, 1).numpy()
            theirs = np.clip(
                render_reference(splats, c.fx, c.fy, c.cx, c.cy, c.width, c.height, view.cam_from_world), 0, 1
            )
            errors.append(((ours - theirs) ** 2).mean())
        psnr[environment] = float(np.mean([-10 * np.log10(e) for e in errors]))
    assert psnr[True] >= 30 and psnr[False] < 20, psnr


@pytest.mark.slow
def test_export_one_object_as_splat(segmented, tmp_path):
    run = load_run(segmented)
    labels = run.labels().labels
    obj = int(np.bincount(labels)[1:].argmax() + 1)
    out = tmp_path / "object.splat"
    r = subprocess.run(
        [script("gsseg"), "export", str(segmented), "--out", str(out), "--object", str(obj)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    records = read_splat(out)
    taken = complete_selection(run.gaussians, labels == obj, run.scene().split("train")).mask  # as an extraction
    assert taken[labels == obj].all()
    mine = run.gaussians.means.numpy()[taken]
    assert len(records) == len(mine)
    np.testing.assert_array_equal(np.unique(records["position"], axis=0), np.unique(mine, axis=0))
    out.write_bytes(out.read_bytes()[:-5])
    with pytest.raises(InputError, match="not a whole number of 32-byte"):
        read_splat(out)


# --- the session: what the panel does --------------------------------------------------------


@pytest.mark.slow
def test_a_click_selects_what_gsseg_edit_click_selects(segmented, small_scene, tmp_path):
    run = _copy(segmented, tmp_path)
    session = ViewerSession(load_run(run), scene_dir=small_scene.root, backend="cpu")
    view = load_scene(small_scene.root, masks="object_mask").split("train")[1]
    mask = view.load_mask()
    labels = session.segmentation.labels
    found = []
    for label in [int(x) for x in np.unique(mask) if x][:3]:
        u, v = _inside_pixel(mask, label)
        chosen = session.select_at(ViewCamera(view.camera, view.cam_from_world), u, v)
        extracted = complete_selection(session.run.gaussians, chosen, session.scene.split("train")).mask
        np.testing.assert_array_equal(extracted, _edited_by_click(run, view.stem, u, v, "extract", f"click_{label}"))
        own = labels == label
        found.append((chosen & own).sum() / (chosen | own).sum() > 0.5)
    # the run is a rough one (200 steps on 8 views): most clicks find their mask's object
    assert sum(found) >= 2, found


@pytest.mark.slow
def test_edits_undo_and_save_write_what_gsseg_edit_writes(segmented, small_scene, tmp_path):
    run = _copy(segmented, tmp_path)
    session = ViewerSession(load_run(run), scene_dir=small_scene.root, backend="cpu", fill=QUICK_FILL)
    base, _ = session.current()
    obj, count = session.objects()[0]
    session.selected = obj
    session.edit("remove")
    assert session.selected is None and len(session.current()[0]) <= len(base) - count
    saved = session.save("viewer")
    r = subprocess.run(
        [
            script("gsseg"),
            "edit",
            str(run),
            "--object-id",
            str(obj),
            "--op",
            "remove",
            "--name",
            "cli",
            "--fill-steps",
            str(QUICK_FILL.steps),
            "--backend",
            "cpu",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    for name, value in read_ply(run / "edits" / "cli" / "gaussians.ply").tensors().items():
        assert torch.equal(getattr(read_ply(saved / "gaussians.ply"), name), value), name
    assert sorted(p.name for p in (saved / "renders").iterdir()) == sorted(
        p.name for p in (run / "edits" / "cli" / "renders").iterdir()
    )
    removed = len(base) - len(session.current()[0])  # the object and what served it alone
    record = json.loads((saved / "edit.json").read_text())
    assert record["steps"] == [{"op": "remove", "object_id": obj, "color": None, "selected_gaussians": removed}]
    filled = session.fill(wait=False)  # saving filled the removal, as gsseg edit does
    assert record["removal_fill"] == filled.record()
    assert len(read_ply(saved / "gaussians.ply")) == len(session.current()[0]) + filled.added
    assert session.undo().op == "remove" and session.current()[0] is base and session.undo() is None
    with pytest.raises(InputError, match="select an object first"):
        session.edit("extract")


@pytest.mark.slow
def test_an_extracted_object_shows_on_white_a_removal_over_the_environment(segmented, small_scene, tmp_path):
    """The learned environment is no part of an extracted object: `gsseg edit --op extract`,
    the viewer after an extraction and its saved edit show it on white, as the report does and
    as any viewer shows the exported object; a removal keeps the environment behind."""
    from gsseg.edits import apply_edit, edit_run

    run_dir = _copy(segmented, tmp_path)
    run = load_run(run_dir)
    obj = int(run.labels().objects[0])
    view = run.scene(small_scene.root).split("test")[0]
    alone = apply_edit(run.gaussians, run.labels().selection(obj), "extract")
    empty = run.render(view, gaussians=alone, background="black", backend="cpu").alpha.squeeze(-1).numpy() < 1e-4
    kept = apply_edit(run.gaussians, run.labels().selection(obj), "remove")
    behind = run.render_rgb(view, gaussians=kept, backend="cpu")
    assert empty.mean() > 0.3 and (behind[empty] < 250).any()  # the environment is no white
    for op in ("extract", "remove"):
        out = edit_run(run_dir, op, object_id=obj, scene_dir=small_scene.root, fill=None, backend="cpu", progress=False)
        frame = read_image(out / "renders" / f"{view.stem}.png")
        expected = np.full_like(behind[empty], 255) if op == "extract" else behind[empty]
        np.testing.assert_array_equal(frame[empty], expected)
    session = ViewerSession(load_run(run_dir), scene_dir=small_scene.root, backend="cpu")
    session.selected = obj
    session.edit("extract")
    assert (session.frame(ViewCamera(view.camera, view.cam_from_world))[empty] == 255).all()
    assert (read_image(session.save("viewer") / "renders" / f"{view.stem}.png")[empty] == 255).all()


@pytest.mark.slow
def test_relabelling_from_the_cache_equals_gsseg_segment(segmented, small_scene, tmp_path):
    run = _copy(segmented, tmp_path)
    session = ViewerSession(load_run(run), scene_dir=small_scene.root, backend="cpu")
    session.relabel("prior", 1.5)
    expected = segment_run(run, small_scene.root, options=LabelOptions(gamma_p=1.5), backend="cpu", progress=False)
    np.testing.assert_array_equal(session.segmentation.labels, expected.labels)
    # without the cache, the matrix is computed from the masks and written for next time
    (run / "contributions.npz").unlink()
    fresh = ViewerSession(load_run(run), scene_dir=small_scene.root, backend="cpu")
    fresh.relabel("prior", 1.5)
    np.testing.assert_array_equal(fresh.segmentation.labels, expected.labels)
    assert (run / "contributions.npz").is_file()


@pytest.mark.slow
def test_a_run_without_labels_opens_with_segments_off(trained, small_scene):
    session = ViewerSession(load_run(trained), scene_dir=small_scene.root, backend="cpu")
    assert "gsseg segment" in session.segments_missing and session.objects() == []
    view = load_scene(small_scene.root).views[0]
    assert session.frame(ViewCamera(view.camera, view.cam_from_world)).shape == (
        view.camera.height,
        view.camera.width,
        3,
    )
    with pytest.raises(InputError, match="gsseg segment"):
        session.select_at(ViewCamera(view.camera, view.cam_from_world), 40, 40)


@pytest.mark.slow
def test_a_port_in_use_is_one_sentence_and_exit_2(segmented):
    pytest.importorskip("viser")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = subprocess.run(
            [script("gsseg"), "view", str(segmented), "--port", str(port)], capture_output=True, text=True, timeout=120
        )
    assert r.returncode == 2 and f"cannot serve on 127.0.0.1:{port}" in r.stderr and "--port" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.slow
def test_gsseg_view_serves_the_page_and_stops_in_one_line_on_ctrl_c(segmented):
    pytest.importorskip("viser")
    import re
    import signal
    import urllib.request

    proc = subprocess.Popen(
        [script("gsseg"), "view", str(segmented), "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = None
        for line in proc.stdout:
            if found := re.search(r"serving .* at (http://\S+)", line):
                url = found.group(1)
                break
        assert url, proc.stderr.read()
        with urllib.request.urlopen(url, timeout=30) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.strip() == f"interrupted: SIGINT: the viewer of {segmented} stopped; the run is as it was.", err


# --- the viewer in a real browser ------------------------------------------------------------


@pytest.fixture
def browser():
    """Headless Chromium driven by selenium (Debian's chromium and chromedriver)."""
    if not (CHROMIUM and CHROMEDRIVER):
        pytest.skip("headless Chromium and chromedriver (Debian's chromium, chromium-driver) are not installed")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    for flag in ("--headless=new", "--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"):
        options.add_argument(flag)
    options.binary_location = CHROMIUM
    driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
    driver.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride", {"width": 900, "height": 480, "deviceScaleFactor": 1, "mobile": False}
    )
    yield driver
    driver.quit()


def _edited_by_click(run: Path, view: str, u: float, v: float, op: str, name: str) -> np.ndarray:
    """The Gaussians (N,) bool ``gsseg edit RUN --click VIEW U V --op OP --name NAME`` edits."""
    cmd = [script("gsseg"), "edit", str(run), "--click", view, str(u), str(v), "--op", op, "--name", name]
    r = subprocess.run([*cmd, "--backend", "cpu"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    kept = {tuple(p) for p in read_ply(run / "edits" / name / "gaussians.ply").means.numpy().tolist()}
    inside = np.array([tuple(p) in kept for p in load_run(run).gaussians.means.numpy().tolist()])
    return inside if op == "extract" else ~inside


def _canvas_image(driver, canvas) -> np.ndarray:
    """(H, W, 3) uint8 screenshot of the page cut to ``canvas``."""
    import cv2

    page = cv2.imdecode(np.frombuffer(driver.get_screenshot_as_png(), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
    x, y, w, h = (int(canvas.rect[k]) for k in ("x", "y", "width", "height"))
    return page[y : y + h, x : x + w]


def _wait(condition, seconds: float = 60.0, what: str = ""):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if value := condition():
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


class _Canvas:
    """The browser canvas (w x h CSS pixels) looking along a training view with its vertical
    field of view: canvas pixels <-> view pixels."""

    def __init__(self, canvas, camera) -> None:
        self.w, self.h, self.camera = int(canvas.rect["width"]), int(canvas.rect["height"]), camera
        self.f = camera.fy * self.h / camera.height

    def from_view(self, u: float, v: float) -> tuple[int, int]:
        c = self.camera
        return round((u - c.cx) / c.fx * self.f + self.w / 2), round((v - c.cy) / c.fy * self.f + self.h / 2)

    def to_view(self, x, y):
        """The view pixel (u, v) under canvas pixel centres (x + 0.5, y + 0.5); arrays welcome."""
        c = self.camera
        return (x + 0.5 - self.w / 2) / self.f * c.fx + c.cx, (y + 0.5 - self.h / 2) / self.f * c.fy + c.cy

    def region(self, inside: np.ndarray) -> np.ndarray:
        """(h, w) bool: the canvas pixels whose view pixel is true in (H, W) ``inside``."""
        u, v = (a.astype(int) for a in self.to_view(*np.meshgrid(np.arange(self.w), np.arange(self.h))))
        ok = (u >= 0) & (u < self.camera.width) & (v >= 0) & (v < self.camera.height)
        out = np.zeros((self.h, self.w), bool)
        out[ok] = inside[v[ok], u[ok]]
        return out


@pytest.mark.slow
def test_the_viewer_in_headless_chromium_selects_and_removes_by_click(segmented, tmp_path, browser):
    """On the test run, or on VIEWER_RUN (a segmented run, e.g. demo/run); VIEWER_SCREENSHOT
    names a file for the page after the removal (the README's picture)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    from gsseg.render.pixel_labels import segment_pixels
    from gsseg.viewer.server import Viewer

    run = Path(os.environ["VIEWER_RUN"]) if "VIEWER_RUN" in os.environ else _copy(segmented, tmp_path)
    viewer = Viewer(ViewerSession(load_run(run), backend="cpu", fill=QUICK_FILL), port=0)
    session, view = viewer.session, viewer.views[1]
    # the pixel of the view's largest object, found before the page opens (nothing renders beside it)
    mask = segment_pixels(
        session.run.gaussians,
        session.segmentation.labels,
        view.camera,
        torch.as_tensor(view.cam_from_world, dtype=torch.float32),
        backend="cpu",
    )
    label = int(np.bincount(mask.ravel())[1:].argmax() + 1)
    arrived = []  # the clicks the server received
    viewer._click = lambda event, mode, answer=viewer._click: arrived.append(mode) or answer(event, mode)

    def open_page():
        """The page, looking along ``view``, drawn, its notices closed: its canvas element and
        the canvas's frame."""
        browser.get(viewer.url)
        element = _wait(lambda: browser.find_elements(By.TAG_NAME, "canvas"), what="the canvas")[0]
        _wait(lambda: viewer.server.get_clients(), what="the browser to connect")
        viewer.go_to(view.name)
        _wait(lambda: _canvas_image(browser, element).std() > 20, what="a frame")  # the scene is drawn
        for close in browser.find_elements(By.CSS_SELECTOR, "[class*='Notification-close']"):
            close.click()  # the notice that WebGL runs in software covers part of the canvas
        time.sleep(1)
        return element, _canvas_image(browser, element)

    try:
        # a click on the pixel of the view's largest object selects it, and it is highlighted; a
        # click the page drops is clicked again on a page opened again
        for attempt in range(3):
            element, shown = open_page()
            canvas = _Canvas(element, view.camera)
            x, y = canvas.from_view(*_inside_pixel(mask, label))
            offset = (x - canvas.w // 2, y - canvas.h // 2)  # selenium's offsets are from the element's centre
            ActionChains(browser).move_to_element_with_offset(element, *offset).click().perform()
            try:
                _wait(lambda: viewer.session.selection() is not None, seconds=30, what="a selection")
                break
            except AssertionError as e:
                if attempt == 2:
                    panel = browser.find_element(By.TAG_NAME, "body").text.replace("\n", " | ")
                    raise AssertionError(f"{e}; the server received clicks {arrived}; the page reads: {panel}") from e

        def changes(region: np.ndarray, since: np.ndarray) -> bool:
            now = _canvas_image(browser, element)
            return np.abs(now[region].astype(int) - since[region].astype(int)).mean() > 25

        selected = viewer.session.selection()
        own = session.segmentation.labels == label
        assert (selected & own).sum() / (selected | own).sum() > 0.5
        region = canvas.region(ndimage.binary_erosion(mask == label, iterations=2))
        _wait(lambda: changes(region, shown), what="the highlight")
        highlighted = _canvas_image(browser, element)
        # the same pixel through `gsseg edit --click` selects the same Gaussians (up to the canvas's rounding
        # of the pixel, which moves the click's weights a little)
        u, v = canvas.to_view(x, y)
        extracted = complete_selection(session.run.gaussians, selected, session.scene.split("train")).mask
        by_cli = _edited_by_click(run, view.stem, u, v, "extract", "click")
        assert (by_cli & extracted).sum() / (by_cli | extracted).sum() > 0.99
        # "Remove" in the panel: the object's pixels change in the next frames
        browser.find_element(By.XPATH, "//button[normalize-space(.)='Remove']").click()
        _wait(lambda: viewer.session.steps, what="the removal")
        _wait(lambda: changes(region, highlighted) and changes(region, shown), what="the object to go")
        left = f"{len(viewer.session.current()[0]):,} Gaussians"  # the header counts what is shown
        assert left != f"{len(viewer.session.run.gaussians):,} Gaussians"
        _wait(lambda: left in browser.find_element(By.TAG_NAME, "body").text, what="the count after the removal")
        if target := os.environ.get("VIEWER_SCREENSHOT"):
            browser.get_screenshot_as_file(target)
    finally:
        browser.get("about:blank")
        viewer.stop()


@pytest.mark.slow
def test_relabelling_keeps_the_3d_regularisation_of_the_labels_shown(segmented, small_scene, tmp_path):
    """Labels made with ``--smooth --fill-interiors`` (saved with them) are reassigned with the
    same regularisation when gamma_p moves in the viewer."""
    run = _copy(segmented, tmp_path)
    options = LabelOptions(gamma_p=0.2, smooth=8, fill=True)
    segment_run(run, small_scene.root, options=options, backend="cpu", progress=False)
    session = ViewerSession(load_run(run), scene_dir=small_scene.root, backend="cpu")
    assert (session.segmentation.smooth, session.segmentation.fill) == (8, True)
    session.relabel("prior", 1.5)
    expected = segment_run(run, small_scene.root, options=replace(options, gamma_p=1.5), backend="cpu", progress=False)
    np.testing.assert_array_equal(session.segmentation.labels, expected.labels)
    assert (session.segmentation.smooth, session.segmentation.fill) == (8, True)
