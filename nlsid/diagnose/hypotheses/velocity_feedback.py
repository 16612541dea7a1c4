"""Forces of the velocity (friction, nonlinear damping) fed back around a transfer function model,
as :mod:`~nlsid.diagnose.hypotheses.feedback` feeds a spring's force back: the model G from u to y
becomes a ``nonlinear_feedback`` plant, y = G (u - F(v)) with v the velocity of the moving part
(gain 1: F in units of u).

Which signal is the velocity depends on what G is, which a fitted transfer function does not say:

- G from force to *velocity* (y = v) when G has a zero at s = 0 (the velocity of a mass held by a
  spring: no static velocity under a constant force): the position is G / s, and the extension
  is the feedback around G / s with ``output: velocity``; G needs relative degree >= 1;
- G from force to *position* (y = p) otherwise: v = p' = s G u. The feedback needs G of relative
  degree >= 2 (a force accelerates: :func:`nlsid.models.mechanical.force_feedback` reads v as a
  state). A discrete G (as ``nlsid fit`` writes it) is extended as its continuous equivalent
  (:mod:`nlsid.diagnose.hypotheses.feedback`'s reasons: a force acts within the sample), its b0
  set to 0; where that has relative degree 1 (a fitted numerator's small leading term), around
  G(z) itself, the velocity the backward difference of the position (the force held over the
  sample, :func:`nlsid.models.mechanical.force_feedback`).

The velocity reading is not offered for a G with a static gain: read as a velocity, y fed back
through a force of it is a static feedback of the output, y = G (u - F(y)), the model of a spring
(:mod:`nlsid.diagnose.hypotheses.feedback`'s cubic feedback for F = c3 y^3): the same model under
two names, which the data cannot tell apart. The velocity of a free damped mass (a static gain
1 / c) is therefore read as a position; its user should give the model from force to position.

The linear part's coefficients are refined with the force (those that are not zero: the integrator
of G / s stays), as for the cubic feedback. Open loop only: in closed loop the velocity along the
model's trajectory needs the loop, which the probe of this module does not close.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, regress
from nlsid.diagnose.hypotheses.feedback import KEPT
from nlsid.diagnose.simulation import ModelRunner
from nlsid.models.continuous_equivalent import continuous_transfer_function

INPUT_KEYS = ("input_offset", "input_channels", "input_nonlinearity", "delay")  # kept in the velocity probe


def applies(runner: ModelRunner) -> str | None:
    model = runner.data["model"]
    if model["type"] != "transfer_function":
        return "needs a transfer_function model (the mechanical templates carry the force themselves)"
    if runner.closed:
        return "needs an open-loop model (the velocity probe does not close the loop)"
    return None


@dataclass(frozen=True)
class Reading:
    """One reading of the model's output: the linear part from force to position (G, or G / s, with
    its ``domain``), ``output`` (``position`` or ``velocity``) and the velocity of every run along
    the nominal trajectory."""

    output: str
    linear: dict
    velocity: list[np.ndarray]


ZERO_AT_DC = 1e-9  # num's constant term below this times its largest (frequency-scaled): a zero at s = 0


def _continuous(ctx: Context) -> tuple[dict | str, list[str]]:
    """The model's transfer function in continuous time (a discrete one's exact ZOH equivalent with
    b0 set to 0), or why there is none; and the notes on it."""
    model = ctx.runner.data["model"]
    if model.get("domain", "continuous") != "discrete":
        return {"num": [float(v) for v in model["num"]], "den": [float(v) for v in model["den"]]}, []
    equivalent = continuous_transfer_function([0.0, *model["num"][1:]], model["den"], ctx.runs[0].fs)
    if isinstance(equivalent, str):
        return f"the discrete model has no continuous equivalent: {equivalent}", []
    return {"num": equivalent["num"], "den": equivalent["den"]}, ["extended in continuous time (the model's exact "
                                                                  "ZOH equivalent)"]


def _relative_degree(linear: dict) -> int:
    return (np.trim_zeros(np.asarray(linear["den"], float), "f").size
            - np.trim_zeros(np.asarray(linear["num"], float), "f").size)


def _zero_at_dc(linear: dict, fs: float) -> bool:
    """Whether the continuous num has a zero at s = 0: its constant term negligible against the
    others, each scaled by the power of a frequency (the sampling rate) it multiplies."""
    num = np.trim_zeros(np.asarray(linear["num"], float), "f")
    scaled = np.abs(num) * (2 * np.pi * fs) ** np.arange(num.size - 1, -1, -1)
    return num.size > 1 and scaled[-1] <= ZERO_AT_DC * scaled.max()


def _probe(ctx: Context, linear: dict) -> list[np.ndarray]:
    """The output of the transfer function ``linear`` (with the model's input-side keys, no output
    offset or block) on every run."""
    model = ctx.runner.data["model"]
    data = {"model": {"type": "transfer_function", **linear,
                      **{k: copy.deepcopy(model[k]) for k in INPUT_KEYS if k in model}}}
    return ctx.runner.with_changes(data).simulate_each(ctx.runs)


def reading(ctx: Context) -> tuple[Reading, list[str]] | str:
    """The reading of the model's output (module docstring), with the notes on the linear part."""
    model = ctx.runner.data["model"]
    discrete = model.get("domain") == "discrete"
    notes = ([f"b0 = {model['num'][0]:.3g} set to 0 (a direct feedthrough would close an algebraic loop)"]
             if discrete and model["num"][0] else [])
    linear, more = _continuous(ctx)
    if isinstance(linear, str):
        return linear
    fs = ctx.runs[0].fs
    if _zero_at_dc(linear, fs):
        if _relative_degree(linear) < 1:
            return "the model is not strictly proper (a force of the velocity would act without delay)"
        integrated = {"num": linear["num"], "den": [*linear["den"], 0.0], "domain": "continuous"}
        return Reading("velocity", integrated, _probe(ctx, {**linear, "domain": "continuous"})), [*notes, *more]
    if _relative_degree(linear) >= 2:
        return (Reading("position", {**linear, "domain": "continuous"},
                        _probe(ctx, {"num": [*linear["num"], 0.0], "den": linear["den"], "domain": "continuous"})),
                [*notes, *more])
    if discrete:
        own = {"num": [0.0, *model["num"][1:]], "den": list(model["den"]), "domain": "discrete"}
        positions = _probe(ctx, own)
        velocity = [np.diff(p, prepend=p[0]) * fs for p in positions]
        return Reading("position", own, velocity), [*notes, "extended in discrete time, the velocity the backward "
                                                            "difference of the position (its continuous equivalent "
                                                            "has relative degree 1: a force would act without delay)"]
    return ("a force of the velocity needs the model from force to position of relative degree >= 2, or one "
            "from force to velocity (a zero at s = 0)")


