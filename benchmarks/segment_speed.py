"""Benchmark: (1) the contribution pass against an RGB forward render over the same views (on
``cpu``, and on ``gsplat`` where a GPU is present);
(2) reassignment of N = 1M Gaussians over 64 labels in both modes, and the binary mode
against a faithful per-label Python loop in the style of the seed authors' code, on the
same inputs (selections must agree);
(3) the 3D regularisations of ``gsseg segment --smooth 16 --fill-interiors`` on N points: 16
hollow spheres labelled as objects, with background points inside them (which the fill must
give to their sphere) and around them (which it must not). Prints and writes JSON.

    python -m benchmarks.segment_speed [--out segment_speed.json] [--gaussians 1000000] [--labels 64]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from benchmarks import record
from benchmarks.render_speed import scene
from eval.report import markdown_table
from gsseg.render import BACKENDS, get_backend, render
from gsseg.render.contributions import Contributions, MaskedView, contribution_matrix
from gsseg.segment.label_options import LabelOptions
from gsseg.segment.reassign import Segmentation, reassign
from gsseg.segment.regularize import fill_interiors, smooth_weak_labels


def seed_style_binary(
    weights: torch.Tensor, labels: np.ndarray, prior_labels: torch.Tensor, prior_probs: torch.Tensor, gamma_p: float
) -> dict[int, torch.Tensor]:
    """One object at a time, as the seed authors' code does it: normalise, stack [rest, object],
    add the prior to the side the classifier picks, argmax."""
    selections = {}
    for row, obj in enumerate(labels):
        if obj == 0:
            continue
        total = weights.sum(0)
        observed = total > 0
        share = weights[row] / torch.where(observed, total, torch.ones_like(total))
        stacked = torch.stack([1 - share, share])
        mine = prior_labels == int(obj)
        stacked[1] += gamma_p * prior_probs * mine
        stacked[0] += gamma_p * prior_probs * ~mine
        selections[int(obj)] = torch.where(observed, stacked.argmax(0) == 1, mine)
    return selections


def timed(fn, repeats: int = 3):
    best, result = float("inf"), None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        if torch.cuda.is_available():
            torch.cuda.synchronize()
        best = min(best, time.perf_counter() - start)
    return best, result


def contribution_vs_rgb(backend: str) -> dict:
    """The contribution pass and an RGB forward render of the same 4 views, 30k Gaussians at
    256x256 and 8 labels, on one backend."""
    g, cam, pose = scene(30_000)
    rng = np.random.default_rng(0)
    mask = np.kron(rng.integers(0, 8, (8, 8)), np.ones((32, 32), int)).astype(np.uint8)
    views = [MaskedView(cam, pose.numpy(), mask)] * 4
    device = get_backend(backend).device
    on_device, pose_on_device = g.to(device), pose.to(device)
    with torch.no_grad():
        t_rgb, _ = timed(
            lambda: [render(on_device, cam, pose_on_device, with_features=False, backend=backend) for _ in views]
        )
    t_contrib, _ = timed(lambda: contribution_matrix(g, views, backend=backend, progress=False))
    return {
        "gaussians": len(g),
        "views": len(views),
        "size": [cam.width, cam.height],
        "rgb_forward_s": t_rgb,
        "contribution_s": t_contrib,
        "ratio": t_contrib / t_rgb,
    }


def hollow_spheres(n: int, objects: int = 16, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, 3) points: ``objects`` spheres of radius 0.5 in a 12 x 12 x 2 box, their shells
    (half the points, labelled 1..objects), points inside them (a tenth, labelled 0) and
    around them (the rest, labelled 0, outside every sphere); (n,) uint8 labels; (n,) the
    sphere each point lies inside, -1 for none."""
    rng = np.random.default_rng(seed)
    centres = np.c_[rng.uniform(1, 11, (objects, 2)), np.ones(objects)]
    shell_n, inside_n = n // 2, n // 10
    which = rng.integers(0, objects, shell_n)
    direction = rng.normal(size=(shell_n, 3))
    shell = centres[which] + 0.5 * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    shell += rng.normal(0, 0.005, shell.shape)
    held = rng.integers(0, objects, inside_n)
    ball = rng.normal(size=(inside_n, 3))
    ball *= (0.4 * rng.random(inside_n) ** (1 / 3) / np.linalg.norm(ball, axis=1))[:, None]
    around = rng.uniform([0, 0, 0], [12, 12, 2], (2 * (n - shell_n - inside_n), 3))
    far = np.linalg.norm(around[:, None] - centres[None], axis=2).min(1) > 0.6
    around = around[far][: n - shell_n - inside_n]
    points = np.concatenate([shell, centres[held] + ball, around])
    labels = np.concatenate([which + 1, np.zeros(len(ball) + len(around), int)]).astype(np.uint8)
    inside = np.concatenate([np.full(shell_n, -1), held, np.full(len(around), -1)])
    return points, labels, inside


