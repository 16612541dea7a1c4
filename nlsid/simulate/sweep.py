"""Parameter sweeps: one validated config per value of the swept key.

The sweep names a key of the same config by a dotted path (``closed_loop.feedforward.coulomb``,
``model.nonlinearities[0].fc``); each value is written at that path into the loaded YAML and the
whole config is validated again, so a swept value obeys the same rules (and gives the same messages)
as a value written in the file. ``linspace`` follows numpy.linspace (both ends included).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError
from nlsid.io.config import load_yaml, validate
from nlsid.io.model_config import SimulateConfig

_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")


@dataclass(frozen=True)
class SweepPoint:
    """One configuration to simulate and the parameters it adds to each run's ``params``."""

    params: dict
    config: SimulateConfig


def _set(data: dict, path: str, value: float) -> None:
    keys: list = []
    for part in path.split("."):
        match = _PART.fullmatch(part)
        if match is None:
            raise InputError("sweep.parameter", f"expected a dotted key path such as closed_loop.feedforward.coulomb, got {path!r}")
        keys.append(match.group(1))
        keys.extend(int(i) for i in re.findall(r"\[(\d+)\]", match.group(2)))
    if keys[0] == "sweep":
        raise InputError("sweep.parameter", "a sweep cannot sweep itself")
    node = data
    for depth, key in enumerate(keys[:-1]):
        if isinstance(key, int):
            if not isinstance(node, list) or key >= len(node):
                raise InputError("sweep.parameter", f"{path}: no item [{key}] in the config")
            node = node[key]
        else:
            if not isinstance(node, dict):
                raise InputError("sweep.parameter", f"{path}: {key!r} is not a mapping key in the config")
            node = node.setdefault(key, {})
    last = keys[-1]
    if isinstance(last, int) or not isinstance(node, dict):
        raise InputError("sweep.parameter", f"{path}: must end in a key of a mapping")
    node[last] = value


def sweep_values(config: SimulateConfig) -> np.ndarray:
    sweep = config.sweep
    if sweep.values is not None:
        return np.asarray(sweep.values, dtype=float)
    return np.linspace(sweep.linspace.start, sweep.linspace.stop, sweep.linspace.num)


def load_points(path: str | os.PathLike) -> list[SweepPoint]:
    """The configs to simulate: the file itself, or one per value of its sweep."""
    data, lines = load_yaml(path)
    config = validate(data, SimulateConfig, path, lines)
    if config.sweep is None:
        return [SweepPoint({}, config)]
    name = config.sweep.name or config.sweep.parameter
    points = []
    for value in sweep_values(config):
        copy = _deep_copy(data)
        _set(copy, config.sweep.parameter, float(value))
        try:
            points.append(SweepPoint({name: float(value)}, validate(copy, SimulateConfig, path, lines)))
        except InputError as exc:
            raise InputError(exc.where, f"sweep value {value:g}: {exc.what}") from None
    return points


def _deep_copy(value):
    if isinstance(value, dict):
        return {k: _deep_copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_deep_copy(v) for v in value]
    return value
