"""Forces on the driven mass of a mechanical template: the signatures' regressors and the extension
that appends a force to ``model.nonlinearities``."""

from __future__ import annotations

import copy
from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.simulation import ModelRunner


def mechanical(runner: ModelRunner) -> str | None:
    return None if runner.mechanical else "needs a mechanical template (mass_spring_damper, two_mass_stage)"

def needs(ctx: Context, signal: str) -> str | None:
    if all(signal in s for s in ctx.internal):
        return None
    return f"the model's {signal} of the driven mass is not available (closed loop on another output)"

def force_columns(ctx: Context, forces: list[Callable[[dict], np.ndarray]]) -> list[np.ndarray]:
    """Responses to unit-coefficient forces F(signals) at the driven mass: d = -F / gain."""
    gain = ctx.runner.actuator_gain
    return [ctx.response([-force(signals) / gain for signals in ctx.internal], "process") for force in forces]

def add_force(force: dict) -> Callable[[dict, dict], dict]:
    def extend(data: dict, values: dict) -> dict:
        out = copy.deepcopy(data)
        out["model"].setdefault("nonlinearities", []).append(
            {**force, **{k: float(v) for k, v in values.items()}})
        return out
    return extend

def force_paths(names: tuple[str, ...]) -> Callable[[dict], dict[str, str]]:
    """Key paths of the parameters of the force :func:`add_force` appends to ``data``."""
    def paths(data: dict) -> dict[str, str]:
        index = len(data["model"].get("nonlinearities", []))
        return {n: f"model.nonlinearities[{index}].{n}" for n in names}
    return paths
