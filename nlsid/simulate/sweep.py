"""Parameter sweeps: one validated config per value of the swept key.

The sweep names a number of the same config by a dotted path (``closed_loop.feedforward.coulomb``,
``model.nonlinearities[0].fc``, or a list element: ``model.den[1]``, ``model.A[1][0]``); each value is written at that path into the loaded YAML and the
whole config is validated again, so a swept value obeys the same rules (and gives the same messages)
as a value written in the file. ``linspace`` follows numpy.linspace (both ends included).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.io.config import load_yaml
from nlsid.io.model_config import SimulateConfig, validate_simulate_config
from nlsid.models.key_paths import deep_copy, parse, set_value

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
        keys = parse(error.where)
        if not self.source or keys is None or keys[0] not in SimulateConfig.model_fields:
            return error
        line = next((self.lines[keys[:end]] for end in range(len(keys), 0, -1) if keys[:end] in self.lines), None)
        where = f"{self.source}:{line}" if line is not None else self.source
        return InputError(where, f"{error.where}: {error.what}")


def sweep_values(config: SimulateConfig) -> np.ndarray:
    sweep = config.sweep
    if sweep.values is not None:
        return np.asarray(sweep.values, dtype=float)
    return np.linspace(sweep.linspace.start, sweep.linspace.stop, sweep.linspace.num)


def load_points(path: str | os.PathLike) -> list[SweepPoint]:
    """The configs to simulate: the file itself, or one per value of its sweep."""
    data, lines = load_yaml(path)
    return config_points(data, path, lines)


def config_points(data, path: str | os.PathLike | None, lines: dict | None = None) -> list[SweepPoint]:
    """:func:`load_points` of loaded data; ``path`` None for a config given as a dict (its errors
    then name the key path alone)."""
    source, lines = ("" if path is None else str(path)), lines or {}
    config = validate_simulate_config(data, path, lines)
    if config.sweep is None:
        return [SweepPoint({}, config, source, lines)]
    name = config.sweep.name or config.sweep.parameter
    points = []
    for value in sweep_values(config):
        copy = deep_copy(data)
        try:
            set_value(copy, config.sweep.parameter, float(value))
        except InputError as exc:
            raise SweepPoint({}, config, source, lines).locate(exc) from None
        try:
            points.append(SweepPoint({name: float(value)}, validate_simulate_config(copy, path, lines), source, lines))
        except InputError as exc:
            raise InputError(exc.where, f"sweep value {value:g}: {exc.what}") from None
    return points