def regularisations(n: int) -> dict:
    """:func:`smooth_weak_labels` (k = 16, 40% of the points weak) and :func:`fill_interiors`
    on :func:`hollow_spheres`; the share of the inner points the fill gives to their sphere,
    and of the points around the spheres it gives to any."""
    points, labels, inside = hollow_spheres(n)
    segmentation = Segmentation.of_labels(labels, "prior", gamma_p=0.2)
    rng = np.random.default_rng(1)
    weak, opacities = rng.random(len(points)) < 0.4, rng.random(len(points))
    t_smooth, _ = timed(lambda: smooth_weak_labels(segmentation, points, opacities, weak, k=16), repeats=1)
    t_fill, filled = timed(lambda: fill_interiors(segmentation, points), repeats=1)
    held = inside >= 0
    return {
        "gaussians": len(points),
        "smooth_s": t_smooth,
        "fill_s": t_fill,
        "inner_filled": float((filled.labels[held] == inside[held] + 1).mean()),
        "around_taken": float((filled.labels[(labels == 0) & ~held] > 0).mean()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/segment_speed.json).")
    parser.add_argument("--gaussians", type=int, default=1_000_000)
    parser.add_argument("--labels", type=int, default=64)
    args = parser.parse_args()
    out = {}

    out["contribution"] = contribution_vs_rgb("cpu")
    if BACKENDS["gsplat"].available():
        out["contribution_gsplat"] = contribution_vs_rgb("gsplat")

    # (2) reassignment at scale
    n, k = args.gaussians, args.labels
    gen = torch.Generator().manual_seed(0)
    weights = torch.rand(k, n, generator=gen) ** 4 * (torch.rand(n, generator=gen) > 0.05)
    labels = np.arange(k, dtype=np.uint8)
    contrib = Contributions(labels=labels, weights=weights)
    prior = torch.randint(0, k, (n,), generator=gen)
    probs = torch.rand(n, generator=gen)
    t_multi, _ = timed(lambda: reassign(contrib, prior, probs, LabelOptions(mode="multi")))
    t_binary, seg = timed(lambda: reassign(contrib, prior, probs, LabelOptions(mode="binary")))
    t_loop, ref = timed(lambda: seed_style_binary(weights, labels, prior, probs, 0.2), repeats=1)
    agree = all(np.array_equal(seg.selection(obj), sel.numpy()) for obj, sel in ref.items())
    out["reassignment"] = {
        "gaussians": n,
        "labels": k,
        "multi_s": t_multi,
        "binary_s": t_binary,
        "seed_style_loop_s": t_loop,
        "loop_over_binary": t_loop / t_binary,
        "binary_equals_loop": agree,
    }
    out["regularisations"] = regularisations(n)
    print(json.dumps(out, indent=2))
    record.save("segment_speed", out, out=args.out)


def report(r: dict) -> tuple[str, str]:
    c, a = r["contribution"], r["reassignment"]
    headline = (
        f"contribution pass {c['ratio']:.2f}x an RGB render; binary reassignment of {a['gaussians']:,} "
        f"Gaussians {a['binary_s']:.2f} s ({a['loop_over_binary']:.1f}x the per-label loop)"
    )
    rows = [
        (
            f"contribution pass / RGB forward, {c['gaussians']} Gaussians, {c['views']} views at "
            f"{c['size'][0]}x{c['size'][1]}",
            f"{c['contribution_s']:.3f} s / {c['rgb_forward_s']:.3f} s = {c['ratio']:.2f}x",
        )
    ]
    if "contribution_gsplat" in r:
        g = r["contribution_gsplat"]
        rows.append(
            (
                "the same on gsplat",
                f"{g['contribution_s'] * 1000:.1f} ms / {g['rgb_forward_s'] * 1000:.1f} ms = {g['ratio']:.2f}x",
            )
        )
    rows += [
        (f"reassignment, {a['gaussians']:,} Gaussians x {a['labels']} labels, multi", f"{a['multi_s']:.2f} s"),
        ("binary", f"{a['binary_s']:.2f} s"),
        (
            "binary, a per-label Python loop",
            f"{a['seed_style_loop_s']:.1f} s ({a['loop_over_binary']:.1f}x); "
            f"same selections: {a['binary_equals_loop']}",
        ),
    ]
    if "regularisations" in r:
        g = r["regularisations"]
        rows += [
            (f"smoothing of weak labels, {g['gaussians']:,} Gaussians, k = 16", f"{g['smooth_s']:.1f} s"),
            (
                "filling of interiors, 16 hollow spheres",
                f"{g['fill_s']:.1f} s; inner points given to their sphere {100 * g['inner_filled']:.1f}%, "
                f"points around them taken {100 * g['around_taken']:.2f}%",
            ),
        ]
    return headline, markdown_table(["what", "result"], [list(row) for row in rows])


if __name__ == "__main__":
    main()
