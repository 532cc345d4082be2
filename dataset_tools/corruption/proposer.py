"""The ``proposer`` family of mask errors: what an automatic proposer such as SAM does to a
capture, with errors that persist over runs of consecutive views (a proposer sees
neighbouring frames alike), built independently of the ``blobs`` family:

1. Granularity switches: over a run of views an object is given as 2 or 3 parts (bands
   across a direction fixed for the run), whole elsewhere.
2. Merges: over a run of views an object shares the ID of its nearest neighbour.
3. Misses: over a run of views an object is not proposed at all.
4. Shadow fragments: over a run of views the ground under an object (its shadow, a
   reflection) is proposed as an object of its own.
5. Background fragments: in each view a Poisson number of background patches (a tile, a
   stain) are proposed as objects.
6. Bleeding boundaries: in each view some objects spill a few pixels into the background
   on one side.
7. Boundary jitter and the per-view permutation of IDs, as in every proposer's output.

A run starts at a random view and lasts 1 to ``run_share`` of the views. Sizes are given at
512 x 512 and scale with the image (:mod:`dataset_tools.corruption.ops`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dataset_tools.corruption.ops import area_scale, blob, ellipse, free_ids, jitter, nearest_other, objects, permute


@dataclass(frozen=True)
class ProposerModel:
    """Per-object probabilities of a run of each error, per-view rates, and sizes at 512 x 512."""

    p_parts: float
    p_merge: float
    p_miss: float
    p_shadow: float
    fragments: float  # Poisson mean of background fragments a view
    p_bleed: float  # per object and view
    bleed_px: float
    jitter_px: float
    run_share: float = 0.25
    fragment_share: tuple[float, float] = (0.001, 0.006)  # of the image area
    jitter_scale_px: float = 6.0


SEVERITIES: dict[str, ProposerModel] = {
    "low": ProposerModel(
        p_parts=0.05, p_merge=0.03, p_miss=0.02, p_shadow=0.1, fragments=0.5, p_bleed=0.1, bleed_px=1.5, jitter_px=0.5
    ),
    "medium": ProposerModel(
        p_parts=0.15, p_merge=0.08, p_miss=0.06, p_shadow=0.25, fragments=1.0, p_bleed=0.25, bleed_px=2.5, jitter_px=1.0
    ),
    "high": ProposerModel(
        p_parts=0.3, p_merge=0.15, p_miss=0.12, p_shadow=0.5, fragments=2.0, p_bleed=0.5, bleed_px=4.0, jitter_px=2.0
    ),
}


@dataclass(frozen=True)
class Run:
    """One error of one object over views ``start`` .. ``stop - 1``; ``angle`` and ``parts``
    fix how a granularity switch cuts it."""

    kind: str
    label: int
    start: int
    stop: int
    angle: float = 0.0
    parts: int = 2


def plan_runs(labels: list[int], n_views: int, model: ProposerModel, rng: np.random.Generator) -> list[Run]:
    """The runs of a scene: for each object and kind, with the kind's probability, one run."""
    longest = max(1, int(np.ceil(model.run_share * n_views)))
    runs = []
    for label in labels:
        for kind, p in (
            ("parts", model.p_parts),
            ("merge", model.p_merge),
            ("miss", model.p_miss),
            ("shadow", model.p_shadow),
        ):
            if rng.uniform() < p:
                start = int(rng.integers(n_views))
                length = int(rng.integers(1, longest + 1))
                runs.append(
                    Run(
                        kind,
                        label,
                        start,
                        min(n_views, start + length),
                        float(rng.uniform(0, np.pi)),
                        int(rng.integers(2, 4)),
                    )
                )
    return runs


def _parts(out: np.ndarray, mask: np.ndarray, run: Run, free: list[int]) -> None:
    """Cut ``mask`` into ``run.parts`` bands across direction ``run.angle``; all but the first get new IDs."""
    ys, xs = np.nonzero(mask)
    t = xs * np.cos(run.angle) + ys * np.sin(run.angle)
    edges = np.quantile(t, np.linspace(0, 1, run.parts + 1)[1:-1])
    band = np.searchsorted(edges, t)
    for k in range(1, run.parts):
        if free:
            out[ys[band == k], xs[band == k]] = free.pop()


def _shadow(out: np.ndarray, mask: np.ndarray, free: list[int]) -> None:
    """The ground under ``mask``: a flat ellipse at its lowest pixels, on background only."""
    ys, xs = np.nonzero(mask)
    height, width = ys.max() - ys.min() + 1, xs.max() - xs.min() + 1
    region = ellipse(out.shape, (ys.max() + 0.1 * height, xs.mean()), (0.6 * width, 0.15 * height), 0.0)
    region &= out == 0
    if free and region.any():
        out[region] = free.pop()


def _bleed(out: np.ndarray, label: int, px: float, rng: np.random.Generator) -> None:
    """``label`` spills ``px`` pixels into the background in a random direction."""
    angle = rng.uniform(0, 2 * np.pi)
    dy, dx = int(round(px * np.sin(angle))), int(round(px * np.cos(angle)))
    mask = out == label
    shifted = np.zeros_like(mask)
    H, W = mask.shape
    shifted[max(dy, 0) : H + min(dy, 0), max(dx, 0) : W + min(dx, 0)] = mask[
        max(-dy, 0) : H + min(-dy, 0), max(-dx, 0) : W + min(-dx, 0)
    ]
    out[shifted & (out == 0)] = label


def corrupt_view(
    ids: np.ndarray, view: int, runs: list[Run], model: ProposerModel, rng: np.random.Generator
) -> np.ndarray:
    """Corrupt view number ``view`` of a scene whose runs are ``runs``. (H, W) uint8 -> (H, W) uint8."""
    s = area_scale(ids.shape)
    out = ids.copy()
    free = free_ids(ids)
    active = [r for r in runs if r.start <= view < r.stop and np.any(ids == r.label)]
    for run in (r for r in active if r.kind == "parts"):
        _parts(out, ids == run.label, run, free)
    for run in (r for r in active if r.kind == "merge"):
        other = nearest_other(ids, run.label)
        if other is not None:
            out[ids == run.label] = out[ids == other][0]
    for run in (r for r in active if r.kind == "miss"):
        out[ids == run.label] = 0
    for run in (r for r in active if r.kind == "shadow"):
        _shadow(out, ids == run.label, free)
    for _ in range(int(rng.poisson(model.fragments))):
        background = np.argwhere(out == 0)
        if len(background) and free:
            area = rng.uniform(*model.fragment_share) * ids.size
            center = background[rng.integers(len(background))]
            out[blob(ids.shape, area, rng, tuple(center)) & (out == 0)] = free.pop()
    for label in objects(out):
        if rng.uniform() < model.p_bleed:
            _bleed(out, int(label), model.bleed_px * np.sqrt(s), rng)
    out = jitter(out, model.jitter_px * np.sqrt(s), model.jitter_scale_px * np.sqrt(s), rng)
    return permute(out, rng)
