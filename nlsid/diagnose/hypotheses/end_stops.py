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

Around a transfer function model (``end_stops_feedback``): y = G (u - F(p, v)), a
``nonlinear_feedback`` with an ``end_stop`` force (gain 1: ks in input units per output unit, cs
per output unit per second) and G's coefficients refined with it
(:mod:`~nlsid.diagnose.hypotheses.velocity_feedback`). The stops read the position, so the model's
output must be one (a G from force to position of relative degree >= 2, or its ZOH equivalent's;
where a discrete G's equivalent has relative degree 1, its numerator's leading term dropped,
:func:`velocity_feedback.degree_two`: around G(z) itself the stops stopped 34 dB above the floor
on the tests' record fitted in z, with the term dropped 0.8 dB, as from a continuous fit);
the signature is the template's with the position and velocity along the model's trajectory and
the force's responses G (-F), and a linear spring c y regressed with the stop, the linear part
started at G / (1 + c G): a G fitted to the data holds part of the stops' stiffness (on the tests'
record, a second-order fit 11 % stiffer than the plant, the refinement from G itself stopped at 46
dB above the floor, ks 5.5 times the truth; from G / (1 + c G) at the floor). The damper's
fallback start takes G's mass, 1 / |w^2 G(jw)| at a quarter of the sampling rate (where a
mechanics is its mass). On a G with a static gain a constant force (the nuisance
``force_offset``, which the nuisances fit on every ``nonlinear_feedback`` with forces) shifts the
rest position, which the edges and the output offset express together: the data fix the edges in
the recorded output's coordinates, edge + output offset, which the estimate reports as
``upper_seen`` and ``lower_seen`` (:func:`_seen`). Held, the force offset stopped the refinement
on the tests' record at 43 dB above the floor; free, the fit reaches the floor along that
direction.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses import velocity_feedback
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.mass_forces import force_columns, mechanical, needs

KEYS = {"ks": "stiffness", "cs": "damping", "upper_stop": "upper", "lower_stop": "lower"}  # parameter -> key
EDGE_QUANTILES = (0.7, 0.8, 0.9, 0.95, 0.99)  # upper edges at these quantiles of p, lower at 1 - these
START_DAMPING = 0.02                            # the damper's start where the regression gives none, of 2 sqrt(ks m)


Columns = Callable[[list[Callable[[dict], np.ndarray]]], list[np.ndarray]]