def estimate(ctx: Context, laws: list[Callable[[np.ndarray], np.ndarray]], names: list[str],
             valid: Callable[[Estimate], str | None]) -> Estimate | str:
    """Start values of the forces sum_i theta_i law_i(v): the residual regressed on the model's
    responses to the input errors -law_i(v), v along the nominal trajectory of the model's reading
    (:func:`reading`); not fitted where the estimate is not ``valid`` (the reason: e.g. a negative
    friction level). The estimate's ``lti`` is the reading's linear part with its ``output``
    (consumed by :func:`extender`)."""
    found = reading(ctx)
    if isinstance(found, str):
        return found
    chosen, notes = found
    columns = [ctx.response([-law(v) for v in chosen.velocity], "process") for law in laws]
    est = regress(ctx.target(), columns, names)
    reason = valid(est)
    if reason is not None:
        return reason
    coefficients = {name: float(chosen.linear[name[:3]][int(name[4:-1])])
                    for name in paths(())({"model": chosen.linear})}
    note = f"the model's output read as the {chosen.output}"
    return Estimate({**est.values, **coefficients}, {**est.std, **{k: math.nan for k in coefficients}},
                    est.explained_db, "; ".join([note, *notes]),
                    lti={"type": "transfer_function", **chosen.linear, "output": chosen.output})


def extender(force: dict, names: tuple[str, ...]) -> Callable[[dict, dict], dict]:
    """The extension: the model (its LTI part as the estimate's ``lti`` left it, with the reading's
    ``output``) as the linear part of a ``nonlinear_feedback`` with the force ``force``."""
    def extend(data: dict, values: dict) -> dict:
        out = copy.deepcopy(data)
        model = out["model"]
        linear = {"type": "transfer_function", "domain": model.get("domain", "continuous"),
                  **{key: [float(values.get(f"{key}[{i}]", v)) for i, v in enumerate(model[key])]
                     for key in ("num", "den")}}
        out["model"] = {"type": "nonlinear_feedback", "linear": linear, "gain": 1.0,
                        "output": model.get("output", "position"),
                        "nonlinearities": [{**force, **{n: float(values[n]) for n in names}}],
                        **{k: model[k] for k in KEPT if k in model}}
        return out
    return extend


def paths(names: tuple[str, ...]) -> Callable[[dict], dict[str, str]]:
    """The force's ``names`` and the linear part's nonzero coefficients (but den[0])."""
    def of(data: dict) -> dict[str, str]:
        model = data["model"]
        out = {n: f"model.nonlinearities[0].{n}" for n in names}
        out.update({f"num[{i}]": f"model.linear.num[{i}]" for i, c in enumerate(model["num"]) if c != 0})
        out.update({f"den[{i}]": f"model.linear.den[{i}]" for i, c in enumerate(model["den"]) if i and c != 0})
        return out
    return of
