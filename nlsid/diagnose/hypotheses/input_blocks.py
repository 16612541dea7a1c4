"""Actuator nonlinearities at the plant input: saturation, deadzone and backlash, each one parameter
found by a bounded search of the residual it predicts, e ~ S[f_a(u) - u].

Each refinement holds the input offset at the value the nuisances got (none in open loop: a
constant at the plant input of a model without a block is a constant force, which the output
offset takes). An offset c before the block moves along a direction the data cannot fix:

- deadzone [l, h]: f(x + c) is the deadzone [l - c, h - c] exactly (x + c - h above it, x + c - l
  below);
- saturation [l, h]: f(x + c) = sat(x; l - c, h - c) + c, the saturation moved by c and a constant
  force c after it, which a plant with a finite static gain G(0) turns into the constant output
  c G(0) that the output offset takes;
- backlash: the play operator commutes with a shift, f(x + c) = f(x) + c in the steady state, the
  same constant force.

Left free, the offset and the limits trade along that direction, and the limits' values are
wherever the search stopped on it (a saturation at +-8 came out at -9.50 / +6.49 with the input
offset at -1.49 on an independent-plant record at 35 dB, tests/diagnose/test_diagnose_msd_battery.py);
held, the limits are those of the recorded input."""

from __future__ import annotations

from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, quantile, scan
from nlsid.diagnose.hypotheses.plant_blocks import block_map, block_paths, no_block, set_block


def _input_block(make: Callable[[float], dict], name: str, lower: Callable[[np.ndarray], float],
                 upper: Callable[[np.ndarray], float]) -> Callable[[Context], Estimate | str]:
    """Estimate of a one-parameter input block: e ~ S[f_a(u) - u], a by a bounded search."""
    def estimate(ctx: Context) -> Estimate | str:
        y = ctx.target()
        magnitude = np.abs(np.concatenate([run.u for run in ctx.runs]))

        def predicted(a: float) -> np.ndarray:
            block = block_map(make(a))
            return ctx.response([block(run.u) - run.u for run in ctx.runs], "process")

        a = scan(lambda a: float(np.sum((y - predicted(a)) ** 2)), lower(magnitude), upper(magnitude))
        rss = float(np.sum((y - predicted(a)) ** 2))
        values = {k: v for k, v in make(a).items() if k != "type"}
        return Estimate(values, {k: float("nan") for k in values}, explained_db(float(np.sum(y**2)), rss),
                        f"symmetric {name} by a bounded search of the residual")
    return estimate

def _saturation(a: float) -> dict:
    return {"type": "saturation", "lower": -a, "upper": a}

def _deadzone(a: float) -> dict:
    return {"type": "deadzone", "lower": -a, "upper": a}

def _backlash(w: float) -> dict:
    return {"type": "backlash", "width": w}


HYPOTHESES = (
    Hypothesis("input_saturation", "Input saturation", "input", "upper", "input units",
               "odd distortion; BLA gain falls with level; residual where |u| is large",
               no_block("input_nonlinearity"),
               _input_block(_saturation, "limit", quantile(0.5), lambda x: float(np.max(x))),
               set_block("input_nonlinearity", "saturation"), ("upper", "lower"),
               block_paths("input_nonlinearity", ("upper", "lower")), holds=("input_offset",)),
    Hypothesis("deadzone", "Input deadzone", "input", "upper", "input units",
               "odd distortion; BLA gain rises with level; residual where |u| is small",
               no_block("input_nonlinearity"),
               _input_block(_deadzone, "half width", lambda x: 0.0, quantile(0.9)),
               set_block("input_nonlinearity", "deadzone"), ("upper", "lower"),
               block_paths("input_nonlinearity", ("upper", "lower")), holds=("input_offset",)),
    Hypothesis("backlash", "Backlash at the input", "input", "width", "input units",
               "odd distortion and a phase lag that shrinks with level",
               no_block("input_nonlinearity"),
               _input_block(_backlash, "width", quantile(0.001), quantile(0.9)),
               set_block("input_nonlinearity", "backlash"), ("width",), block_paths("input_nonlinearity", ("width",)),
               holds=("input_offset",)),
)
