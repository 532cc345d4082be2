"""Frames of a video for structure from motion: a target number of frames spread evenly over
it, each the sharpest of its interval (variance of the Laplacian), so that motion blur, the
commonest fault of a handheld video, is skipped where the video allows."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from dataset_tools.infra.errors import InputError

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".m4v", ".webm", ".MP4", ".MOV", ".AVI", ".MKV", ".M4V")


def sharpness(frame: np.ndarray) -> float:
    """Variance of the Laplacian of the grey frame at most 640 px wide: high when sharp."""
    grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    scale = min(1.0, 640 / grey.shape[1])
    if scale < 1:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return float(cv2.Laplacian(grey, cv2.CV_64F).var())


def _open(video: Path) -> cv2.VideoCapture:
    capture = cv2.VideoCapture(str(video))
    if not capture.isOpened():
        raise InputError(f"{video}: OpenCV cannot open this video; convert it to H.264 MP4 or pass a folder of photos.")
    return capture


def sample_frames(video: Path, out_dir: Path, count: int, *, progress: bool = True) -> list[str]:
    """Write ``count`` frames of ``video`` (or all of them, when it has fewer) as
    ``out_dir/frame_NNNNN.jpg``, frame k of the result the sharpest of the k-th of ``count``
    equal intervals. Returns the file names, in video order."""
    capture = _open(video)
    scores = []
    with tqdm(desc="scoring frames", unit="frame", disable=not progress, leave=False) as bar:
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            scores.append(sharpness(frame))
            bar.update(1)
    capture.release()
    if len(scores) < 2:
        raise InputError(f"{video}: OpenCV reads {len(scores)} frame(s) from this video; it needs at least two.")
    bounds = np.linspace(0, len(scores), min(count, len(scores)) + 1).round().astype(int)
    keep = {int(a + np.argmax(scores[a:b])) for a, b in zip(bounds[:-1], bounds[1:]) if b > a}
    out_dir.mkdir(parents=True, exist_ok=True)
    names = []
    capture = _open(video)
    for index in tqdm(range(len(scores)), desc="extracting frames", unit="frame", disable=not progress, leave=False):
        ok, frame = capture.read()
        if not ok:
            break
        if index in keep:
            name = f"frame_{index:05d}.jpg"
            ok, data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 95])
            (out_dir / name).write_bytes(data.tobytes())
            names.append(name)
    capture.release()
    return names
