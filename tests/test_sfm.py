"""Structure from motion: the cameras of a real capture recovered from its photos alone
(photos and a video), resumption, the camera-error metric, and bad input."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import script

from dataset_tools import InputError, load_scene
from dataset_tools.cameras import turned_frames
from dataset_tools.colmap import load_pycolmap
from dataset_tools.image_files import read_image
from dataset_tools.infra.locks import exclusive
from dataset_tools.sfm import SfmConfig, run_sfm
from dataset_tools.sfm.pipeline import (
    _input_images,
    incremental_options,
    mean_residuals,
    pixel_scale,
    sift_peak_threshold,
    weakly_posed,
)
from dataset_tools.synth import SynthConfig, generate_scene
from eval.metrics import camera_errors, similarity_alignment
from pipeline.demo import run_demo
from pipeline.demo_options import DemoOptions


def test_similarity_alignment_recovers_a_known_similarity():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(20, 3))
    angle = 0.7
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    s, R_found, t = similarity_alignment(points, 2.5 * points @ R.T + [1.0, -2.0, 0.5])
    assert s == pytest.approx(2.5) and np.allclose(R_found, R) and np.allclose(t, [1.0, -2.0, 0.5])


def test_camera_errors_are_zero_for_a_similar_copy_and_see_a_turned_camera():
    poses = [np.concatenate([np.eye(3), [[k], [0.3 * k * k], [3.0]]], 1) for k in range(-2, 3)]
    spin = np.deg2rad(40)
    Q = np.array([[1, 0, 0], [0, np.cos(spin), -np.sin(spin)], [0, np.sin(spin), np.cos(spin)]])
    copy = [np.concatenate([p[:, :3] @ Q.T, 0.5 * p[:, 3:]], 1) for p in poses]  # a turned world at half scale
    rot, ctr = camera_errors(copy, poses)
    assert np.allclose(rot, 0, atol=1e-5) and np.allclose(ctr, 0, atol=1e-9)
    turn = np.deg2rad(3)
    turned = np.array([[np.cos(turn), 0, np.sin(turn)], [0, 1, 0], [-np.sin(turn), 0, np.cos(turn)]])
    small = [np.concatenate([turned @ copy[0][:, :3], turned @ copy[0][:, 3:]], 1), *copy[1:]]  # about its centre
    rot, ctr = camera_errors(small, poses)
    shift = np.degrees(np.arctan2(np.sin(turn), 4 + np.cos(turn)))  # the chordal mean of 0, 0, 0, 0 and 3 degrees
    assert rot[0] == pytest.approx(3.0 - shift, abs=1e-6) and np.allclose(rot[1:], shift, atol=1e-6)
    assert np.allclose(ctr, 0, atol=1e-9)


def test_camera_errors_leave_a_camera_on_the_far_side_out_of_the_alignment():
    """A camera mapped to the far side (turned 180 degrees about the vertical through the
    scene's centre) shows its whole error; the other cameras stay exact."""
    poses = [np.concatenate([np.eye(3), [[k], [0.3 * k * k], [3.0]]], 1) for k in range(-3, 4)]
    half = np.diag([-1.0, 1.0, -1.0])  # 180 degrees about y, through the world origin
    copy = list(poses)
    copy[1] = np.concatenate([poses[1][:, :3] @ half.T, poses[1][:, 3:]], 1)
    rot, ctr = camera_errors(copy, poses)
    assert rot[1] == pytest.approx(180.0) and np.allclose(np.delete(rot, 1), 0, atol=1e-5)
    centre = -poses[1][:, :3].T @ poses[1][:, 3]
    extent = max(
        np.linalg.norm(-p[:, :3].T @ p[:, 3] - np.mean([-q[:, :3].T @ q[:, 3] for q in poses], 0)) for p in poses
    )
    assert ctr[1] == pytest.approx(np.linalg.norm(half @ centre - centre) / extent)
    assert np.allclose(np.delete(ctr, 1), 0, atol=1e-9)


def test_turned_frames_are_those_far_from_the_posed_frame_before():
    def turned(degrees: float) -> np.ndarray:
        a = np.deg2rad(degrees)
        return np.array([[np.cos(a), 0, np.sin(a), 0], [0, 1, 0, 0], [-np.sin(a), 0, np.cos(a), 0]])

    poses = {"f0": turned(0), "f1": turned(10), "f2": turned(170), "f3": turned(180), "f5": turned(235)}
    order = ["f0", "f1", "f2", "f3", "f4", "f5"]  # f4 unposed: f5 is not compared with f3
    assert turned_frames(poses, order) == ["f2"]
    assert turned_frames(poses, order, degrees=5) == ["f1", "f2", "f3"]


def test_sift_threshold_is_colmaps_for_large_images_and_lower_for_small_ones():
    assert sift_peak_threshold(1000) == sift_peak_threshold(4000) == pytest.approx(0.02 / 3)  # COLMAP's default
    assert sift_peak_threshold(320) == pytest.approx(0.32 * 0.02 / 3)
    assert sift_peak_threshold(64) == pytest.approx(0.25 * 0.02 / 3)  # a quarter at most


def test_weakly_posed_images_hold_under_a_fifth_of_the_median_share_of_3d_points():
    """Shares of keypoints with a 3D point 0.30, 0.25, 0.35, 0.05 and 0.049, all reprojecting
    alike: the median is 0.25 and a fifth of it 0.05; 0.049 is under it, 0.05 is not."""
    names = ["a", "b", "c", "d", "e"]
    keypoints = np.array([1000, 2000, 400, 1000, 1000])
    triangulated = np.array([300, 500, 140, 50, 49])
    alike = np.full(5, 0.5)
    assert weakly_posed(names, keypoints, triangulated, alike) == ["e"]
    assert weakly_posed(names, keypoints, keypoints, alike) == []  # all alike: none
    no_keypoints = np.array([0])  # share 0, as the median's
    assert weakly_posed(["x"], no_keypoints, no_keypoints, np.array([0.0])) == []


def test_a_pose_whose_points_reproject_far_has_its_share_discounted():
    """Shares 0.25 (the median) and 0.075 (0.3 of it): reprojecting twice as far as the median
    image's, the second's support is 0.15, under a fifth; reprojecting half as far earns the
    third nothing, at 0.04 of the median share (0.16 of it)."""
    names = ["a", "b", "c", "d", "e"]
    keypoints = np.full(5, 1000)
    triangulated = np.array([250, 75, 40, 250, 300])
    assert weakly_posed(names, keypoints, triangulated, np.array([0.5, 0.5, 0.5, 0.5, 0.5])) == ["c"]
    assert weakly_posed(names, keypoints, triangulated, np.array([0.5, 1.0, 0.25, 0.5, 0.5])) == ["b", "c"]


def test_mean_residuals_agree_with_colmaps_errors_of_the_points(beer):
    """Each image's mean distance between its keypoints and where their points project, times
    how many it has, summed over the images, is the sum over the points of COLMAP's mean error
    over each one's track times its length: both count every observation once."""
    pycolmap = load_pycolmap()
    model = pycolmap.Reconstruction(str(beer / "sparse" / "0"))
    model.update_point_3d_errors()
    counts = np.array([image.num_points3D for image in model.images.values()])
    by_points = sum(point.error * point.track.length() for point in model.points3D.values())
    assert np.sum(mean_residuals(model) * counts) == pytest.approx(by_points, rel=1e-6)


def test_mapper_thresholds_are_colmaps_for_large_images_and_scaled_for_small_ones():
    def thresholds(side: int) -> list[float]:
        o = incremental_options(pixel_scale(side), seed=0, threads=1)
        return [
            o.mapper.init_max_error,
            o.mapper.abs_pose_max_error,
            o.mapper.filter_max_reproj_error,
            o.triangulation.complete_max_reproj_error,
            o.triangulation.merge_max_reproj_error,
        ]

    assert thresholds(4000) == thresholds(1000) == pytest.approx([4, 12, 4, 4, 4])  # COLMAP's defaults
    assert thresholds(320) == pytest.approx([1.28, 3.84, 1.28, 1.28, 1.28])
    assert thresholds(64) == pytest.approx([1, 3, 1, 1, 1])  # a quarter at most
    assert incremental_options(1.0, seed=7, threads=1).random_seed == 7


def photos_of(beer: Path, out: Path, count: int) -> Path:
    """The first ``count`` photos of the beer capture at half size: what a user's photo folder holds."""
    out.mkdir()
    for path in sorted((beer / "images_2").iterdir())[:count]:
        shutil.copy(path, out / path.name)
    return out


@pytest.mark.slow
def test_sfm_recovers_the_cameras_of_a_real_capture_and_resumes(beer, tmp_path):
    """14 consecutive beer photos: every one registers, and the cameras agree with the
    capture's own COLMAP model (all 71 views at full size) to under a degree. (That model
    maps 0014.jpg to the far side of the can; the first 14 photos are before it.)"""
    photos = photos_of(beer, tmp_path / "photos", 14)
    result = run_sfm(photos, tmp_path / "scene", SfmConfig(), progress=False)
    assert result.registered == result.images == 14 and result.left_out == []
    made, truth = load_scene(result.scene), {v.name: v for v in load_scene(beer, images="images_2").views}
    assert made.views[0].camera.width > 0 and (result.scene / "images_2").is_dir()
    rot, ctr = camera_errors([v.cam_from_world for v in made.views], [truth[v.name].cam_from_world for v in made.views])
    assert np.median(rot) < 1.0 and rot.max() < 2.0 and np.median(ctr) < 0.02
    database = tmp_path / "scene" / ".sfm" / "database.db"
    stamp = database.stat().st_mtime_ns
    for name in ("images", "images_2", "images_4", "sparse", "scene.json"):  # a run cut before the end
        path = result.scene / name
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    again = run_sfm(photos, tmp_path / "scene", SfmConfig(), progress=False)
    assert again.registered == 14 and database.stat().st_mtime_ns == stamp  # nothing recomputed


@pytest.mark.slow
def test_sfm_takes_a_phone_style_video(beer, tmp_path):
    """20 beer photos as the frames of an MP4; 12 frames are kept and register."""
    frames = [read_image(p) for p in sorted((beer / "images_2").iterdir())[:20]]
    height, width = frames[0].shape[:2]
    video = tmp_path / "walk.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 10, (width, height))
    for frame in frames:
        writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    writer.release()
    result = run_sfm(video, tmp_path / "scene", SfmConfig(frames=12), progress=False)
    assert result.images == 12 and result.registered >= 10
    assert len(load_scene(result.scene).views) == result.registered


@pytest.fixture(scope="module")
def speckled(tmp_path_factory) -> Path:
    """A 40-view synthetic orbit with the irregular ground SIFT can match (the checker ground
    repeats), as photos and as the frames of a video."""
    return generate_scene(
        SynthConfig(views=40, res=320, objects=5, seed=3, ground="speckle"),
        tmp_path_factory.mktemp("sfm") / "truth",
        progress=False,
    ).root


@pytest.mark.slow
def test_sfm_recovers_the_exact_cameras_of_a_synthetic_orbit_and_again_the_same(speckled, tmp_path):
    """Every second photo of the orbit (20, 18 degrees apart). A second run on the same photos
    gives the same cameras (on several threads, COLMAP's CPU SIFT gives slightly different
    keypoints on this capture from run to run: about 1e-6). To 1e-3: the matching runs on
    every core, and two runs' poses once differed by 4e-5 on a loaded AMD EPYC, once by 3e-4
    on an Intel Xeon after the rest of the test suite (another model, from another initial
    pair or registration order, moves them by far more)."""
    (tmp_path / "photos").mkdir()
    for path in sorted((speckled / "images").iterdir())[::2]:
        shutil.copy(path, tmp_path / "photos" / path.name)
    result = run_sfm(tmp_path / "photos", tmp_path / "scene", progress=False)
    assert result.registered == result.images == 20
    made, truth = load_scene(result.scene), {v.name: v for v in load_scene(speckled).views}
    rot, ctr = camera_errors([v.cam_from_world for v in made.views], [truth[v.name].cam_from_world for v in made.views])
    assert np.median(rot) < 0.5 and np.median(ctr) < 0.01
    again = load_scene(run_sfm(tmp_path / "photos", tmp_path / "again", progress=False).scene)
    assert (
        np.abs(
            np.stack([v.cam_from_world for v in again.views]) - np.stack([v.cam_from_world for v in made.views])
        ).max()
        < 1e-3
    )


@pytest.mark.slow
def test_retrieval_matching_registers_shuffled_photos_with_fewer_pairs(speckled, tmp_path):
    """Two of every three of the orbit's photos (27, 9 and 18 degrees apart) renamed in a
    random order: each matched with its 8 most alike (VLAD of its SIFT descriptors), every
    photo registers with the cameras exhaustive matching finds, from under half of the pairs."""
    photos = tmp_path / "photos"
    photos.mkdir()
    kept = [path for k, path in enumerate(sorted((speckled / "images").iterdir())) if k % 3 != 2]
    for rank, path in zip(np.random.default_rng(0).permutation(len(kept)), kept):
        shutil.copy(path, photos / f"{rank:03d}_{path.name}")
    result = run_sfm(photos, tmp_path / "scene", SfmConfig(matcher="retrieval", neighbours=8), progress=False)
    assert result.registered == result.images == 27
    pairs = (tmp_path / "scene" / ".sfm" / "pairs.txt").read_text().splitlines()
    assert len(pairs) < 0.5 * 27 * 26 / 2
    made, truth = load_scene(result.scene), {v.name: v for v in load_scene(speckled).views}
    rot, ctr = camera_errors(
        [v.cam_from_world for v in made.views], [truth[v.name[4:]].cam_from_world for v in made.views]
    )
    assert np.median(rot) < 0.5 and np.median(ctr) < 0.01


def _video_of(views, path: Path) -> Path:
    """The views' images as the frames of an MP4 at 10 frames a second, as a phone writes one."""
    height, width = views[0].load_image().shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (width, height))
    for view in views:
        writer.write(cv2.cvtColor(view.load_image(), cv2.COLOR_RGB2BGR))
    writer.release()
    return path


