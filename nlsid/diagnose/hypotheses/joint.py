"""A nonlinear joint: a cubic spring in the coupling of a two-mass stage, k (p1 - p2) + k3 (p1 - p2)^3
between the motor and the load (``cubic_stiffness`` with ``at: joint``,
:mod:`nlsid.models.mechanical`), k3 > 0 a joint that stiffens with its deflection, < 0 one that
softens.

Signature: the joint's force is not an input error at the actuator, so the model's response to it
is not the response to a process disturbance: it is the model's sensitivity to k3 at k3 = 0,
taken here by a forward difference (the model simulated with a small cubic joint, less the model;
the probe's k3 scaled so that its effect is :data:`PROBE` of the output, in two passes), along the
model's own trajectory, in open or closed loop. A model fitted to the data holds the joint's mean
stiffening in its coupling stiffness, as the cubic feedback's linear part does
(:mod:`nlsid.diagnose.hypotheses.feedback`), so k3 is regressed together with a change of the
coupling stiffness (the sensitivity to it, the same forward difference) on the residual; the
coupling starts at the model's plus that change, where it stays positive.

What tells it from its neighbours: a cubic spring to the ground at the motor (``cubic_stiffness``)
acts on the motor's position, the joint on the deflection of the coupling, which the flexible
mode moves and the rigid-body motion does not: the joint's distortion is where the mode is. The
same family as the cubic spring (stiffness): the verdict names the one that is significantly
better (one parameter each).

Around a transfer function (``joint_feedback``): a continuous G (or a discrete one's exact ZOH
equivalent at its ``fs``) from force to the motor's position or velocity, with the numerator of
degree 2 that the motor's output has, is the two-mass stage of
:func:`two_mass_of` (gain 1: its masses and k3 in units of u); the joint is estimated and refined
on that stage, its mechanics with it. The joint reads the deflection p1 - p2, which the output is
not, so it needs the stage's two masses, not a force fed back around G as the friction families
(:mod:`~nlsid.diagnose.hypotheses.friction_feedback`) and the modal joint, whose modal form a free
stage lacks (its double pole at s = 0 is defective).
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress, spring
from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.errors import InputError

PROBE = 1e-4  # the probes' effect on the output, relative to its rms


def _applies(runner: ModelRunner) -> str | None:
    return None if runner.kind == "two_mass_stage" else "needs a two_mass_stage model (a joint between two masses)"


def _joint(data: dict, k3: float) -> dict:
    out = copy.deepcopy(data)
    out["model"].setdefault("nonlinearities", []).append({"type": "cubic_stiffness", "k3": float(k3), "at": "joint"})
    return out


def _coupling(data: dict, change: float) -> dict:
    out = copy.deepcopy(data)
    out["model"]["stiffness"] = float(out["model"]["stiffness"]) + change
    return out


def _sensitivity(ctx: Context, changed, step: float) -> tuple[np.ndarray, float]:
    """The stacked mean steady-state sensitivity of the judged signal (the output, or in closed
    loop the command: :class:`Context`) to a parameter, (y(step) - y) / step with
    ``changed(data, step)`` the model moved by it, the step rescaled once so that its effect is
    PROBE of that signal's rms; and that step."""
    base = [steady_mean(run, x) for run, x in zip(ctx.runs, ctx.simulated())]
    scale = float(np.sqrt(np.mean(np.concatenate(base) ** 2)))
    for _ in range(2):
        moved = ctx.simulated(ctx.runner.with_changes(changed(ctx.runner.data, step)))
        column = np.concatenate([(steady_mean(run, y) - b) / step for run, y, b in zip(ctx.runs, moved, base)])
        effect = float(np.sqrt(np.mean((column * step) ** 2)))
        if effect == 0:
            break
        step *= PROBE * scale / effect
    return column, step


def _estimate(ctx: Context) -> Estimate | str:
    """Start values (module docstring)."""
    model = ctx.runner.data["model"]
    stiffness = float(model["stiffness"])
    output = np.concatenate(ctx.runner.simulate_each(ctx.runs))
    scale = float(np.sqrt(np.mean(output**2))) or 1.0
    try:
        cubic, _ = _sensitivity(ctx, _joint, PROBE * stiffness / scale**2)
        linear, _ = _sensitivity(ctx, _coupling, PROBE * stiffness)
    except InputError as exc:  # a probe the simulation refuses (diverged)
        return f"the joint's sensitivity could not be simulated: {exc.what}"
    if not np.any(cubic):
        return "the joint does not move the output on the estimation runs"
    est = regress(ctx.target(), [cubic, linear], ["k3", "c"])
    c = est.values["c"]
    starts = {"stiffness": stiffness + c} if stiffness + c > 0 else None
    note = f"a {spring(est.values['k3'])} joint to first order (sensitivities by forward differences)"
    if starts:
        note += f"; the coupling stiffness started at {stiffness + c:.4g} (a linear change regressed with k3)"
    return Estimate({"k3": est.values["k3"]}, {"k3": est.std["k3"]}, est.explained_db, note, starts=starts)


