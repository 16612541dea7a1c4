"""Static and hysteretic blocks at a plant's input or output: when a hypothesis applies, and the
extension that sets the block."""

from __future__ import annotations

import copy
from typing import Callable

import numpy as np

from nlsid.diagnose.simulation import LTI, ModelRunner


def no_block(key: str) -> Callable[[ModelRunner], str | None]:
    def applies(runner: ModelRunner) -> str | None:
        if runner.kind not in LTI + ("mass_spring_damper", "two_mass_stage", "equations"):
            return "needs an LTI model, a mechanical template or a model written as equations"
        if runner.data["model"].get(key) is not None:
            return f"the model already has an {key}"
        return None
    return applies

def block_map(block: dict) -> Callable[[np.ndarray], np.ndarray]:
    from nlsid.io.model_config import BacklashConfig, DeadzoneConfig, SaturationConfig
    from nlsid.models.blocks import static_block
    from nlsid.simulate.engine import apply_static

    schema = {"saturation": SaturationConfig, "deadzone": DeadzoneConfig, "backlash": BacklashConfig}[block["type"]]
    encoded = static_block(schema(**block))
    return lambda x: apply_static(encoded, x)

def set_block(key: str, kind: str) -> Callable[[dict, dict], dict]:
    def extend(data: dict, values: dict) -> dict:
        out = copy.deepcopy(data)
        out["model"][key] = {"type": kind, **{k: float(v) for k, v in values.items()}}
        return out
    return extend

def block_paths(key: str, names: tuple[str, ...]) -> Callable[[dict], dict[str, str]]:
    return lambda data: {n: f"model.{key}.{n}" for n in names}
