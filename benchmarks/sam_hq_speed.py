"""Benchmark: the SAM-HQ ONNX runtime on CPU with the stand-in model (`hqmask.sam_hq.standin`) (the real
SAM-HQ networks are far heavier; this measures the runtime around them). Prints and writes JSON.

Encoder latency, decoder prompts/s batched (64 per call) and one per call, and the automatic
generator (32x32 grid) with the share of its time spent outside ONNX Runtime, in the
pre- and post-processing (target: under 15%).

    python -m benchmarks.sam_hq_speed [--res 768] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import record
from dataset_tools.scene import load_scene
from dataset_tools.synth import SynthConfig, generate_scene
from eval.report import markdown_table
from hqmask.sam_hq import AutomaticMaskGenerator, GeneratorConfig, SamHQ
from hqmask.sam_hq.standin import export_standin_model


class RunTimer:
    """Wraps an ONNX Runtime session's ``run`` and adds up the seconds spent in it."""

    def __init__(self, session):
        self.session, self.seconds = session, 0.0

    def run(self, *args, **kwargs):
        t = time.perf_counter()
        try:
            return self.session.run(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t

    def __getattr__(self, name):
        return getattr(self.session, name)


def mean_seconds(fn, repeats: int) -> float:
    fn()  # warm-up
    t = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t) / repeats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=768, help="side of the square synthetic test image")
    ap.add_argument("--out", default=None, help="JSON file (default: benchmarks/results/sam_hq_speed.json).")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scene = generate_scene(
            SynthConfig(views=2, res=args.res, objects=6, seed=0), Path(tmp) / "scene", progress=False
        )
        image = load_scene(scene.root).views[0].load_image()
        model = SamHQ(export_standin_model(Path(tmp) / "model"), device="cpu")
        model.encoder, model.decoder = RunTimer(model.encoder), RunTimer(model.decoder)

        encode = mean_seconds(lambda: model.encode(image), 5)
        embedding = model.encode(image)
        rng = np.random.default_rng(0)
        points = rng.uniform(0, args.res, (64, 1, 2)).astype(np.float32)
        coords = np.concatenate([points, np.zeros_like(points)], axis=1)
        labels = np.tile(np.array([[1, -1]], np.float32), (64, 1))
        batched = mean_seconds(lambda: model.decode(embedding, coords, labels), 5) / 64
        single = (
            mean_seconds(lambda: [model.decode(embedding, coords[i : i + 1], labels[i : i + 1]) for i in range(16)], 2)
            / 16
        )

        generator = AutomaticMaskGenerator(model, GeneratorConfig())
        generator.generate(image)  # warm-up
        model.encoder.seconds = model.decoder.seconds = 0.0
        t = time.perf_counter()
        masks = generator.generate(image)
        total = time.perf_counter() - t
        in_runtime = model.encoder.seconds + model.decoder.seconds
    result = {
        "model": "stand-in with SAM-HQ's inputs/outputs (hqmask.sam_hq.standin), CPU execution provider",
        "image": f"{args.res}x{args.res} synthetic view",
        "cpu_count": os.cpu_count(),
        "encoder_ms": round(1000 * encode, 1),
        "decoder_prompts_per_s_batched": round(1 / batched, 1),
        "decoder_prompts_per_s_single": round(1 / single, 1),
        "batched_speedup": round(single / batched, 2),
        "generator_points": 32 * 32,
        "generator_s": round(total, 3),
        "generator_masks": len(masks),
        "generator_share_outside_runtime": round(1 - in_runtime / total, 3),
    }
    print(json.dumps(result, indent=2))
    record.save("sam_hq_speed", result, out=args.out)


def report(r: dict) -> tuple[str, str]:
    headline = (
        f"generator {r['generator_s']:.1f} s for {r['generator_points']} points, "
        f"{100 * r['generator_share_outside_runtime']:.1f}% outside ONNX Runtime"
    )
    rows = [
        ("encoder", f"{r['encoder_ms']} ms"),
        ("decoder, 64 prompts a call", f"{r['decoder_prompts_per_s_batched']} prompts/s"),
        ("decoder, one prompt a call", f"{r['decoder_prompts_per_s_single']} prompts/s"),
        (f"automatic generator, {r['generator_points']} points", f"{r['generator_s']} s, {r['generator_masks']} masks"),
        ("share of the generator's time outside ONNX Runtime", f"{100 * r['generator_share_outside_runtime']:.1f}%"),
    ]
    table = markdown_table(["what", "result"], [list(row) for row in rows])
    return headline, f"{r['model']}; {r['image']}; {r['cpu_count']} CPUs.\n\n{table}"


if __name__ == "__main__":
    main()
