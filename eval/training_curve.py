"""The training-view PSNR of a run as a curve of the model alone.

Each logged step trains one view, and views differ by several dB (a view of black backdrop
scores 35 dB where one of foliage scores 22), so a plain average over a window of steps moves
with the views that fell in it: on DTU scan24 the last 100 steps averaged 5 dB under the 100
before them with no change in the model. The views follow from the step
(:func:`gsseg.train.trainer.view_at_step`), so each logged PSNR is fitted as the level of its
window plus the offset of its view, by least squares with the offsets summing to zero; the
levels are the curve. A summary takes windows of a tenth of the run: 30 logged steps at the
CPU schedule's 3000 (one in 10 is logged), which averages out what the offsets leave (windows
of 100 steps still move by 1 dB on DTU scan24, of 300 by 0.03 dB), and still shows a
collapse (the opacity reset that cost the statue 7 dB held it down for more than 600 steps).
"""

from __future__ import annotations

import numpy as np

from gsseg.train.trainer import view_at_step


def psnr_levels(history: list[dict], n_views: int, seed: int, window: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """The training PSNR of every ``window`` steps with each view's own offset taken out.

    Args:
        history: the run's log, dicts with ``step`` (1-based) and ``psnr``.
        n_views: training views of the run; seed: its training seed (together they name the
            view of every step).
        window: steps per level.

    Returns:
        (W,) the last step of each window that holds a logged step, and (W,) its level in dB.
    """
    steps = np.array([h["step"] for h in history])
    values = np.array([h["psnr"] for h in history], np.float64)
    views = np.array([view_at_step(int(s), n_views, seed) for s in steps])
    windows, which = np.unique((steps - 1) // window, return_inverse=True)
    rows = np.arange(len(steps))
    design = np.zeros((len(steps) + 1, len(windows) + n_views))
    design[rows, which] = 1.0
    design[rows, len(windows) + views] = 1.0
    design[-1, len(windows) :] = 1.0  # the offsets sum to zero
    solution = np.linalg.lstsq(design, np.append(values, 0.0), rcond=None)[0]
    ends = np.minimum((windows + 1) * window, steps.max())
    return ends, solution[: len(windows)]


def curve_summary(history: list[dict], n_views: int, seed: int, window: int | None = None) -> dict:
    """The peak of :func:`psnr_levels` (windows of ``window`` steps, default a tenth of the
    run), where it is, the last level, and ``kept``: the last minus the peak (a fit that
    collapsed and never won its loss back ends far under it)."""
    window = window or max(1, history[-1]["step"] // 10)
    ends, levels = psnr_levels(history, n_views, seed, window)
    return {
        "peak_psnr": float(levels.max()),
        "peak_step": int(ends[levels.argmax()]),
        "final_psnr": float(levels[-1]),
        "kept": float(levels[-1] - levels.max()),
    }