@pytest.mark.slow
def test_demo_takes_a_synthetic_video_whose_frames_register_with_the_true_cameras(speckled, tmp_path):
    """The renders of the orbit as an MP4 (9 degrees a frame: an MP4's compression leaves too
    little of the ground's texture for wider steps) through ``gsseg demo --scene walk.mp4``:
    the frames register with the true cameras (frame k is view k), and every later stage runs
    (60 iterations at 160 px: plumbing, the scores mean nothing)."""
    views = load_scene(speckled).views
    video = _video_of(views, tmp_path / "walk.mp4")
    r = subprocess.run(
        [
            script("gsseg"),
            "demo",
            "--scene",
            str(video),
            "--out",
            str(tmp_path / "demo"),
            "--images",
            "images_2",
            "--iters",
            "60",
            "--backend",
            "cpu",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    made = load_scene(tmp_path / "demo" / "scene", masks=None).views
    assert len(made) >= 38
    truth = [views[int(Path(v.name).stem.split("_")[1])].cam_from_world for v in made]
    rot, ctr = camera_errors([v.cam_from_world for v in made], truth)
    assert np.median(rot) < 1.0 and np.median(ctr) < 0.02
    assert (tmp_path / "demo" / "report" / "report.html").is_file()
    assert sorted(p.name.split("_")[0] for p in (tmp_path / "demo" / "run" / "edits").iterdir()) == [
        "extract",
        "recolor",
        "remove",
    ]


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p.mkdir(), "holds no JPEG or PNG images"),
        (lambda p: (p.mkdir(), (p / "a.jpg").write_bytes(b"\xff\xd8\xff junk")), "not a readable image"),
        (lambda p: p.with_suffix(".mp4").write_text("not a video") or None, "cannot open this video"),
    ],
)
def test_bad_photos_are_one_sentence_and_write_nothing(tmp_path, make, message):
    source = tmp_path / "photos"
    make(source)
    source = source if source.exists() else source.with_suffix(".mp4")
    with pytest.raises(InputError, match=message):
        run_sfm(source, tmp_path / "scene", progress=False)
    assert not (tmp_path / "scene").exists()  # not even the work folder


