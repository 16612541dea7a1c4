"""A sensor that saturates: the recorded output flat at a ceiling or a floor.

A sensor or its converter that reaches the end of its range records the same value for as long
as the signal stays beyond it: y = min(max(x, lower), upper) + output offset, the
``output_nonlinearity: saturation`` block of the model language. Its signature is in the
recording itself, not in the residual: many samples at the largest (or smallest) recorded value.
A continuous signal with noise takes its extreme value once; quantised by an ADC, a few times,
fewer than the levels just inside it (the extreme is in the tail of the distribution). So a side
is *flat* when at least FLAT_SHARE of the samples (and FLAT_MIN of them) lie on the extreme value
(within FLAT_TOLERANCE of the recorded range) and they outnumber those on the next recorded value
inward by FLAT_RATIO; the limit is that value less the model's output offset (the block acts
before the offset). A sensor that adds its noise after the clip records no flat side: the
hypothesis does not apply then.

Only the flat sides are parameters (refined by the fit engine with the model's linear part, as
every block): the other limit is put far beyond the recorded range (FAR times the range), where
it never acts. The first-order residual of the nominal model is exact for an output block in open
loop: e = S[sat(x) - x], x the model's output, S the response to an output error (identity in
open loop, the output sensitivity in closed loop).

An input (actuator) saturation clips the plant's input; the plant's dynamics smooth it, so the
output has no flat top: the two are told apart by the recording (tests/diagnose/test_output_saturation.py).
"""

from __future__ import annotations

import copy

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db
from nlsid.diagnose.hypotheses.plant_blocks import no_block

FLAT_SHARE = 0.002     # of the samples at least on the extreme value, for a flat side
FLAT_MIN = 5           # and at least this many
FLAT_RATIO = 3.0       # and this many times those on the next recorded value inward
FLAT_TOLERANCE = 1e-9  # of the recorded range: values this close count as one
FAR = 10.0             # the limit of a side that is not flat: this many ranges beyond the recorded one


def flat_sides(y: np.ndarray) -> dict[str, float]:
    """The flat sides of a recorded output (module docstring): ``upper`` -> the ceiling,
    ``lower`` -> the floor, each only where it is flat."""
    y = y[np.isfinite(y)]
    top, bottom = float(np.max(y)), float(np.min(y))
    tolerance = FLAT_TOLERANCE * max(top - bottom, abs(top), abs(bottom), 1e-300)
    out = {}
    for side, extreme, inward in (("upper", top, -1.0), ("lower", bottom, 1.0)):
        on = np.abs(y - extreme) <= tolerance
        count = int(np.sum(on))
        rest = y[~on]
        if count < max(FLAT_MIN, FLAT_SHARE * y.size) or rest.size == 0:
            continue
        nearest = float(rest[np.argmin(np.abs(rest - extreme))])
        below = int(np.sum(np.abs(rest - nearest) <= tolerance))
        if count >= FLAT_RATIO * below:
            out[side] = extreme
    return out


def _estimate(ctx: Context) -> Estimate | str:
    """The limits from the recorded extremes (less the model's output offset), the far limit for
    a side that is not flat, and the drop of the residual the block predicts."""
    y = np.concatenate([run.y for run in ctx.runs])
    flat = flat_sides(y)
    if not flat:
        return ("does not apply: the recorded output has no flat ceiling or floor (no value taken by "
                f"{FLAT_SHARE:.1%} of the samples at its extreme)")
    offset = float(ctx.runner.data["model"].get("output_offset", 0.0))
    spread = float(np.max(y) - np.min(y))
    upper = flat.get("upper", float(np.max(y)) + FAR * spread) - offset
    lower = flat.get("lower", float(np.min(y)) - FAR * spread) - offset
    outputs = [x - offset for x in ctx.runner.simulate_each(ctx.runs)]
    predicted = ctx.response([np.clip(x, lower, upper) - x for x in outputs], "output")
    target = ctx.target()
    if "upper" in flat:
        values = {"limit": upper, **({"floor": lower} if "lower" in flat else {"lower": lower})}
    else:
        values = {"limit": lower, "upper": upper}
    paths = {name: f"model.output_nonlinearity.{_side(values, name)}" for name in ("limit", "floor") if name in values}
    share = {side: float(np.mean(np.abs(y - flat[side]) <= FLAT_TOLERANCE * max(spread, 1e-300))) for side in flat}
    note = "; ".join(f"{'ceiling' if side == 'upper' else 'floor'} at {flat[side]:.6g} recorded on "
                     f"{100 * share[side]:.2g} % of the samples" for side in flat)
    return Estimate(values, {k: float("nan") for k in values},
                    explained_db(float(np.sum(target**2)), float(np.sum((target - predicted) ** 2))),
                    f"{note}; the limits from the recorded values less the output offset"
                    + ("" if len(flat) == 2 else f", the other side {FAR:g} recorded ranges beyond (never reached)"),
                    paths=paths)


def _side(values: dict, name: str) -> str:
    """The block key of the parameter ``name``: ``limit`` is the ceiling (``upper``) unless only the
    floor is flat (the values then hold the far ``upper``); ``floor`` is ``lower``."""
    return "lower" if name == "floor" or (name == "limit" and "upper" in values) else "upper"


def _extend(data: dict, values: dict) -> dict:
    """The saturation block of the values of :func:`_estimate` (``limit``, and ``floor`` or the far
    ``lower`` or ``upper``)."""
    blocks = {_side(values, name): value for name, value in values.items() if name in ("limit", "floor")}
    blocks.update({side: values[side] for side in ("upper", "lower") if side in values})
    out = copy.deepcopy(data)
    out["model"]["output_nonlinearity"] = {"type": "saturation", "lower": float(blocks["lower"]),
                                           "upper": float(blocks["upper"])}
    return out


def _qualifier(values: dict) -> str:
    return "ceiling and floor" if "floor" in values else "floor" if "upper" in values else "ceiling"


HYPOTHESES = (
    Hypothesis("output_saturation", "Output (sensor) saturation", "output", "limit", "output units",
               "the recorded output flat at a ceiling or a floor: many samples at its extreme value",
               no_block("output_nonlinearity"), _estimate, _extend, ("limit",), qualifier=_qualifier),
)
