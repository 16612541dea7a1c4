"""Hysteresis: a Bouc-Wen restoring force on the mass of a mass-spring-damper, or fed back around a
transfer function model from force to position (``hysteresis_feedback``: y = G (u - k z(y')), a
``nonlinear_feedback`` with G's coefficients refined, :mod:`~nlsid.diagnose.hypotheses.velocity_feedback`).

The force is F = k z with the Bouc-Wen state z' = v - beta |v| z - gamma v |z| (A = 1 and n = 1
held: for n = 1, A and k are one parameter, :mod:`nlsid.models.forces`), z in position units. It
is a spring of stiffness k for small strokes (z ~ p after each reversal) that yields on long ones,
the force tending to k zmax, zmax = 1 / (beta + gamma): a loop whose width the stroke sets, not
the rate. The elastic part alpha k0 p of the classical form is the model's own stiffness, refined
with the force (:func:`nlsid.diagnose.hypotheses.mechanics.linear_paths`).

Start: the refinement (the fit engine, with the model's mass, damping and stiffness) needs a
start in the basin of the truth, and the first-order signature (the residual regressed on the
model's response to -z along the model's motion) did not give one: where hysteresis is the cause
the model's own motion is far from the true one (the loop moves the resonance and damps it), and
on the tests' oscillator the regressed start took the wrong sign of gamma, from which the
refinement cannot cross zero. So the start is the grid point of least simulation error of the
estimation runs: zmax a share of the model's rms position (:data:`BOUND_SHARES`), gamma / beta
(:data:`GAMMA_SHARES`, nonzero: the refinement keeps each parameter's sign), and k a share of the
model's stiffness (:data:`SPLITS`) with the model's stiffness lowered by k / 2: a model fitted to
the data holds a spring between the small-stroke stiffness (its own plus k) and the large-stroke
one (its own), near the middle at strokes of about zmax, which the grid spans.

What tells it from its neighbours: a cubic spring stiffens (or softens) with the level but keeps
no memory (its force is a function of p, the loop has no area); a backlash at the input delays
the force by a play that is the same at every level; the Bouc-Wen force depends on the path
since the last reversal, and the loop's area grows with the stroke. The verdict names it over a
cubic spring (the same family, one parameter against three) only when it is significantly better
(:mod:`nlsid.diagnose.verdict`).
"""

from __future__ import annotations

import numpy as np

from nlsid.diagnose.hypotheses import velocity_feedback
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, with_lti
from nlsid.diagnose.hypotheses.mass_forces import add_force, force_paths, needs
from nlsid.diagnose.simulation import ModelRunner

BOUND_SHARES = (0.3, 0.6, 1.2, 2.4)  # zmax over the model's rms position, on the start grid
GAMMA_SHARES = (-0.5, 0.5)           # gamma / beta (the loop's unloading slope)
SPLITS = (0.25, 0.5)                 # k over the model's stiffness


def _applies(runner: ModelRunner) -> str | None:
    if runner.data["model"].get("type") != "mass_spring_damper":
        return "needs a mass_spring_damper model (its spring to the ground is what yields)"
    return None


def _shape(bound: float, share: float) -> tuple[float, float]:
    """(beta, gamma) with 1 / (beta + gamma) = bound and gamma = share beta."""
    beta = 1.0 / (bound * (1.0 + share))
    return beta, share * beta


def _estimate(ctx: Context) -> Estimate | str:
    """Start values (module docstring): the grid point of the least simulation error."""
    for signal in ("position", "velocity"):
        if needs(ctx, signal):
            return needs(ctx, signal)
    spread = float(np.sqrt(np.mean(np.concatenate([s["position"] - s["position"].mean() for s in ctx.internal]) ** 2)))
    if spread == 0:
        return "the model does not move on the estimation runs"
    stiffness = float(ctx.runner.data["model"].get("stiffness", 0.0))
    if stiffness <= 0:
        return "needs a spring in the model (stiffness > 0), part of which the hysteretic spring is"
    candidates = []
    for share in GAMMA_SHARES:
        for bound in (b * spread for b in BOUND_SHARES):
            beta, gamma = _shape(bound, share)
            for split in SPLITS:
                values = {"k": split * stiffness, "beta": beta, "gamma": gamma}
                starts = {"stiffness": (1 - 0.5 * split) * stiffness}
                cost = ctx.simulation_rss(HYSTERESIS.extend(_with_keys(ctx.runner.data, starts), values))
                candidates.append((cost, values, starts, bound, split))
    cost, values, starts, bound, split = min(candidates, key=lambda c: c[0])
    note = (f"the least simulation error of a grid of {len(BOUND_SHARES) * len(GAMMA_SHARES) * len(SPLITS)} starts: "
            f"zmax = {bound:.3g}, gamma / beta = {values['gamma'] / values['beta']:.2g}, k = {split:g} of the "
            f"model's stiffness and the model's stiffness lowered by k / 2 (no standard errors)")
    return Estimate(values, {"k": float("nan"), "beta": float("nan"), "gamma": float("nan")},
                    explained_db(float(np.sum(ctx.target() ** 2)), cost), note, starts=starts)


