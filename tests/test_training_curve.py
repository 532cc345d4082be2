"""The training curve with each view's own level taken out (eval/training_curve.py)."""

import numpy as np

from eval.training_curve import curve_summary, psnr_levels
from gsseg.train.trainer import view_at_step


def _history(level, n_views: int, seed: int, offsets: np.ndarray, every: int = 10, last: int = 3000) -> list[dict]:
    """A log of every ``every``-th step: the model's ``level(step)`` plus the offset of the view
    that step trains."""
    return [
        {"step": s, "psnr": level(s) + offsets[view_at_step(s, n_views, seed)]} for s in range(every, last + 1, every)
    ]


def test_levels_are_the_model_without_the_mix_of_views():
    """Known answer: views 8 dB apart and a model that rises then holds; the levels are the
    model's, window by window, where plain window means move with the views drawn."""
    rng = np.random.default_rng(0)
    offsets = rng.uniform(-4, 4, 7)
    offsets -= offsets.mean()

    def level(step: int) -> float:
        return 20 + 8 * min(1, (step - 1) // 100 / 20)  # constant within each window of 100 steps

    history = _history(level, 7, 3, offsets)
    ends, levels = psnr_levels(history, 7, 3, window=100)
    np.testing.assert_array_equal(ends, np.arange(100, 3001, 100))
    np.testing.assert_allclose(levels, [level(e) for e in ends], atol=1e-9)
    plain = np.array([h["psnr"] for h in history]).reshape(30, 10).mean(1)
    assert np.abs(plain - levels).max() > 0.5


def test_a_collapse_that_is_not_won_back_shows_and_one_that_is_does_not():
    """A drop of 7 dB after step 1000: won back at step 1700, the run ends at its peak; never
    won back, it ends 7 dB under where it would have been, far under its peak."""
    offsets = np.linspace(-3, 3, 5)

    def rising(step: int) -> float:
        return 20 + 6 * min(step, 2000) / 2000

    def dropped(end: int):
        return lambda step: rising(step) - (7 if 1000 < step <= end else 0)

    won_back = curve_summary(_history(dropped(1700), 5, 0, offsets), 5, 0)
    assert abs(won_back["kept"]) < 0.05 and abs(won_back["final_psnr"] - 26) < 0.05
    lost = curve_summary(_history(dropped(3000), 5, 0, offsets), 5, 0)
    assert abs(lost["final_psnr"] - 19) < 0.05 and lost["kept"] < -3 and lost["peak_step"] == 900
