"""A dead time: the BLA phase error growing linearly with frequency, the gain right."""

from __future__ import annotations

import copy
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, always
from nlsid.diagnose.hypotheses.bla_ratio import bla_ratios


def _estimate_delay(ctx: Context) -> Estimate | str:
    """The dead time tau from the phase of G_BLA / G_model, -w tau, by weighted least squares
    (weights 2 |R|^2 / var(R), the inverse variance of the phase): a real number of samples,
    simulated exactly (:func:`nlsid.simulate.engine.timing`), then refined by the fit engine. Below
    one sample it is a converter skew, a nuisance estimated before any hypothesis
    (:mod:`nlsid.diagnose.nuisances`), not a cause. A discrete model has no values between samples:
    its dead time is rounded to whole samples, as is that of a model written as equations."""
    ratios = bla_ratios(ctx)
    if not ratios:
        return "needs multisine runs (the BLA phase)"
    num = den = 0.0
    for w, R, var in ratios:
        phase = np.unwrap(np.angle(R))
        weight = 2 * np.abs(R) ** 2 / var
        num += float(np.sum(weight * w * phase))
        den += float(np.sum(weight * w * w))
    if den == 0:  # every R is 0: the measured output shows no response at the excited lines, so no phase
        return "the measured BLA is zero at every excited line (the output does not respond): no phase to read"
    tau = -num / den
    fs = ctx.runs[0].fs
    samples = tau * fs
    if samples < 1 - 3 * fs / math.sqrt(den):
        return f"the BLA phase shows no dead time of a sample or more (slope {samples:.2f} samples)"
    current = float(ctx.runner.data["model"].get("delay", 0.0))
    if _whole_samples(ctx.runner.data):
        whole = max(int(round(samples)), 1)
        return Estimate({"delay": current + whole / fs}, {"delay": 1 / math.sqrt(den)}, float("nan"),
                        f"{whole} more samples from the BLA phase slope ({samples:.2f} before rounding: the "
                        "model's dead time is whole samples)")
    return Estimate({"delay": current + tau}, {"delay": 1 / math.sqrt(den)}, float("nan"),
                    f"{samples:.3f} more samples from the BLA phase slope")


def _whole_samples(data: dict) -> bool:
    """The model's dead time is whole samples: a discrete model, or one written as equations
    (its u is the command delayed by whole samples, :mod:`nlsid.models.equations`)."""
    return data["model"].get("domain") == "discrete" or data["model"].get("type") == "equations"


def _delay_paths(data: dict) -> dict[str, str] | None:
    """The fit engine refines a continuous model's dead time (a discrete one, or one written as
    equations, keeps whole samples)."""
    return {} if _whole_samples(data) else {"delay": "model.delay"}


def _extend_delay(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    out["model"]["delay"] = float(values["delay"])
    return out


HYPOTHESES = (
    Hypothesis("delay", "A dead time", "delay", "delay", "s",
               "BLA phase error growing linearly with frequency, gain right; no distortion",
               always, _estimate_delay, _extend_delay, ("delay",), _delay_paths),
)
