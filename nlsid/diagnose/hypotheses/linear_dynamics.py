"""Wrong linear dynamics of a transfer-function model: its coefficients corrected by the simulation
error, alone (this hypothesis) or together with a block (every input or output block hypothesis on
a transfer function refines them with its own parameters, :func:`coefficient_paths`).

A transfer function fitted to a BLA is biased where the system is nonlinear: the BLA of a
saturating actuator has a lower gain than the small-signal one (Bussgang 1952: under Gaussian
excitation a static curve in series acts on the BLA as its mean slope), so a block added to that
model with the linear part frozen cannot reach the noise floor. Freed, the
coefficients could also absorb what is only a wrong linear model; this hypothesis is that linear
refit alone, so that the verdict can name a block only when it is significantly better than the
refit without it (:attr:`nlsid.diagnose.outcome.Outcome.generalizes`), as ``wrong_mechanics``
does for the mechanical templates.

The free coefficients are the nonzero ones of the numerator (each may change sign: a zero may lie
in either half-plane) and of the denominator but its first nonzero one (the normalisation: num and
den scaled together are the same model; a zero coefficient is a structural choice, an integrator or
a relative degree, and stays). The headline gives what moved in physical terms
(:func:`derive`): the largest relative change of a pole's natural frequency (|s|, for a discrete
pole |ln z| fs, matched in ascending order; an integrator's pole stays at zero and is left out)
and the change of the static gain G(0) (G(1) of a discrete model; unknown, NaN, with an integrator).
"""

from __future__ import annotations

import copy
import math
import re

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis
from nlsid.diagnose.simulation import ModelRunner

COEFFICIENT = re.compile(r"^(num|den)\[(\d+)\]$")


def coefficient_paths(data: dict) -> dict[str, str]:
    """The free coefficients of a ``transfer_function`` model (module docstring), name (``num[i]``,
    ``den[i]``) -> key path; empty for other models."""
    model = data["model"]
    if model.get("type") != "transfer_function":
        return {}
    num, den = (np.asarray(model[key], float) for key in ("num", "den"))
    lead = int(np.flatnonzero(den)[0]) if np.any(den) else 0
    return ({f"num[{i}]": f"model.num[{i}]" for i in np.flatnonzero(num)}
            | {f"den[{i}]": f"model.den[{i}]" for i in np.flatnonzero(den) if i != lead})


def is_coefficient(name: str) -> bool:
    return COEFFICIENT.match(name) is not None


def _with_values(model: dict, values: dict) -> tuple[np.ndarray, np.ndarray]:
    """The model's num and den with the coefficients of ``values`` written in."""
    polys = {key: np.asarray(model[key], float).copy() for key in ("num", "den")}
    for name, value in values.items():
        match = COEFFICIENT.match(name)
        if match:
            polys[match.group(1)][int(match.group(2))] = value
    return polys["num"], polys["den"]


def _natural_frequencies(den: np.ndarray, discrete: bool) -> np.ndarray:
    """|s| of each pole, |ln z| of a discrete one (fs cancels in a ratio), ascending."""
    poles = np.roots(np.trim_zeros(den, "f"))
    if discrete:
        poles = poles[poles != 0]
        with np.errstate(divide="ignore"):
            return np.sort(np.abs(np.log(poles)))
    return np.sort(np.abs(poles))


def _static_gain(num: np.ndarray, den: np.ndarray, discrete: bool) -> float:
    n, d = (np.sum(num), np.sum(den)) if discrete else (num[-1], den[-1])
    return float(n / d) if d != 0 else math.nan


def derive(values: dict, starts: dict, model: dict) -> dict[str, float]:
    """``pole_shift`` and ``gain_change`` (percent, module docstring) of the coefficients in
    ``values`` against those in ``starts`` (the model's), both written over ``model``'s num and den."""
    discrete = model.get("domain") == "discrete"
    before, after = _with_values(model, starts), _with_values(model, values)
    w0, w1 = (_natural_frequencies(den, discrete) for _, den in (before, after))
    moving = w0 > 0 if w0.size == w1.size else np.zeros(0, bool)  # an integrator's pole stays at 0
    if np.any(moving):
        ratios = 100 * (w1[moving] / w0[moving] - 1)
        shift = float(ratios[np.argmax(np.abs(ratios))])
    else:
        shift = math.nan
    g0, g1 = (_static_gain(num, den, discrete) for num, den in (before, after))
    gain = 100 * (g1 / g0 - 1) if math.isfinite(g0) and math.isfinite(g1) and g0 != 0 else math.nan
    return {"pole_shift": shift, "gain_change": float(gain)}


def _applies(runner: ModelRunner) -> str | None:
    if runner.kind != "transfer_function":
        return "needs a transfer_function model (a mechanical template has wrong_mechanics)"
    if not coefficient_paths(runner.data):
        return "the transfer function has no coefficient to correct"
    return None


def _estimate(ctx: Context) -> Estimate:
    """Start values: the model's own coefficients (the fit engine corrects them)."""
    model = ctx.runner.data["model"]
    values = {name: float(model[match.group(1)][int(match.group(2))])
              for name in coefficient_paths(ctx.runner.data) for match in [COEFFICIENT.match(name)]}
    values |= {"pole_shift": 0.0, "gain_change": 0.0}
    return Estimate(values, {k: float("nan") for k in values}, float("nan"), "start at the model's own coefficients")


def _extend(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    num, den = _with_values(out["model"], values)
    out["model"]["num"], out["model"]["den"] = [float(c) for c in num], [float(c) for c in den]
    return out


def _reading(values: dict) -> str:
    def percent(value: float) -> str:
        return f"{value:+.3g} %" if math.isfinite(value) else "unknown"

    return (f"the largest change of a pole's natural frequency {percent(values['pole_shift'])}, "
            f"of the static gain {percent(values['gain_change'])}")


HYPOTHESES = (
    Hypothesis("wrong_dynamics", "Wrong linear dynamics (the transfer function's coefficients)", "linear",
               "pole_shift", "% (largest change of a pole's natural frequency)",
               "BLA differs from the model in shape or gain; no distortion",
               _applies, _estimate, _extend, ("num", "den", "gain"),  # counted as three, as wrong_mechanics
               coefficient_paths, _reading, derive=derive),
)
