"""Benchmark: one forward + backward render of 30k Gaussians at 256x256 with 3 colour and
16 object-feature channels, ``cpu`` against the ``torch`` reference (and ``gsplat`` where a
GPU is present), plus the cost of the object channels: fused with colour; kept off the
geometry as training blends them by default (``cpu``: one blend whose backward pass lets
only colour and depth reach the geometry); and, side by side, the same in a second pass over
the detached geometry (what the other backends do). Prints and writes JSON.

    python -m benchmarks.render_speed [--out render_speed.json] [--gaussians 30000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import time

import numba
import torch

from benchmarks import record
from dataset_tools.cameras import PinholeCamera
from eval.report import markdown_table
from gsseg.model.gaussians import Gaussians
from gsseg.render import BACKENDS, get_backend, render
from gsseg.render.backends import Backend, CpuBackend


class TwoPass(CpuBackend):
    """The ``cpu`` backend blending detached features in a second pass (the default of
    :meth:`gsseg.render.backends.Backend.rasterize_beside`)."""

    name = "cpu-two-pass"
    rasterize_beside = Backend.rasterize_beside


def scene(n: int, seed: int = 0) -> tuple[Gaussians, PinholeCamera, torch.Tensor]:
    """``n`` Gaussians filling a 2.4 x 1.8 x 2 box 3.5 units in front of a 256x256 camera
    (60 degree field of view), standard deviations 1-4 % of the box, opacities ~ sigmoid(N(0, 1))."""
    gen = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=gen) - 0.5) * torch.tensor([2.4, 1.8, 2.0])
    g = Gaussians(
        means=means,
        log_scales=torch.log(0.01 + 0.03 * torch.rand(n, 3, generator=gen)),
        quats=torch.randn(n, 4, generator=gen),
        opacity_logits=torch.randn(n, generator=gen),
        sh_dc=torch.randn(n, 3, generator=gen),
        sh_rest=0.1 * torch.randn(n, 15, 3, generator=gen),
        obj_feat=torch.randn(n, 16, generator=gen),
    )
    f = 128 / math.tan(math.radians(30))
    pose = torch.tensor([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3.5]])
    return g, PinholeCamera(256, 256, f, f, 128, 128), pose


def time_step(
    g: Gaussians,
    cam: PinholeCamera,
    pose: torch.Tensor,
    backend: str | Backend,
    features: bool,
    repeats: int,
    feature_geometry_grad: bool = True,
) -> float:
    """Median seconds of render + backward of a loss on every output."""
    device = get_backend(backend).device
    times = []
    for _ in range(repeats + 1):  # the first call compiles / warms up
        params = Gaussians(**{k: v.to(device).requires_grad_(True) for k, v in g.tensors().items()})
        if device == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        out = render(
            params,
            cam,
            pose.to(device),
            with_features=features,
            feature_geometry_grad=feature_geometry_grad,
            backend=backend,
        )
        (out.rgb.sum() + out.features.sum() + out.alpha.sum() + out.depth.sum()).backward()
        if device == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - start)
    return sorted(times[1:])[len(times[1:]) // 2]


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/render_speed.json).")
    parser.add_argument("--gaussians", type=int, default=30_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    g, cam, pose = scene(args.gaussians)
    result = {
        "gaussians": args.gaussians,
        "size": [cam.width, cam.height],
        "threads": numba.get_num_threads(),
        "channels": "3 colour + 16 object features (+ depth)",
    }
    result["cpu_s"] = time_step(g, cam, pose, "cpu", True, args.repeats)
    result["cpu_rgb_only_s"] = time_step(g, cam, pose, "cpu", False, args.repeats)
    result["cpu_detached_s"] = time_step(g, cam, pose, "cpu", True, args.repeats, feature_geometry_grad=False)
    result["cpu_two_pass_s"] = time_step(g, cam, pose, TwoPass(), True, args.repeats, feature_geometry_grad=False)
    result["cpu_peak_rss_mb"] = peak_rss_mb()
    result["torch_s"] = time_step(g, cam, pose, "torch", True, max(1, args.repeats // 2))
    result["torch_peak_rss_mb"] = peak_rss_mb()
    result["torch_over_cpu"] = result["torch_s"] / result["cpu_s"]
    result["features_over_rgb_only"] = result["cpu_s"] / result["cpu_rgb_only_s"]
    if BACKENDS["gsplat"].available():
        result["gsplat_s"] = time_step(g, cam, pose, "gsplat", True, args.repeats)
        result["gpu_peak_mb"] = torch.cuda.max_memory_allocated() / 2**20
    print(json.dumps(result, indent=2))
    record.save("render_speed", result, out=args.out)


def report(r: dict) -> tuple[str, str]:
    headline = f"cpu {r['cpu_s']:.3f} s, torch {r['torch_s']:.2f} s ({r['torch_over_cpu']:.1f}x)"
    rows = [
        ("cpu, colour + object features", f"{r['cpu_s']:.3f} s"),
        ("cpu, colour only", f"{r['cpu_rgb_only_s']:.3f} s (features cost {r['features_over_rgb_only']:.2f}x)"),
        (
            "cpu, features kept off the geometry in the same blend (training's default)",
            f"{r['cpu_detached_s']:.3f} s ({r['cpu_detached_s'] / r['cpu_s']:.2f}x fused)",
        ),
        (
            "cpu, features in a second pass over detached geometry",
            f"{r['cpu_two_pass_s']:.3f} s ({r['cpu_two_pass_s'] / r['cpu_detached_s']:.2f}x the same blend)",
        ),
        ("torch reference", f"{r['torch_s']:.2f} s ({r['torch_over_cpu']:.1f}x cpu)"),
        ("peak RSS", f"cpu {r['cpu_peak_rss_mb'] / 1024:.2f} GB, torch {r['torch_peak_rss_mb'] / 1024:.2f} GB"),
    ]
    if "gsplat_s" in r:
        rows.append(("gsplat", f"{r['gsplat_s']:.4f} s, {r['gpu_peak_mb']:.0f} MB GPU"))
    table = markdown_table(["forward + backward", "seconds"], [list(row) for row in rows])
    return headline, (
        f"{r['gaussians']} Gaussians at {r['size'][0]}x{r['size'][1]}, {r['channels']}, "
        f"{r['threads']} threads, median of repeats.\n\n{table}"
    )


if __name__ == "__main__":
    main()