@pytest.mark.slow
def test_photos_that_do_not_overlap_are_refused(tmp_path):
    """Noise images: no two of them match, so no model forms."""
    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for k in range(5):
        cv2.imwrite(str(photos / f"{k}.png"), rng.integers(0, 255, (120, 160, 3), dtype=np.uint8))
    with pytest.raises(InputError, match="need more overlap"):
        run_sfm(photos, tmp_path / "scene", progress=False)
    assert not (tmp_path / "scene").exists()
    for _ in range(2):  # a refused demo leaves nothing, so the plain retry is refused for the same reason
        with pytest.raises(InputError, match="need more overlap"):
            run_demo(tmp_path / "demo", DemoOptions(scene=photos, backend="cpu"), progress=False)
        assert not (tmp_path / "demo").exists()


def _some_photos(speckled: Path, into: Path, first: int, count: int = 12) -> Path:
    """``count`` consecutive orbit views from ``first``, named 00.png, 01.png, ..."""
    into.mkdir()
    for k, src in enumerate(sorted((speckled / "images").iterdir())[first : first + count]):
        shutil.copy(src, into / f"{k:02d}.png")
    return into


@pytest.mark.slow
def test_sfm_redoes_its_steps_when_the_photos_change_under_the_same_names(speckled, tmp_path):
    photos = _some_photos(speckled, tmp_path / "photos", 0)
    run_sfm(photos, tmp_path / "scene", progress=False)
    old = {p.name: read_image(p) for p in photos.iterdir()}
    shutil.rmtree(photos)
    _some_photos(speckled, photos, 20)
    result = run_sfm(photos, tmp_path / "scene", overwrite=True, progress=False)
    assert result.registered == 12
    for view in load_scene(result.scene).views:  # undistorted: compare at the photo's size
        image = view.load_image().astype(float)
        new = cv2.resize(read_image(photos / view.name), image.shape[1::-1]).astype(float)
        before = cv2.resize(old[view.name], image.shape[1::-1]).astype(float)
        assert np.abs(image - new).mean() < 0.25 * np.abs(image - before).mean()


