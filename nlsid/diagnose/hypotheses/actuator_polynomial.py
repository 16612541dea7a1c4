"""A static actuator polynomial before the dynamics (a Hammerstein system): the plant gets
f(u) = u + a2 u^2 + a3 u^3 instead of u, the ``input_nonlinearity: polynomial`` block with
coefficients [0, 1, a2, a3].

The linear coefficient stays 1 (a gain error is the linear part's, refined with the block) and the
constant 0 (it is the input offset, a nuisance). An even term a2 makes the actuator asymmetric
(stronger one way) and leaves even distortion; the odd a3 compresses (< 0) or expands (> 0) the
large commands, odd distortion.

Signature: to first order the residual is the model's response to the input error a2 u^2 + a3 u^3
at the plant input, so a2 and a3 are the least-squares regression of the residual on the responses
to u^2 and u^3, with a constant (the u^2 column has a mean, a constant force whose static effect
the offsets take: target and columns without their means, Frisch-Waugh). The fit engine then
refines a2 and a3 with the linear part. Its neighbours differ in where the polynomial acts: a
cubic spring reads the output (y^3 fed back through the dynamics), a quadratic output block acts
after them; the input's polynomial goes through the whole plant as the command does, so its
distortion has the plant's shape at every harmonic.
"""

from __future__ import annotations

import copy

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.plant_blocks import no_block

TERMS = ("a2", "a3")


def _centred(x: np.ndarray) -> np.ndarray:
    return x - x.mean()


def _estimate(ctx: Context) -> Estimate | str:
    columns = [ctx.response([run.u ** int(name[1]) for run in ctx.runs], "process") for name in TERMS]
    est = regress(_centred(ctx.target()), [_centred(c) for c in columns], list(TERMS))
    return Estimate(est.values, est.std, est.explained_db,
                    "a2 and a3 regressed on the responses to u^2 and u^3 at the plant input, with a constant")


def _extend(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    out["model"]["input_nonlinearity"] = {"type": "polynomial",
                                          "coefficients": [0.0, 1.0, float(values["a2"]), float(values["a3"])]}
    return out


def _paths(data: dict) -> dict[str, str]:
    return {name: f"model.input_nonlinearity.coefficients[{int(name[1])}]" for name in TERMS}


def _reading(values: dict) -> str:
    """The fitted curve in words: where it is stronger (a2) and whether it compresses or expands (a3)."""
    a2, a3 = values["a2"], values["a3"]
    return (f"the actuator {'stronger' if a2 > 0 else 'weaker'} for u > 0 (a2), "
            f"{'expanding' if a3 > 0 else 'compressing'} large commands (a3)")


HYPOTHESES = (
    Hypothesis("actuator_polynomial", "Static actuator polynomial (Hammerstein)", "input", "a3", "1/input units^2",
               "odd and even distortion; residual like the responses to u^2 and u^3 at the plant input",
               no_block("input_nonlinearity"), _estimate, _extend, TERMS, _paths, reading=_reading,
               holds=("input_offset",)),
)