def _columns(responses: Columns, edge: float, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Responses to the unit spring and unit damper of a stop at ``edge`` (sign +1 upper, -1 lower);
    ``responses``: the model's responses to forces of the internal signals."""
    def depth(s: dict) -> np.ndarray:
        return np.where(sign * (s["position"] - edge) > 0, s["position"] - edge, 0.0)

    def rate(s: dict) -> np.ndarray:
        return np.where(sign * (s["position"] - edge) > 0, s["velocity"], 0.0)
    spring, damper = responses([depth, rate])
    return spring, damper


def _estimate(ctx: Context) -> Estimate | str:
    """Start values (module docstring)."""
    for signal in ("position", "velocity"):
        if needs(ctx, signal):
            return needs(ctx, signal)
    model = ctx.runner.data["model"]
    mass = float(model.get("mass", model.get("motor_mass", 1.0)))
    return _start(ctx, ctx.internal, lambda forces: force_columns(ctx, forces), mass)


def _start(ctx: Context, internal: list[dict], responses: Columns, mass: float, stiffening: bool = False
           ) -> Estimate | str:
    """Start values from the position and velocity ``internal`` of the model's motion and the
    model's ``responses`` to forces of them (module docstring); ``mass`` for the damper's fallback.
    ``stiffening``: a linear spring c p and damper d v regressed with the stop (``c`` and ``d``
    among the values)."""
    position = np.concatenate([s["position"] for s in internal])
    if np.ptp(position) == 0:
        return "the model does not move on the estimation runs"
    target = ctx.target()
    uppers = {q: float(np.quantile(position, q)) for q in EDGE_QUANTILES}
    lowers = {q: float(np.quantile(position, 1 - q)) for q in EDGE_QUANTILES}
    up = {q: _columns(responses, edge, 1.0) for q, edge in uppers.items()}
    down = {q: _columns(responses, edge, -1.0) for q, edge in lowers.items()}
    options = [({"upper_stop": uppers[q]}, up[q]) for q in EDGE_QUANTILES]
    options += [({"lower_stop": lowers[q]}, down[q]) for q in EDGE_QUANTILES]
    options += [({"upper_stop": uppers[a], "lower_stop": lowers[b]}, (up[a][0] + down[b][0], up[a][1] + down[b][1]))
                for a in EDGE_QUANTILES for b in EDGE_QUANTILES]
    linear = responses([lambda s: s["position"], lambda s: s["velocity"]]) if stiffening else []
    best = None
    for edges, (spring, damper) in options:
        est = regress(target, [spring, damper, *linear], ["ks", "cs", "c", "d"][:2 + len(linear)])
        if est.values["ks"] > 0 and (best is None or est.explained_db > best[1].explained_db):
            best = (edges, est)
    if best is None:
        return "no edge of the grid gives a stop that pushes back (stiffness > 0) to first order"
    edges, est = best
    values = {"ks": est.values["ks"], "cs": est.values["cs"], **edges,
              **({"c": est.values["c"], "d": est.values["d"]} if stiffening else {})}
    std = {"ks": est.std["ks"], "cs": est.std["cs"], **{k: math.nan for k in edges}}
    sides = [k.split("_")[0] for k in edges]
    note = (f"{' and '.join(sides)} stop{'s' if len(edges) > 1 else ''} at quantiles of the model's position on a "
            f"grid of {len(EDGE_QUANTILES)} (the edges without standard errors)")
    if values["cs"] <= 0:
        values["cs"] = START_DAMPING * 2 * math.sqrt(values["ks"] * mass)
        std["cs"] = math.nan
        note += f"; the damper starts at {START_DAMPING:g} of critical (its regression is not positive)"
    index = len(ctx.runner.data["model"].get("nonlinearities", []))
    return Estimate(values, std, est.explained_db, note,
                    paths={k: f"model.nonlinearities[{index}].{KEYS[k]}" for k in values if k in KEYS})


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



def _mass(linear: dict, fs: float) -> float:
    """The mass of a force-to-position transfer function config: 1 / |w^2 G(jw)| at w = 2 pi fs / 4
    (a discrete G at z = e^(jw / fs))."""
    num, den = np.asarray(linear["num"], float), np.asarray(linear["den"], float)
    w = 2 * math.pi * fs / 4
    if linear.get("domain") == "discrete":
        zi = np.exp(-1j * w / fs)  # z^-1: the coefficients are of ascending powers of z^-1
        gain = np.polyval(num[::-1], zi) / np.polyval(den[::-1], zi)
    else:
        gain = np.polyval(num, 1j * w) / np.polyval(den, 1j * w)
    return float(1.0 / abs(w**2 * gain))


def _linear_start(lti: dict, c: float, d: float) -> dict | None:
    """``lti`` with its denominator that of G / (1 + (c + d s) G) (:func:`velocity_feedback.with_spring`),
    or None where that changes the sign of a coefficient (a change of structure, not a start)."""
    return velocity_feedback.with_spring(lti, c, d)


def _coefficients(lti: dict, names: tuple[str, ...]) -> dict[str, float]:
    """The linear part's refined coefficients (``num[i]``, ``den[i]``) of ``lti`` by name."""
    paths = velocity_feedback.paths(names, KEYS)({"model": lti})
    return {n: float(lti[n[:3]][int(n[4:-1])]) for n in paths if n not in KEYS}


def _estimate_feedback(ctx: Context) -> Estimate | str:
    """Start values around a transfer function (module docstring): the template's, the forces'
    responses those of the model at its input (gain 1), with a linear spring c regressed with the
    stop and the linear part started at G / (1 + c G)."""
    found = velocity_feedback.reading(ctx, accelerates=True)
    if isinstance(found, str):
        return found
    chosen, notes = found
    positions = velocity_feedback.positions(ctx, chosen)
    if isinstance(positions, str):
        return positions
    internal = [{"position": p, "velocity": v} for p, v in zip(positions, chosen.velocity)]

    def responses(forces: list[Callable[[dict], np.ndarray]]) -> list[np.ndarray]:
        return [ctx.response([-force(s) for s in internal], "process") for force in forces]
    est = _start(ctx, internal, responses, _mass(chosen.linear, ctx.runs[0].fs), stiffening=True)
    if isinstance(est, str):
        return est
    values = dict(est.values)
    c, d = values.pop("c"), values.pop("d")
    lti = {"type": "transfer_function", **chosen.linear, "output": "position"}
    stiffened = _linear_start(lti, c, d)
    if stiffened is not None:
        notes = [f"the linear part started at G / (1 + (c + d s) G), c = {c:.4g}, d = {d:.4g} (a linear spring and "
                 "damper regressed with the stop: a model fitted to the data holds part of the stops' force)", *notes]
        lti = stiffened
    names = tuple(k for k in KEYS if k in values)
    coefficients = _coefficients(lti, names)
    return dataclasses.replace(est, values={**values, **coefficients},
                               std={**est.std, **{n: math.nan for n in coefficients}},
                               note="; ".join([est.note, "the model's output read as the position", *notes]),
                               paths=velocity_feedback.paths(names, KEYS)({"model": lti}), lti=lti)


def _seen(fitted: dict, starts: dict, model: dict) -> dict:
    """The edges in the recorded output's coordinates, edge + output offset (``upper_seen``,
    ``lower_seen``): around a G with a static gain a constant force (the nuisance ``force_offset``)
    shifts the rest position, the edges and the output offset together, so these are what the
    data fix (on the tests' records the edges moved by -0.09 and +0.05, these by less than 0.002)."""
    offset = float(model.get("output_offset", 0.0))
    return {f"{side}_seen": fitted[f"{side}_stop"] + offset for side in ("upper", "lower") if f"{side}_stop" in fitted}


def _reading_seen(values: dict) -> str:
    where = [f"{side} at {values[f'{side}_seen']:.4g}" for side in ("upper", "lower") if f"{side}_seen" in values]
    return (f"end stop{'s' if len(where) > 1 else ''} {' and '.join(where)} of the recorded output (the edge plus the "
            f"output offset; stiffness {values['ks']:.4g}, damping {values['cs']:.4g} in input units)")


END_STOPS_FEEDBACK = Hypothesis(
    "end_stops_feedback", "End stops (contact beyond a position) fed back around the transfer function", "stiffness",
    "ks", "input units / output units",
    "as end_stops, for a transfer function model (its output read as the position): residual like the response to "
    "a one-sided spring and damper beyond an edge of the output",
    velocity_feedback.applies, _estimate_feedback, velocity_feedback.extender({"type": "end_stop"}, tuple(KEYS), KEYS),
    tuple(KEYS), velocity_feedback.paths(tuple(KEYS), KEYS), reading=_reading_seen, derive=_seen)

HYPOTHESES = (END_STOPS, END_STOPS_FEEDBACK)
