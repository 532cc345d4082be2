"""Scenes as Hugging Face ``datasets`` rows and back: one row per view with its image, mask,
pinhole camera, pose, view name, scene name and split."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from dataset_tools import colmap
from dataset_tools.cameras import PinholeCamera
from dataset_tools.image_files import as_label_map, encode_png
from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.errors import InputError, OutputExists
from dataset_tools.scene import MASKS, Scene

COLUMNS = ("image", "mask", "intrinsics", "width", "height", "cam_from_world", "view", "scene", "split")


def dataset_features():
    """The ``datasets.Features`` of a view row."""
    import datasets

    return datasets.Features(
        {
            "image": datasets.Image(),
            "mask": datasets.Image(),
            "intrinsics": datasets.Sequence(datasets.Value("float64"), length=4),  # fx, fy, cx, cy
            "width": datasets.Value("int32"),
            "height": datasets.Value("int32"),
            "cam_from_world": datasets.Sequence(datasets.Sequence(datasets.Value("float64"), length=4), length=3),
            "view": datasets.Value("string"),
            "scene": datasets.Value("string"),
            "split": datasets.Value("string"),
        }
    )


def export_dataset(scene: Scene, out: Path, *, overwrite: bool = False, shard_views: int = 64) -> Path:
    """Write one row per view (image, mask, intrinsics, extrinsics, view and scene name).

    ``out`` holds the dataset as ``datasets.save_to_disk`` writes it (load it with
    ``datasets.load_from_disk``) and the same rows as parquet shards in ``out/parquet/``.
    """
    import datasets
    from PIL import Image

    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExists(out)

    def rows():
        for v in scene.views:
            mask = v.load_mask()
            yield {
                "image": Image.fromarray(v.load_image()),
                "mask": Image.fromarray(mask) if mask is not None else None,
                "intrinsics": [v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy],
                "width": v.camera.width,
                "height": v.camera.height,
                "cam_from_world": v.cam_from_world.tolist(),
                "view": v.stem,
                "scene": scene.root.name,
                "split": "test" if v.name in scene.test_names else "train",
            }

    ds = datasets.Dataset.from_list(list(rows()), features=dataset_features())
    with atomic_directory(out, overwrite=overwrite) as tmp:
        ds.save_to_disk(str(tmp))
        n = max(1, -(-len(ds) // shard_views))
        (tmp / "parquet").mkdir()
        for k in range(n):
            ds.shard(n, k, contiguous=True).to_parquet(str(tmp / "parquet" / f"train-{k:05d}-of-{n:05d}.parquet"))
    return out


def write_scenes_from_rows(
    rows, out: Path, *, scenes: list[str] | None = None, masks: str = MASKS, overwrite: bool = False
) -> list[Path]:
    """Write the scenes of a ``datasets.Dataset`` of view rows (:data:`COLUMNS`) as scene
    folders ``out/<scene>/`` (PNG images, ``<masks>/`` ID maps, a pinhole COLMAP model without
    points, the split in scene.json). ``scenes`` keeps only those names. Each folder appears
    whole or not at all."""
    missing = set(COLUMNS) - set(rows.column_names)
    if missing:
        raise InputError(f"the dataset rows lack the columns {sorted(missing)}; expected {', '.join(COLUMNS)}.")
    by_scene: dict[str, list[int]] = defaultdict(list)
    for k, name in enumerate(rows["scene"]):
        if scenes is None or name in scenes:
            by_scene[name].append(k)
    written = []
    for name, indices in sorted(by_scene.items()):
        dst = Path(out) / name
        if dst.exists() and not overwrite:
            raise OutputExists(dst)
        with atomic_directory(dst, overwrite=overwrite) as tmp:
            names, cameras, poses, test = [], [], [], []
            for k in indices:
                row = rows[k]
                image_name = f"{row['view']}.png"
                write_bytes_atomic(tmp / "images" / image_name, encode_png(np.asarray(row["image"].convert("RGB"))))
                if row["mask"] is not None:
                    mask = as_label_map(np.asarray(row["mask"]), f"{name}/{row['view']} mask")
                    write_bytes_atomic(tmp / masks / image_name, encode_png(mask))
                names.append(image_name)
                cameras.append(PinholeCamera(row["width"], row["height"], *row["intrinsics"]))
                poses.append(np.asarray(row["cam_from_world"], dtype=np.float64))
                if row["split"] == "test":
                    test.append(image_name)
            empty = (np.zeros(0, np.int64), np.zeros((0, 2)))
            colmap.write_model(
                tmp / "sparse" / "0",
                names,
                cameras,
                poses,
                [empty] * len(names),
                np.zeros((0, 3)),
                np.zeros((0, 3), np.uint8),
            )
            write_bytes_atomic(tmp / "scene.json", json.dumps({"split": {"test": sorted(test)}}, indent=2).encode())
        written.append(dst)
    return written
