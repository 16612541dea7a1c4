"""Dotted key paths into a config dict: ``model.nonlinearities[0].fc``, ``model.den[1]``, ``model.A[1][0]``.

A sweep, a free parameter of ``fit --model`` and a diagnosis's hypothesis all name a number of a
model config this way; the value is written at that path into the loaded YAML and the whole config
is validated again, so that a value set here obeys the rules (and gives the messages) of a value
written in the file.

Examples
--------
>>> data = {"model": {"mass": 2.0, "den": [1.0, 0.5]}}
>>> parse("model.den[1]")
('model', 'den', 1)
>>> copy = deep_copy(data)
>>> set_value(copy, "model.den[1]", 0.25)
>>> copy["model"]["den"], data["model"]["den"]
([1.0, 0.25], [1.0, 0.5])
>>> key_text(("model", "den", 1))
'model.den[1]'
"""

from __future__ import annotations

import numbers as numbers_module

import re
from typing import Callable

from nlsid.errors import InputError

_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")


def parse(path: str) -> tuple | None:
    """``a.b[2].c`` -> ("a", "b", 2, "c"); None when ``path`` is not a dotted key path."""
    keys: list = []
    for part in path.split("."):
        match = _PART.fullmatch(part)
        if match is None:
            return None
        keys.append(match.group(1))
        keys.extend(int(i) for i in re.findall(r"\[(\d+)\]", match.group(2)))
    return tuple(keys)


def key_text(keys: tuple) -> str:
    """``("model", "den", 2)`` -> ``model.den[2]`` (``the config`` for no keys)."""
    text = ""
    for key in keys:
        text += f"[{key}]" if isinstance(key, int) else (f".{key}" if text else key)
    return text or "the config"


def check_step(node, key, above: tuple, error: Callable[[str], Exception]) -> None:
    """Raise ``error(what)`` unless ``key`` can be taken from ``node`` (reached by the keys ``above``):
    an index needs a list that long, a name a mapping (a missing name is created by :func:`set_value`)."""
    if isinstance(key, int):
        if not isinstance(node, list):
            raise error(f"{key_text(above)} is not a list: no item [{key}]")
        if key >= len(node):
            raise error(f"no item [{key}]: {key_text(above)} has {len(node)} item{'s' if len(node) != 1 else ''}")
    elif not isinstance(node, dict):
        raise error(f"{key_text(above)} is not a mapping: no key {key!r}")


def set_value(data: dict, path: str, value: float, key: str = "sweep.parameter") -> None:
    """Write ``value`` at the dotted key ``path`` of ``data`` (missing mapping keys are created).
    Errors are addressed to ``key``, the config key that named the path: ``sweep.parameter`` (the
    message then starts with the path), or a free parameter's own key ``free.<path>``."""
    def error(what: str) -> InputError:
        return InputError(key, f"{path}: {what}" if key == "sweep.parameter" else what)

    keys = parse(path)
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


def deep_copy(value):
    """A copy of a loaded YAML tree (dicts and lists copied, leaves shared: they are immutable)."""
    if isinstance(value, dict):
        return {k: deep_copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [deep_copy(v) for v in value]
    return value


def numbers(data: dict, sections: tuple[str, ...] = ("model", "closed_loop")) -> dict[str, float | int]:
    """Every number (not a bool) of the ``sections`` of a config as written, by dotted key path
    (``{"model.mass": 2.0, "model.nonlinearities[0].fc": 0.5, ...}``): the paths ``free:``,
    ``sweep.parameter`` and :func:`set_value` take."""
    out: dict[str, float | int] = {}

    def walk(node, keys: tuple) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                walk(value, keys + (key,))
        elif isinstance(node, list):
            for i, value in enumerate(node):
                walk(value, keys + (i,))
        elif isinstance(node, numbers_module.Real) and not isinstance(node, bool):
            out[key_text(keys)] = node

    for section in sections:
        if section in data:
            walk(data[section], (section,))
    return out
