"""Wrong mass, damping or stiffness of a mass_spring_damper, corrected by the fit engine from the
model's own values."""

from __future__ import annotations

import copy
import math

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis
from nlsid.diagnose.hypotheses.linear_dynamics import coefficient_paths
from nlsid.diagnose.simulation import ModelRunner


MECHANICS = ("mass", "damping", "stiffness")

LINEAR_MECHANICS = {"mass_spring_damper": MECHANICS,
                    "two_mass_stage": ("motor_mass", "load_mass", "stiffness", "damping", "motor_damping",
                                       "load_damping")}


def linear_paths(data: dict) -> dict[str, str]:
    """The linear mechanics a force or block hypothesis refines together with its own parameters
    (a linear part held at the user's values cannot reach the floor once reality
    differs from it in two ways, e.g. a 5 % mass error and Coulomb friction): the masses, dampings
    and stiffnesses of a mechanical template that are not zero (a zero has no sign to keep and is
    a structural choice: a free mass has no spring). The actuator gain is held: with the masses,
    dampings and stiffnesses free it only rescales them. Of a model written as equations, its
    nonzero ``parameters`` (named ``parameter NAME``). Name -> key path; empty for other models.
    """
    model = data["model"]
    if model.get("type") == "transfer_function":
        return coefficient_paths(data)
    if model.get("type") == "equations":  # the parameters of the user's equations, named apart from a block's
        return {f"parameter {k}": f"model.parameters.{k}" for k, v in (model.get("parameters") or {}).items()
                if float(v) != 0.0}
    keys = LINEAR_MECHANICS.get(model.get("type"), ())
    return {k: f"model.{k}" for k in keys if float(model.get(k, 0.0)) != 0.0}

def _mass_spring_damper(runner: ModelRunner) -> str | None:
    return None if runner.kind == "mass_spring_damper" else "needs a mass_spring_damper model"

def _estimate_mechanics(ctx: Context) -> Estimate | str:
    """Start values: the model's own mass, damping and stiffness (the fit engine corrects them). A
    zero stiffness stays zero, not fitted (a free mass has no spring: a structural choice, and a
    start of zero has no sign to keep); a zero damping of a mass on a spring starts at 5 % of
    critical, 0.1 sqrt(k m), so that it has an effect to fit, and of a free mass stays zero."""
    model = ctx.runner.data["model"]
    values = {"mass": float(model["mass"]), "damping": float(model.get("damping", 0.0)),
              "stiffness": float(model.get("stiffness", 0.0))}
    if values["damping"] == 0 and values["stiffness"] > 0:
        values["damping"] = 0.1 * math.sqrt(values["stiffness"] * values["mass"])
    note = "start at the model's own values" + ("; a free mass: no stiffness" if values["stiffness"] == 0 else "")
    return Estimate(values, {k: float("nan") for k in values}, float("nan"), note,
                    paths={k: f"model.{k}" for k, v in values.items() if v != 0})

def _set_keys(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    out["model"].update({k: float(v) for k, v in values.items()})
    return out


HYPOTHESES = (
    Hypothesis("wrong_mechanics", "Wrong damping, stiffness or mass", "linear", "damping", "N s/m",
               "BLA differs from the model around its resonance (height, frequency); no distortion",
               _mass_spring_damper, _estimate_mechanics, _set_keys, MECHANICS,
               lambda data: {k: f"model.{k}" for k in MECHANICS}),
)