def _paths(data: dict) -> dict[str, str]:
    return {"k3": f"model.nonlinearities[{len(data['model'].get('nonlinearities', []))}].k3"}


CUBIC_JOINT = Hypothesis(
    "cubic_joint", "Cubic spring in the joint", "stiffness", "k3", "N/m^3",
    "odd distortion around the flexible mode; the anti-resonance and resonance move with level; residual like "
    "the sensitivity to a cubic spring between the masses",
    _applies, _estimate, lambda data, values: _joint(data, values["k3"]), ("k3",), _paths,
    qualifier=lambda values: spring(values["k3"]))



MECHANICS = ("motor_mass", "load_mass", "stiffness", "damping", "motor_damping", "load_damping")
ROUNDING = 1e-9  # a damper (a scaled coefficient) below this share of the largest is rounding (two_mass_of, _rounded)


def _template(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The force-to-motor-position transfer function (num, den / s) of a two-mass stage with the
    parameters (m1, m2, k, c, c1, c2) of :data:`MECHANICS` (gain 1), den / s monic."""
    m1, m2, k, c, c1, c2 = params
    cubic = np.array([m1 * m2, m1 * (c2 + c) + m2 * (c1 + c), (m1 + m2) * k + c1 * c2 + c * (c1 + c2), k * (c1 + c2)])
    return np.array([m2, c2 + c, k]) / cubic[0], cubic / cubic[0]


def _mismatch(got: np.ndarray, given: np.ndarray, scale: float) -> float:
    """The largest difference of two polynomials' coefficients (descending powers of s), each
    coefficient of s^i times ``scale``^i, relative to the largest of ``given`` so scaled."""
    weights = scale ** np.arange(given.size - 1, -1, -1, dtype=float)
    return float(np.max(np.abs(got - given) * weights) / np.max(np.abs(given) * weights))


def two_mass_of(num, den) -> tuple[dict, float] | str:
    """The two_mass_stage (gain 1: forces in units of u) whose force-to-motor transfer function is
    the continuous ``num`` / ``den`` (descending powers of s), and the largest relative error of its
    coefficients against them; or why there is none.

    With the motor's position p1 the output (the motor's velocity: one power of s fewer in den),

        p1 / F = (m2 s^2 + (c2 + c) s + k) / (s (m1 m2 s^3 + (m1 (c2 + c) + m2 (c1 + c)) s^2
                 + ((m1 + m2) k + c1 c2 + c (c1 + c2)) s + k (c1 + c2))),

    c the coupling's damper, c1 and c2 the motor's and the load's to the ground. Divided by
    m1 m2, the numerator b2 s^2 + b1 s + b0 and the monic cubic s^3 + a2 s^2 + a1 s + a0 give
    m1 = 1 / b2, c1 + c2 = a0 / b0, c1 + c = m1 (a2 - b1 m1), c2 + c = b1 m1 m2, k = b0 m1 m2, and
    a1 a quadratic in the load mass m2 (the sums above put into a1's expression). Each positive
    root gives a stage (a damper below 0, where a fitted G is biased, at 0); the one that
    reproduces the coefficients best is kept. The six parameters are fixed by the motor's
    transfer function; the load's (numerator c s + k) does not fix the masses' split."""
    num = np.trim_zeros(np.asarray(num, float), "f")
    den = np.trim_zeros(np.asarray(den, float), "f")
    while num.size > 1 and den.size > 1 and num[-1] == 0 and den[-1] == 0:  # a common s (a velocity written as s G)
        num, den = num[:-1], den[:-1]
    if den.size == 5 and den[-1] == 0:
        output, cubic = "position", den[:-1]
    elif den.size == 4:
        output, cubic = "velocity", den
    else:
        return ("needs the transfer function of a two-mass stage from force to the motor's position (order 4, a "
                "pole at s = 0) or velocity (order 3)")
    if num.size != 3:
        return ("needs a numerator of degree 2 (the motor's output: the load's, of degree 1, does not fix the "
                "masses' split)")
    b2, b1, b0 = num / cubic[0]
    _, a2, a1, a0 = cubic / cubic[0]
    if b2 <= 0 or b0 <= 0:
        return "the numerator is not a two-mass stage's (its s^2 and constant coefficients must be positive)"
    m1 = 1.0 / b2
    ground, motor = a0 / b0, m1 * (a2 - b1 * m1)  # c1 + c2, c1 + c
    g = b1 * m1
    roots = np.roots([b0 * m1 - g**2 / 4, b0 * m1**2 + g * (motor + ground) / 2 - a1 * m1, -(ground - motor) ** 2 / 4])
    best = None
    for m2 in roots[(np.abs(roots.imag) <= 1e-9 * np.abs(roots)) & (roots.real > 0)].real:
        c = (g * m2 + motor - ground) / 2
        params = np.maximum([m1, m2, b0 * m1 * m2, c, motor - c, g * m2 - c], 0.0)
        params[3:][params[3:] <= ROUNDING * params[3:].max()] = 0.0  # a damper of the roots' rounding is none
        got_num, got_den = _template(params)
        scale = math.sqrt(abs(a1))  # about the flexible mode's frequency: each coefficient of s^i times scale^i
        error = max(_mismatch(got_num, num / cubic[0], scale), _mismatch(got_den, cubic / cubic[0], scale))
        if params[2] > 0 and (best is None or error < best[1]):
            best = (params, error)
    if best is None:
        return "no two-mass stage with positive masses and stiffness has this transfer function"
    params, error = best
    return {"type": "two_mass_stage", **{k: float(v) for k, v in zip(MECHANICS, params)}, "gain": 1.0,
            "output": output, "output_at": "motor"}, error


def _read(model: dict) -> tuple[dict, float] | str:
    """The two-mass stage a transfer function config is (:func:`two_mass_of`; a discrete one's
    exact ZOH equivalent at its ``fs``), or why there is none."""
    from nlsid.models.continuous_equivalent import continuous_transfer_function

    if model["type"] != "transfer_function":
        return "needs a transfer_function model (a two_mass_stage has the joint itself)"
    num, den = model["num"], model["den"]
    if model.get("domain", "continuous") == "discrete":
        if model.get("fs") is None:
            return "a discrete transfer function needs its rate (model.fs) to be read as a two-mass stage"
        equivalent = continuous_transfer_function(num, den, float(model["fs"]))
        if isinstance(equivalent, str):
            return f"the discrete model has no continuous equivalent: {equivalent}"
        num, den = (_rounded(equivalent[key], float(model["fs"])) for key in ("num", "den"))
    return two_mass_of(num, den)


def _rounded(poly: list[float], fs: float) -> np.ndarray:
    """A continuous equivalent's coefficients with those of the ZOH inverse's rounding set to 0:
    each coefficient of s^i times (2 pi fs)^i at most ROUNDING of the largest so scaled (a pole or
    zero at z = 1 comes out at s of order 1e-10 of the sampling rate, not at 0)."""
    out = np.asarray(poly, float).copy()
    scaled = np.abs(out) * (2 * math.pi * fs) ** np.arange(out.size - 1, -1, -1, dtype=float)
    out[scaled <= ROUNDING * scaled.max()] = 0.0
    return out


def _applies_feedback(runner: ModelRunner) -> str | None:
    found = _read(runner.data["model"])
    return found if isinstance(found, str) else None


def _stage(data: dict) -> tuple[dict, float]:
    """``data`` with its transfer function replaced by the two_mass_stage it is (:func:`_read`),
    its offsets, dead time, channels and blocks kept; and the coefficients' mismatch."""
    from nlsid.diagnose.hypotheses.feedback import KEPT

    model = data["model"]
    stage, error = _read(model)
    return {**data, "model": {**stage, **{k: copy.deepcopy(model[k]) for k in KEPT if k in model}}}, error


def _estimate_feedback(ctx: Context) -> Estimate | str:
    """Start values around a transfer function: the joint's (:func:`_estimate`) on the two-mass
    stage the transfer function is, the residual that stage's."""
    stage, error = _stage(ctx.runner.data)
    runner = ctx.runner.with_changes(stage)
    residuals = [steady_mean(run, ctx.measured(run)) - steady_mean(run, x)
                 for run, x in zip(ctx.runs, runner.simulate_each(ctx.runs, ctx.signal))]
    est = _estimate(Context(runner, ctx.runs, residuals, [], signal=ctx.signal))
    if isinstance(est, str):
        return est
    model = stage["model"]
    read = (f"the transfer function read as a two-mass stage from force (u) to the motor's {model['output']}: "
            f"masses {model['motor_mass']:.4g} and {model['load_mass']:.4g}, coupling {model['stiffness']:.4g} and "
            f"{model['damping']:.4g}, ground dampers {model['motor_damping']:.4g} and {model['load_damping']:.4g} "
            f"(coefficients reproduced within {error:.2g})")
    return dataclasses.replace(est, note=f"{read}; {est.note}")


JOINT_FEEDBACK = Hypothesis(
    "joint_feedback", "Cubic spring in the joint of the two-mass stage the transfer function is", "stiffness", "k3",
    "input units / deflection^3",
    "as cubic_joint, for a transfer function from force to the motor's position or velocity read as a two-mass "
    "stage: residual like the sensitivity to a cubic spring between the masses",
    _applies_feedback, _estimate_feedback, lambda data, values: _joint(_stage(data)[0], values["k3"]), ("k3",),
    _paths, qualifier=lambda values: spring(values["k3"]))

HYPOTHESES = (CUBIC_JOINT, JOINT_FEEDBACK)
