"""A dead time: the BLA phase error growing linearly with frequency, the gain right."""

from __future__ import annotations

import copy
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, always
from nlsid.diagnose.hypotheses.bla_ratio import bla_ratios


def _estimate_delay(ctx: Context) -> Estimate | str:
    ratios = bla_ratios(ctx)
    if not ratios:
        return "needs multisine runs (the BLA phase)"
    num = den = 0.0
    for w, R, var in ratios:
        phase = np.unwrap(np.angle(R))
        weight = 2 * np.abs(R) ** 2 / var
        num += float(np.sum(weight * w * phase))
        den += float(np.sum(weight * w * w))
    tau = -num / den
    fs = ctx.runs[0].fs
    samples = int(round(tau * fs))
    if samples < 1:
        return f"the BLA phase shows no dead time (slope {tau * fs:.2f} samples)"
    current = float(ctx.runner.data["model"].get("delay", 0.0))
    return Estimate({"delay": current + samples / fs}, {"delay": 1 / math.sqrt(den)}, float("nan"),
                    f"{samples} more samples from the BLA phase slope ({tau * fs:.2f} samples before rounding)")

def _extend_delay(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    out["model"]["delay"] = float(values["delay"])
    return out


HYPOTHESES = (
    Hypothesis("delay", "A dead time", "delay", "delay", "s",
               "BLA phase error growing linearly with frequency, gain right; no distortion",
               always, _estimate_delay, _extend_delay, ("delay",)),
)
