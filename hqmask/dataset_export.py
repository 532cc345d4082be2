"""Export a scene with its masks as a Hugging Face ``datasets`` dataset."""

from __future__ import annotations

from pathlib import Path

from dataset_tools.atomic import atomic_directory
from dataset_tools.errors import InputError
from dataset_tools.scene import Scene


def export_dataset(scene: Scene, out: Path, *, overwrite: bool = False, shard_views: int = 64) -> Path:
    """Write one row per view (image, mask, intrinsics, extrinsics, view and scene name).

    ``out`` holds the dataset as ``datasets.save_to_disk`` writes it (load it with
    ``datasets.load_from_disk``) and the same rows as parquet shards in ``out/parquet/``.
    """
    import datasets
    from PIL import Image

    out = Path(out)
    if out.exists() and not overwrite:
        raise InputError(f"{out}: already exists; choose another --dataset or pass --force.")
    features = datasets.Features(
        {
            "image": datasets.Image(),
            "mask": datasets.Image(),
            "intrinsics": datasets.Sequence(datasets.Value("float64"), length=4),
            "width": datasets.Value("int32"),
            "height": datasets.Value("int32"),
            "cam_from_world": datasets.Sequence(datasets.Sequence(datasets.Value("float64"), length=4), length=3),
            "view": datasets.Value("string"),
            "scene": datasets.Value("string"),
            "split": datasets.Value("string"),
        }
    )

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

    ds = datasets.Dataset.from_list(list(rows()), features=features)
    with atomic_directory(out, overwrite=overwrite) as tmp:
        ds.save_to_disk(str(tmp))
        n = max(1, -(-len(ds) // shard_views))
        (tmp / "parquet").mkdir()
        for k in range(n):
            ds.shard(n, k, contiguous=True).to_parquet(str(tmp / "parquet" / f"train-{k:05d}-of-{n:05d}.parquet"))
    return out
