"""Cubic feedback of the output around a linear model: the Duffing structure for any transfer
function, continuous or discrete (such as the one ``nlsid fit`` writes from a BLA).

The model G from u to y becomes y = G (u - k3 y^3): a ``nonlinear_feedback`` plant with G as its
linear part (gain 1, so k3 is in units of u per y^3) and a ``cubic_stiffness`` force reading y. Its
physical reading is a cubic spring, hardening for k3 > 0 and softening for k3 < 0, when y is a
position and u a force (the electronic Duffing oscillator of the Silverbox benchmark, Wigren and
Schoukens 2013, is this system).

Signature: to first order in k3 the residual is the model's response to the input error
-k3 y_model^3, so k3 is the least-squares regression of the residual on that response. A force
cannot act within the sample it is computed from, so G must be strictly proper: a discrete b0 (the
z^0 coefficient of the numerator) is set to zero, a continuous numerator must be of lower degree.
The fit engine then refines k3 together with the linear part's coefficients (all of the numerator
but b0, the denominator but its leading 1): under the nonlinearity the BLA the model came from is
biased, and a frozen linear part could not reach the floor.
"""

from __future__ import annotations

import copy

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.simulation import ModelRunner

KEPT = ("input_offset", "output_offset", "input_channels", "output_timing", "input_nonlinearity",
        "output_nonlinearity", "delay")


def _applies(runner: ModelRunner) -> str | None:
    model = runner.data["model"]
    if model["type"] != "transfer_function":
        return "needs a transfer_function model (the mechanical templates have cubic stiffness)"
    num, den = np.trim_zeros(np.asarray(model["num"], float), "f"), np.asarray(model["den"], float)
    if model.get("domain", "continuous") == "continuous" and num.size >= np.trim_zeros(den, "f").size:
        return "the continuous model is not strictly proper (a force would act without delay)"
    return None


def _estimate(ctx: Context) -> Estimate | str:
    outputs = [ctx.runner.simulate(run).y for run in ctx.runs]
    est = regress(ctx.target(), [ctx.response([-x**3 for x in outputs], "process")], ["k3"])
    notes = [f"odd feedback of y^3 with the sign of a {'hardening' if est.values['k3'] > 0 else 'softening'} spring"]
    model = ctx.runner.data["model"]
    if model.get("domain") == "discrete" and model["num"][0] != 0:
        notes.append(f"b0 = {model['num'][0]:.3g} set to 0: a force cannot act within its own sample")
    return Estimate(est.values, est.std, est.explained_db, "; ".join(notes))


def _extend(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    model = out["model"]
    linear = {k: model[k] for k in ("type", "num", "den", "domain") if k in model}
    if linear.get("domain") == "discrete":
        linear["num"] = [0.0, *linear["num"][1:]]
    out["model"] = {"type": "nonlinear_feedback", "linear": linear, "gain": 1.0,
                    "nonlinearities": [{"type": "cubic_stiffness", "k3": float(values["k3"])}],
                    **{k: model[k] for k in KEPT if k in model}}
    return out


def _paths(data: dict) -> dict[str, str]:
    """k3, and the linear part's coefficients (numerator but a discrete b0, denominator but a0)."""
    model = data["model"]
    first = 1 if model.get("domain") == "discrete" else 0
    paths = {"k3": "model.nonlinearities[0].k3"}
    paths.update({f"num[{i}]": f"model.linear.num[{i}]" for i in range(first, len(model["num"]))
                  if model["num"][i] != 0})
    paths.update({f"den[{i}]": f"model.linear.den[{i}]" for i in range(1, len(model["den"])) if model["den"][i] != 0})
    return paths


HYPOTHESES = (
    Hypothesis("cubic_feedback", "Cubic feedback of the output (cubic stiffness)", "stiffness", "k3",
               "input units / output units^3",
               "odd distortion; the resonance moves with level; residual like the response to -y^3 at the input",
               _applies, _estimate, _extend, ("k3",), _paths),
)
