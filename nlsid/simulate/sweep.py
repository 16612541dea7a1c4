"""Parameter sweeps: one validated config per value of the swept key.

The sweep names a number of the same config by a dotted path (``closed_loop.feedforward.coulomb``,
``model.nonlinearities[0].fc``, or a list element: ``model.den[1]``, ``model.A[1][0]``); each value is written at that path into the loaded YAML and the
whole config is validated again, so a swept value obeys the same rules (and gives the same messages)
as a value written in the file. ``linspace`` follows numpy.linspace (both ends included).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.io.config import load_yaml
from nlsid.io.model_config import SimulateConfig, validate_simulate_config

_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")


@dataclass(frozen=True)
class SweepPoint:
    """One configuration to simulate and the parameters it adds to each run's ``params``.

    ``source`` (the file) and ``lines`` (key path -> line) let errors found while building or
    running the model name the file, line and key like the config loader does.
    """

    params: dict
    config: SimulateConfig
    source: str = ""
    lines: dict = field(default_factory=dict)

    def locate(self, error: InputError) -> InputError:
        """Re-address an error whose ``where`` is a config key (``closed_loop.controller``) to the file."""
        keys = _keys(error.where)
        if not self.source or keys is None or keys[0] not in SimulateConfig.model_fields:
            return error
        line = next((self.lines[keys[:end]] for end in range(len(keys), 0, -1) if keys[:end] in self.lines), None)
        where = f"{self.source}:{line}" if line is not None else self.source
        return InputError(where, f"{error.where}: {error.what}")


def _keys(path: str) -> tuple | None:
    """``a.b[2].c`` -> ("a", "b", 2, "c"); None when ``path`` is not a dotted key path."""
    keys: list = []
    for part in path.split("."):
        match = _PART.fullmatch(part)
        if match is None:
            return None
        keys.append(match.group(1))
        keys.extend(int(i) for i in re.findall(r"\[(\d+)\]", match.group(2)))
    return tuple(keys)


def _set(data: dict, path: str, value: float, key: str = "sweep.parameter") -> None:
    """Write ``value`` at the dotted key ``path`` of ``data``. Errors are addressed to ``key``, the
    config key that named the path: ``sweep.parameter`` (the message then starts with the path), or
    a free parameter's own key ``free.<path>``."""
    def error(what: str) -> InputError:
        return InputError(key, f"{path}: {what}" if key == "sweep.parameter" else what)

    keys = _keys(path)
    if keys is None:
        raise InputError(key, f"expected a dotted key path such as closed_loop.feedforward.coulomb, got {path!r}")
    if keys[0] == "sweep":
        raise InputError(key, "a sweep cannot sweep itself") if key == "sweep.parameter" \
            else error("the sweep section holds no model parameter")
    node = data
    for depth, part in enumerate(keys[:-1]):
        check_step(node, part, keys[:depth], error)
        node = node[part] if isinstance(part, int) else node.setdefault(part, {})
    check_step(node, keys[-1], keys[:-1], error)
    node[keys[-1]] = value


def key_text(keys: tuple) -> str:
    """``("model", "den", 2)`` -> ``model.den[2]`` (``the config`` for no keys)."""
    text = ""
    for key in keys:
        text += f"[{key}]" if isinstance(key, int) else (f".{key}" if text else key)
    return text or "the config"


def check_step(node, key, above: tuple, error) -> None:
    """Raise ``error(what)`` unless ``key`` can be taken from ``node`` (reached by the keys ``above``):
    an index needs a list that long, a name a mapping (a missing name is created by :func:`_set`)."""
    if isinstance(key, int):
        if not isinstance(node, list):
            raise error(f"{key_text(above)} is not a list: no item [{key}]")
        if key >= len(node):
            raise error(f"no item [{key}]: {key_text(above)} has {len(node)} item{'s' if len(node) != 1 else ''}")
    elif not isinstance(node, dict):
        raise error(f"{key_text(above)} is not a mapping: no key {key!r}")


def sweep_values(config: SimulateConfig) -> np.ndarray:
    sweep = config.sweep
    if sweep.values is not None:
        return np.asarray(sweep.values, dtype=float)
    return np.linspace(sweep.linspace.start, sweep.linspace.stop, sweep.linspace.num)


def load_points(path: str | os.PathLike) -> list[SweepPoint]:
    """The configs to simulate: the file itself, or one per value of its sweep."""
    data, lines = load_yaml(path)
    config = validate_simulate_config(data, path, lines)
    if config.sweep is None:
        return [SweepPoint({}, config, str(path), lines)]
    name = config.sweep.name or config.sweep.parameter
    points = []
    for value in sweep_values(config):
        copy = _deep_copy(data)
        try:
            _set(copy, config.sweep.parameter, float(value))
        except InputError as exc:
            raise SweepPoint({}, config, str(path), lines).locate(exc) from None
        try:
            points.append(SweepPoint({name: float(value)}, validate_simulate_config(copy, path, lines), str(path), lines))
        except InputError as exc:
            raise InputError(exc.where, f"sweep value {value:g}: {exc.what}") from None
    return points


def _deep_copy(value):
    if isinstance(value, dict):
        return {k: _deep_copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_deep_copy(v) for v in value]
    return value
