"""``gsseg render``: a run's renders of a scene's views as PNG files any script can score."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from dataset_tools.depth_maps import write_depth
from dataset_tools.image_files import colorize_labels, write_png
from dataset_tools.infra.atomic import atomic_directory
from dataset_tools.infra.errors import OptionError, OutputExists
from dataset_tools.infra.overlap import refuse_overlap
from gsseg.render import Backend, get_backend, surface_depth, to_uint8
from gsseg.render.pixel_labels import classify_pixels, segment_pixels
from gsseg.run.loaded import load_run

PRODUCTS = ("rgb", "labels", "segments", "depth")


@torch.no_grad()
def render_run(
    run_dir: Path | str,
    scene_dir: Path | str | None,
    out: Path | str,
    *,
    split: str = "test",
    what: tuple[str, ...] = ("rgb", "labels"),
    colorize: bool = False,
    images: str | None = None,
    backend: str | Backend = "auto",
    overwrite: bool = False,
    other_scene: bool = False,
    progress: bool = True,
) -> Path:
    """Render the views of ``split`` and write ``out/rgb/<stem>.png``, ``out/labels/<stem>.png``
    (raw 8-bit classifier argmax), ``out/segments/<stem>.png`` (raw 8-bit labels of
    ``RUN/labels.npz``, by largest blended weight) and ``out/depth/<stem>.npy`` (camera depth,
    :mod:`dataset_tools.depth_maps`, for ``hqmask build --depth``); with ``colorize`` also
    ``out/<kind>_color/<stem>.png``. The folder appears complete or not at all; ``other_scene``
    renders on a scene other than the run's."""
    unknown = set(what) - set(PRODUCTS)
    if not what or unknown:
        raise OptionError(
            f"{{what}}: unknown products {', '.join(sorted(unknown)) or '(none given)'}; choose from "
            f"{', '.join(PRODUCTS)}.",
            what=",".join(what),
        )
    out = Path(out)
    run = load_run(run_dir, other_scene=other_scene)
    refuse_overlap(out, run.inputs(scene_dir))
    if out.exists() and not overwrite:
        raise OutputExists(out, " or choose another {out}")
    segmentation = run.labels() if "segments" in what else None
    backend = get_backend(backend)
    classifier = run.classifier.to(backend.device)
    with atomic_directory(out, overwrite=overwrite) as tmp:
        for view in tqdm(
            run.scene(scene_dir, images=images).split(split), desc="rendering", unit="view", disable=not progress
        ):
            result = run.render(view, with_features="labels" in what, backend=backend)
            if "rgb" in what:
                write_png(tmp / "rgb" / f"{view.stem}.png", to_uint8(result.rgb))
            if "depth" in what:
                write_depth(tmp / "depth" / f"{view.stem}.npy", surface_depth(result))
            maps = {}
            if "labels" in what:
                maps["labels"] = classify_pixels(result.features, classifier).cpu().numpy().astype(np.uint8)
            if segmentation is not None:
                pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
                maps["segments"] = segment_pixels(
                    run.gaussians_on(backend.device), segmentation.labels, view.camera, pose, backend=backend
                )
            for kind, ids in maps.items():
                write_png(tmp / kind / f"{view.stem}.png", ids)
                if colorize:
                    write_png(tmp / f"{kind}_color" / f"{view.stem}.png", colorize_labels(ids))
    return out
