"""An overflowing upper tank: the two cascaded tanks of :mod:`~nlsid.diagnose.hypotheses.tank_outflow`
whose upper tank spills over its rim at the level x1max.

With f1 = -k1 sqrt(x1) + k4 u the upper tank's net inflow (k2 = k1: equal cross-sections, the
scale of that module), a tank at its rim cannot rise: what the pump brings beyond the outflow
spills, a share ``frac`` of it into the lower tank (the rest is lost):

    dx1/dt = f1                    where x1 < x1max,  min(f1, 0) where x1 >= x1max,
    dx2/dt = k1 sqrt(x1) - k3 sqrt(x2) + frac max(f1, 0) [x1 >= x1max],     y = x2 + c,

the ``where`` of the model language (``docs/configs.md``: the switch located within the step).
The rim is on the scale of k2 = k1 (a rim at h in a tank of other cross-sections reads as
(k2 / k1) h), and it is what the output sees of the upper level: an overflow at a fixed level breaks
the scale's freedom, so with it the four rates could be told apart; the extension keeps k2 = k1,
one scale for both members of the family.

Signature: as the tanks', with the lower level's response to a rising input capped at the largest
levels (an upper tank that no longer rises). Start: for each pole assignment the tanks of the
linear model's map (:mod:`~nlsid.diagnose.hypotheses.tank_outflow`), the upper level x1 they
simulate, and the rim at the quantile of it of RIM_QUANTILES, with frac from FRACTIONS, that
simulates closest (each with the output offset moved by the mean error); then all of them
pre-fitted together in the coordinates of ``tank_outflow.prefit`` (ln x1max and ln frac added),
and the assignment of lower simulation error kept. Not from the two tanks' fit without the
overflow: where the overflow is strong that fit ends far from the rates (k3 3.6 times the truth
on the test's tanks), the levels it simulates with them. The fit engine then refines the rates,
the rim, frac and the offset together.
"""

from __future__ import annotations

import copy
import itertools
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db
from nlsid.diagnose.hypotheses.tank_outflow import (PARAMETER, SIGNATURE, applies_to, derive, extension, named,
                                                    operating_point, plain, pole_note, prefit, simulated, start_values)
from nlsid.diagnose.hypotheses.tank_outflow import extend as extend_plain
from nlsid.diagnose.simulation import steady_mean
from nlsid.errors import InputError

RIM_QUANTILES = (0.6, 0.75, 0.85, 0.95)  # of the simulated upper level over the estimation runs
FRACTIONS = (0.25, 0.75)                 # of the spill that reaches the lower tank

NET = "-k1*sqrt(x1) + k4*u"


def equations(values: dict) -> dict:
    """The equations model's own keys of the overflowing tanks of ``values`` (module docstring)."""
    x1max = float(values["x1max"])
    states = {"x1": min(float(values["level_upper"]), x1max), "x2": float(values["level"])}
    return {"type": "equations", "states": states,
            "parameters": {k: float(values[k]) for k in ("k1", "k3", "k4", "x1max", "frac")},
            "derivatives": {"x1": f"where(x1 >= x1max, min({NET}, 0.0), {NET})",
                            "x2": f"k1*sqrt(x1) - k3*sqrt(x2) + where(x1 >= x1max, frac*max({NET}, 0.0), 0.0)"},
            "bounds": {"x1": [0.0, None], "x2": [0.0, None]}, "output": "x2"}


extend = extension(equations)


def upper_level(ctx: Context, config: dict) -> np.ndarray:
    """The upper tank's level x1 over the steady state of the estimation runs, as the tanks'
    ``config`` simulates it (its output set to x1, without output block and offset)."""
    probe = copy.deepcopy(config)
    model = probe["model"]
    model["output"] = "x1"
    model.pop("output_nonlinearity", None)
    model["output_offset"] = 0.0
    runner = ctx.runner.with_changes(probe)
    return np.concatenate([steady_mean(run, x) for run, x in zip(ctx.runs, runner.simulate_each(ctx.runs))])


def rim_start(ctx: Context, values: dict, y: np.ndarray) -> dict[str, float]:
    """The rim and spill share of the grid (module docstring) that simulate closest with the
    tanks of ``values`` (each trial's output offset moved by its mean error)."""
    x1 = upper_level(ctx, extend_plain(ctx.runner.data, values))
    best, best_rss = {"x1max": float(np.quantile(x1, RIM_QUANTILES[-1])), "frac": FRACTIONS[0]}, math.inf
    for q, frac in itertools.product(RIM_QUANTILES, FRACTIONS):
        trial = {"x1max": float(np.quantile(x1, q)), "frac": frac}
        try:
            e = y - simulated(ctx, {**values, **trial}, extend)
        except InputError:  # a trial the equations cannot run
            continue
        rss = float(np.sum((e - np.mean(e)) ** 2))
        if rss < best_rss:
            best, best_rss = trial, rss
    return best


def _estimate(ctx: Context) -> Estimate | str:
    """From the linear model's map (:func:`~nlsid.diagnose.hypotheses.tank_outflow.start_values`),
    each pole assignment with the rim of :func:`rim_start`, pre-fitted with it
    (:func:`~nlsid.diagnose.hypotheses.tank_outflow.prefit`); the one of lower simulation error."""
    point = operating_point(ctx)
    if isinstance(point, str):
        return point
    rates, gain, u0, y = point
    fits = []
    for poles in (tuple(reversed(rates)), tuple(rates)):
        values = {**start_values(poles, gain, u0), "u0": u0, "output_offset": 0.0}
        try:
            rim = rim_start(ctx, values, y)
        except InputError:
            continue
        fits.append(prefit(ctx, poles, gain, u0, y, rim, extend))
    if not fits or not math.isfinite(min(f[1] for f in fits)):
        return "the start does not run (a level leaves its bounds or a value is not finite)"
    values, rss, _ = min(fits, key=lambda f: f[1])
    note = (f"linearisation of sqrt outflow at the mean input u0 = {u0:.4g}, the rim on a grid of the upper level's "
            f"percentiles and spill shares, pre-fitted ({sum(f[2] for f in fits)} simulations): the rim at "
            f"{values['x1max']:.4g}, {values['frac']:.3g} of the spill into the lower tank; {pole_note(values)}")
    paths = {PARAMETER + k: f"model.parameters.{k}" for k in ("k1", "k3", "k4", "x1max", "frac")}
    before = float(np.sum(ctx.target() ** 2))
    return Estimate(named(values), {k: float("nan") for k in named(values)}, explained_db(before, rss), note,
                    paths=paths)


def _extend(data: dict, values: dict) -> dict:
    return extend(data, plain(values))


def _reading(values: dict) -> str:
    values = plain(values)
    return (f"two tanks (equal cross-sections, k2 = k1): outflows k1 = {values['k1']:.4g}, k3 = {values['k3']:.4g}, "
            f"inflow k4 = {values['k4']:.4g} per unit input; the upper tank overflows at x1max = "
            f"{values['x1max']:.4g} (on the scale of k2 = k1), {values['frac']:.3g} of the spill into the lower tank")


HYPOTHESES = (
    Hypothesis("cascaded_tanks_overflow", "Square-root outflow (two cascaded tanks), the upper one overflowing",
               "structure", "parameter x1max", "the upper tank's level (on the scale of equal cross-sections)",
               SIGNATURE + "; the response to a rising input capped at the largest levels (the upper tank spills)",
               applies_to(2), _estimate, _extend, tuple(PARAMETER + k for k in ("k1", "k3", "k4", "x1max", "frac")),
               reading=_reading, derive=derive),
)
