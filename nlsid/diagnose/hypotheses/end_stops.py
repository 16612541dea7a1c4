"""Contact and end stops: a stiff one-sided spring with a damper beyond a position of the driven
mass, above (``upper``), below (``lower``) or both (``nonlinearities: end_stop``,
:mod:`nlsid.models.forces`): F = max(0, ks (p - upper) + cs v) beyond the upper stop, its mirror
image below the lower one, nothing between. Piecewise affine: the model is exact between the stops
and wrong only where the motion reaches one.

Signature: to first order the residual is the model's response to the input error -F / gain
along the model's own motion. For given edges the force is linear in ks and cs, so they are
regressed on the responses to the depth beyond the edge and to the velocity while there. The
edges are chosen on a grid of quantiles of the model's position (:data:`EDGE_QUANTILES`: the
upper edge where the motion spends the last 1-30 % of its time above it, the lower likewise),
with three structures for each pair: the upper stop alone, the lower alone, both with one
stiffness and one damping; the grid point and structure of the largest explained drop with
ks > 0 are kept. The damper starts at its regressed value where that is positive, else at
START_DAMPING of the critical damping of the stop's spring on the model's mass (a start of zero
has no sign for the refinement to keep). The parameters are named ks, cs, upper_stop and
lower_stop (:data:`KEYS`: the force's keys ``stiffness``, ``damping``, ``upper``, ``lower``), apart
from the model's own stiffness and damping, refined with them.

What tells it from its neighbours: a cubic spring stiffens at every level, smoothly, the stops
only beyond a position, so the largest level alone shows them; an input saturation cuts the force
at a value of the input, a sensor that tops out the output at a value of the output, both
wherever the dynamics are, the stops a position of the mass (its output flattens at the stop only
as far as the spring lets it in, with the model's resonance on it). A stop is in the stiffness
family: the verdict names it over a cubic spring (one parameter against three or four) only when
it is significantly better (:mod:`nlsid.diagnose.verdict`).
"""

from __future__ import annotations

import copy
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.mass_forces import force_columns, mechanical, needs

KEYS = {"ks": "stiffness", "cs": "damping", "upper_stop": "upper", "lower_stop": "lower"}  # parameter -> key
EDGE_QUANTILES = (0.7, 0.8, 0.9, 0.95, 0.99)  # upper edges at these quantiles of p, lower at 1 - these
START_DAMPING = 0.02                            # the damper's start where the regression gives none, of 2 sqrt(ks m)


def _columns(ctx: Context, edge: float, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Responses to the unit spring and unit damper of a stop at ``edge`` (sign +1 upper, -1 lower)."""
    def depth(s: dict) -> np.ndarray:
        return np.where(sign * (s["position"] - edge) > 0, s["position"] - edge, 0.0)

    def rate(s: dict) -> np.ndarray:
        return np.where(sign * (s["position"] - edge) > 0, s["velocity"], 0.0)
    spring, damper = force_columns(ctx, [depth, rate])
    return spring, damper


def _estimate(ctx: Context) -> Estimate | str:
    """Start values (module docstring)."""
    for signal in ("position", "velocity"):
        if needs(ctx, signal):
            return needs(ctx, signal)
    position = np.concatenate([s["position"] for s in ctx.internal])
    if np.ptp(position) == 0:
        return "the model does not move on the estimation runs"
    target = ctx.target()
    uppers = {q: float(np.quantile(position, q)) for q in EDGE_QUANTILES}
    lowers = {q: float(np.quantile(position, 1 - q)) for q in EDGE_QUANTILES}
    up = {q: _columns(ctx, edge, 1.0) for q, edge in uppers.items()}
    down = {q: _columns(ctx, edge, -1.0) for q, edge in lowers.items()}
    options = [({"upper_stop": uppers[q]}, up[q]) for q in EDGE_QUANTILES]
    options += [({"lower_stop": lowers[q]}, down[q]) for q in EDGE_QUANTILES]
    options += [({"upper_stop": uppers[a], "lower_stop": lowers[b]}, (up[a][0] + down[b][0], up[a][1] + down[b][1]))
                for a in EDGE_QUANTILES for b in EDGE_QUANTILES]
    best = None
    for edges, (spring, damper) in options:
        est = regress(target, [spring, damper], ["ks", "cs"])
        if est.values["ks"] > 0 and (best is None or est.explained_db > best[1].explained_db):
            best = (edges, est)
    if best is None:
        return "no edge of the grid gives a stop that pushes back (stiffness > 0) to first order"
    edges, est = best
    values = {"ks": est.values["ks"], "cs": est.values["cs"], **edges}
    std = {"ks": est.std["ks"], "cs": est.std["cs"], **{k: math.nan for k in edges}}
    sides = [k.split("_")[0] for k in edges]
    note = (f"{' and '.join(sides)} stop{'s' if len(edges) > 1 else ''} at quantiles of the model's position on a "
            f"grid of {len(EDGE_QUANTILES)} (the edges without standard errors)")
    if values["cs"] <= 0:
        model = ctx.runner.data["model"]
        mass = float(model.get("mass", model.get("motor_mass", 1.0)))
        values["cs"] = START_DAMPING * 2 * math.sqrt(values["ks"] * mass)
        std["cs"] = math.nan
        note += f"; the damper starts at {START_DAMPING:g} of critical (its regression is not positive)"
    index = len(ctx.runner.data["model"].get("nonlinearities", []))
    return Estimate(values, std, est.explained_db, note,
                    paths={k: f"model.nonlinearities[{index}].{KEYS[k]}" for k in values})


def _extend(data: dict, values: dict) -> dict:
    """The model with an ``end_stop`` force of the values (parameter names -> its keys, :data:`KEYS`)."""
    out = copy.deepcopy(data)
    out["model"].setdefault("nonlinearities", []).append(
        {"type": "end_stop", **{KEYS[k]: float(v) for k, v in values.items() if k in KEYS}})
    return out


def _reading(values: dict) -> str:
    where = [f"{key.split('_')[0]} at {values[key]:.4g}" for key in ("upper_stop", "lower_stop") if key in values]
    return (f"end stop{'s' if len(where) > 1 else ''} {' and '.join(where)} (stiffness {values['ks']:.4g}, "
            f"damping {values['cs']:.4g})")


def _paths(data: dict) -> dict[str, str]:
    index = len(data["model"].get("nonlinearities", []))
    return {n: f"model.nonlinearities[{index}].{key}" for n, key in KEYS.items()}


END_STOPS = Hypothesis(
    "end_stops", "End stops (contact beyond a position)", "stiffness", "ks", "N/m",
    "odd or even distortion at the largest levels only; the resonance moves where the motion reaches a position; "
    "residual force where the position is beyond an edge",
    mechanical, _estimate, _extend, tuple(KEYS), _paths,
    reading=_reading)

HYPOTHESES = (END_STOPS,)