def _with_keys(data: dict, values: dict[str, float]) -> dict:
    return {**data, "model": {**data["model"], **values}}


def _reading(values: dict) -> str:
    bound = 1.0 / (values["beta"] + values["gamma"])
    return (f"a hysteretic spring of initial stiffness {values['k']:.4g} whose force yields towards "
            f"{values['k'] * bound:.4g} beyond a stroke of about {bound:.3g} (zmax = 1 / (beta + gamma))")


HYSTERESIS = Hypothesis(
    "hysteresis", "Hysteresis (Bouc-Wen restoring force)", "stiffness", "k", "N/m",
    "odd distortion; the resonance moves with level and the damping with it; residual force depends on the "
    "path since the last reversal (a loop whose area grows with the stroke)",
    _applies, _estimate, add_force({"type": "bouc_wen"}), ("k", "beta", "gamma"),
    force_paths(("k", "beta", "gamma")), reading=_reading)



def _estimate_feedback(ctx: Context) -> Estimate | str:
    """Start values of the feedback around a transfer function: the same grid, the model's output
    read as the position (:func:`velocity_feedback.reading`: a continuous G or its equivalent of
    relative degree >= 2), its static stiffness K = G(0)^-1 in input units per output unit playing
    the model's stiffness (k a share of it, the denominator lowered by k / 2 times the numerator)."""
    found = velocity_feedback.reading(ctx)
    if isinstance(found, str):
        return found
    reading, notes = found
    if reading.output != "position":
        return "needs the model's output read as a position (it has a zero at s = 0: a velocity)"
    num, den = np.asarray(reading.linear["num"], float), np.asarray(reading.linear["den"], float)
    discrete = reading.linear.get("domain") == "discrete"
    num0, den0 = (num.sum(), den.sum()) if discrete else (num[-1], den[-1])
    if num0 == 0 or den0 / num0 <= 0:
        return "needs a spring in the model (a positive static stiffness den(0) / num(0)), part of which yields"
    stiffness = float(den0 / num0)
    outputs = np.concatenate(ctx.runner.simulate_each(ctx.runs))
    spread = float(np.std(outputs))
    if spread == 0:
        return "the model does not move on the estimation runs"
    lti = {"type": "transfer_function", **reading.linear, "output": "position"}
    base = with_lti(ctx.runner.data, lti)
    aligned = (np.pad(num, (0, max(den.size - num.size, 0)))[:den.size] if discrete
               else np.pad(num, (den.size - num.size, 0)))
    candidates = []
    for share in GAMMA_SHARES:
        for bound in (b * spread for b in BOUND_SHARES):
            beta, gamma = _shape(bound, share)
            for split in SPLITS:
                k = split * stiffness
                lowered = den - 0.5 * k * aligned
                values = {"k": k, "beta": beta, "gamma": gamma,
                          **{f"num[{i}]": float(c) for i, c in enumerate(num)},
                          **{f"den[{i}]": float(c) for i, c in enumerate(lowered)}}
                cost = ctx.simulation_rss(HYSTERESIS_FEEDBACK.extend(base, values))
                candidates.append((cost, values, bound, split))
    cost, values, bound, split = min(candidates, key=lambda c: c[0])
    note = (f"the least simulation error of a grid of {len(candidates)} starts: zmax = {bound:.3g}, gamma / beta = "
            f"{values['gamma'] / values['beta']:.2g}, k = {split:g} of the model's static stiffness {stiffness:.4g} and "
            "the denominator lowered by k / 2 times the numerator (no standard errors)")
    return Estimate(values, {n: float("nan") for n in values}, explained_db(float(np.sum(ctx.target() ** 2)), cost),
                    "; ".join([note, *notes]), lti=lti)


HYSTERESIS_FEEDBACK = Hypothesis(
    "hysteresis_feedback", "Hysteresis (Bouc-Wen force) fed back around the transfer function", "stiffness", "k",
    "input units / output units",
    "as hysteresis, for a transfer function model: residual like the response to a Bouc-Wen force of the output",
    velocity_feedback.applies, _estimate_feedback, velocity_feedback.extender({"type": "bouc_wen"}, ("k", "beta", "gamma")),
    ("k", "beta", "gamma"), velocity_feedback.paths(("k", "beta", "gamma")), reading=_reading)

HYPOTHESES = (HYSTERESIS, HYSTERESIS_FEEDBACK)
