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
"""

from __future__ import annotations

import copy

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

HYPOTHESES = (CUBIC_JOINT,)