@pytest.mark.slow
def test_photos_of_two_sizes_register_with_a_camera_each(speckled, tmp_path):
    """A phone mixes sizes (portrait and landscape, or a cropped photo): one shared camera
    cannot fit both, so each photo gets its own."""
    photos = _some_photos(speckled, tmp_path / "photos", 0)
    image = read_image(photos / "05.png")
    cv2.imwrite(str(photos / "05.png"), cv2.cvtColor(cv2.resize(image, (240, 240)), cv2.COLOR_RGB2BGR))
    result = run_sfm(photos, tmp_path / "scene", progress=False)
    assert result.registered == 12
    with pytest.raises(InputError, match=r"2 sizes \(240x240, 320x320\)"):
        run_sfm(photos, tmp_path / "one_camera", SfmConfig(single_camera=True), progress=False)
    assert not (tmp_path / "one_camera").exists()


def test_the_photo_search_skips_scene_folders_and_hidden_ones(tmp_path):
    photos = tmp_path / "photos"
    for name in (
        "a.jpg",
        "trip/b.png",
        "scene/images/c.png",
        "old/.sfm/frames/d.png",
        ".thumbs/e.png",
        "copy/images_2/f.png",
    ):
        (photos / name).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(photos / name), np.full((8, 8, 3), 128, np.uint8))
    (photos / "scene" / "scene.json").write_text("{}")
    (photos / "copy" / "sparse").mkdir()
    assert _input_images(photos) == ["a.jpg", "trip/b.png"]


def test_a_second_sfm_on_one_output_is_refused_and_a_full_disk_is_one_sentence(tmp_path, monkeypatch):
    photos = tmp_path / "photos"
    photos.mkdir()
    for k in range(3):
        cv2.imwrite(str(photos / f"{k}.png"), np.full((64, 64, 3), 40 * k, np.uint8))
    with exclusive(tmp_path / "scene" / ".sfm" / "lock", tmp_path / "scene", "this scene"):
        with pytest.raises(InputError, match="is writing this scene"):
            run_sfm(photos, tmp_path / "scene", progress=False)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9 - 10**6, 10**6))
    with pytest.raises(InputError, match=r"0.00 GB free, structure from motion needs about 0.0\d GB"):
        run_sfm(photos, tmp_path / "full", progress=False)
    assert not (tmp_path / "full").exists()
