"""A text summary of a scene folder and a contact sheet of its views beside their masks."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from dataset_tools.image_files import colorize_labels, write_png
from dataset_tools.mask_manifest import describe, read_manifest
from dataset_tools.scene import Scene


@dataclass
class SceneSummary:
    root: str
    views: int
    train: int
    test: int
    image_dir: str
    resolutions: list[tuple[int, int]]
    undistorted: int
    points: int
    mean_track_length: float
    mask_dir: str | None
    masked_views: int
    object_ids: list[int]
    made: str | None = None  # how the masks were made (their manifest), when there are masks
    other_masks: dict[str, str] = field(default_factory=dict)  # every other mask folder: how it was made

    def __str__(self) -> str:
        sizes = [f"{w}x{h}" for w, h in self.resolutions]
        res = sizes[0] if len(sizes) == 1 else f"{len(sizes)} sizes, {sizes[0]} .. {sizes[-1]}"
        ids = self.object_ids
        id_text = f"{len(ids)} ({ids[0]}..{ids[-1]})" if ids else "none"
        return "\n".join(
            [
                f"scene        {self.root}",
                f"views        {self.views} ({self.train} train, {self.test} test) from {self.image_dir}/",
                f"resolution   {res}"
                + (f"  ({self.undistorted} views undistorted to pinhole)" if self.undistorted else ""),
                f"points3D     {self.points} (mean track length {self.mean_track_length:.2f})",
                f"masks        {self.mask_dir or 'none'}: {self.masked_views} of {self.views} views",
                *([f"made by      {self.made}"] if self.made else []),
                f"object IDs   {id_text}",
                *[f"also masks   {name}: {made}" for name, made in sorted(self.other_masks.items())],
            ]
        )


def mask_folders(root: Path) -> dict[str, str]:
    """Every mask folder of the scene ``root`` (a folder of PNGs other than the images, or one
    with a manifest), with how it was made."""
    found = {}
    for folder in sorted(p for p in Path(root).iterdir() if p.is_dir() and not p.name.startswith(".")):
        if folder.name.startswith("images") or folder.name == "sparse":
            continue
        record = read_manifest(folder)
        if record is not None or next(folder.glob("*.png"), None) is not None:
            found[folder.name] = describe(record)
    return found


def summarize(scene: Scene) -> SceneSummary:
    """Counts, resolutions, tracks and the object IDs found in the masks (reads every mask)."""
    ids: set[int] = set()
    masked = 0
    for v in scene.views:
        m = v.load_mask()
        if m is not None:
            masked += 1
            ids.update(int(x) for x in np.unique(m) if x > 0)
    n_obs = sum(len(v.point_ids) for v in scene.views)
    return SceneSummary(
        root=str(scene.root),
        views=len(scene.views),
        train=len(scene.split("train")),
        test=len(scene.split("test")),
        image_dir=scene.image_dir,
        resolutions=sorted({(v.camera.width, v.camera.height) for v in scene.views}),
        undistorted=sum(v.source_camera is not None for v in scene.views),
        points=len(scene.points),
        mean_track_length=n_obs / max(len(scene.points), 1),
        mask_dir=scene.mask_dir,
        masked_views=masked,
        object_ids=sorted(ids),
        made=describe(read_manifest(scene.root / scene.mask_dir)) if scene.mask_dir else None,
        other_masks={k: v for k, v in mask_folders(scene.root).items() if k != scene.mask_dir},
    )


def contact_sheet(scene: Scene, out: Path, *, max_views: int = 12, thumb: int = 192, columns: int = 4) -> Path:
    """Write a PNG grid of thumbnails: each view's image beside its colourised mask.

    Views are picked evenly over the scene; a view without a mask shows a grey panel.
    """
    picks = np.unique(np.linspace(0, len(scene.views) - 1, min(max_views, len(scene.views))).round().astype(int))
    views = [scene.views[k] for k in picks]
    scales = [thumb / max(v.camera.width, v.camera.height) for v in views]
    sizes = [(max(1, round(v.camera.width * s)), max(1, round(v.camera.height * s))) for v, s in zip(views, scales)]
    panel_w, panel_h = max(w for w, _ in sizes), max(h for _, h in sizes)
    tiles = []
    for v, size in zip(views, sizes):
        img = cv2.resize(v.load_image(), size, interpolation=cv2.INTER_AREA)
        mask = v.load_mask()
        right = (
            colorize_labels(cv2.resize(mask, size, interpolation=cv2.INTER_NEAREST))
            if mask is not None
            else np.full_like(img, 96)
        )
        pair = np.zeros((panel_h + 18, 2 * panel_w + 8, 3), np.uint8)
        pair[18 : 18 + size[1], : size[0]] = img
        pair[18 : 18 + size[1], panel_w + 4 : panel_w + 4 + size[0]] = right
        cv2.putText(pair, v.name, (2, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(pair)
    while len(tiles) % columns:
        tiles.append(np.zeros_like(tiles[0]))
    rows = [np.concatenate(tiles[i : i + columns], axis=1) for i in range(0, len(tiles), columns)]
    sheet = np.concatenate(rows, axis=0)
    write_png(out, sheet)
    return Path(out)
