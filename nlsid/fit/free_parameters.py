"""Free parameters of a model config: start values and bounds, and the values their key paths name.

A free parameter is named by a dotted key path into the config (``model.nonlinearities[0].fc``,
``closed_loop.feedforward.coulomb``, or any number of a list: ``model.num[0]``, ``model.A[1][0]``);
its start is the value written there unless the ``free:`` section gives one
(:func:`value_at`). Writing values: :func:`nlsid.models.key_paths.set_value`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nlsid.errors import InputError
from nlsid.models.key_paths import check_step, parse


@dataclass(frozen=True)
class FreeParameter:
    """A free parameter: start value (None: the value written in the config) and bounds."""

    start: float | None = None
    lower: float = -math.inf
    upper: float = math.inf


def free_from_config(free_config: dict) -> dict[str, FreeParameter]:
    """The ``free:`` section of a validated config as :class:`FreeParameter` objects."""
    return {
        key: FreeParameter(p.start, -math.inf if p.lower is None else p.lower, math.inf if p.upper is None else p.upper)
        for key, p in free_config.items()
    }


def value_at(data: dict, path: str):
    """The value at a dotted key path of a config dict, list elements included (``model.den[2]``);
    None when a mapping key along it is absent. An index beyond a list, or into something that is
    not a list, is an error naming the path (:func:`nlsid.models.key_paths.check_step`)."""
    keys = parse(path)
    if keys is None:
        raise InputError(f"free.{path}", "expected a dotted key path such as model.nonlinearities[0].fc")
    node = data
    for depth, key in enumerate(keys):
        check_step(node, key, keys[:depth], lambda what: InputError(f"free.{path}", what))
        if not isinstance(key, int) and key not in node:
            return None
        node = node[key]
    return node
