"""An even (quadratic) nonlinearity at the plant output: y = x + a2 x^2."""

from __future__ import annotations

import copy

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.plant_blocks import no_block


def _estimate_quadratic(ctx: Context) -> Estimate | str:
    outputs = ctx.runner.simulate_each(ctx.runs)
    return regress(ctx.target(), [ctx.response([x**2 for x in outputs], "output")], ["a2"])

def _extend_quadratic(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    out["model"]["output_nonlinearity"] = {"type": "polynomial", "coefficients": [0.0, 1.0, float(values["a2"])]}
    return out


HYPOTHESES = (
    Hypothesis("quadratic_output", "Quadratic (even) output nonlinearity", "output", "a2", "1/output units",
               "even distortion at the even detection lines",
               no_block("output_nonlinearity"), _estimate_quadratic, _extend_quadratic, ("a2",),
               lambda data: {"a2": "model.output_nonlinearity.coefficients[2]"}),
)
