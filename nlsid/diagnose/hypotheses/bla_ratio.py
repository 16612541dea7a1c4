"""The ratio G_BLA / G_model of the measured and the model's BLA per level, the evidence of the
linear hypotheses (a dead time, a missing resonance)."""

from __future__ import annotations

import numpy as np

from nlsid.diagnose.hypotheses.base import Context


def bla_ratios(ctx: Context) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(angular frequency, G/G_model, variance of the ratio) per level. The variance of G is at
    least its numerical precision (noise-free data have none: :mod:`nlsid.analysis.precision`)
    relative to the larger of the two BLAs, so that the weights stay finite: also where the
    measured output did not respond at all (a constant y, e.g. a stage stuck in friction at a low
    level: G = 0 with no variance), the ratio 0 is then known to that precision."""
    from nlsid.analysis.precision import PRECISION

    out = []
    measured, model = ctx.bla_levels
    for a, b in zip(measured, model):
        w = 2 * np.pi * a.lines.frequency(a.lines.excited)
        R = a.robust.G / b.robust.G
        var = a.robust.var_total if np.all(np.isfinite(a.robust.var_total)) else a.robust.var_noise
        var = np.maximum(var, PRECISION**2 * np.maximum(np.abs(a.robust.G), np.abs(b.robust.G)) ** 2)
        out.append((w, R, var / np.abs(b.robust.G) ** 2))
    return out
