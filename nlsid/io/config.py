"""YAML configs: a strict loader and validation against a pydantic schema, with line numbers.

PyYAML implements YAML 1.1, which silently turns ``1e3`` into a string, ``on``/``yes``/``no`` into
booleans and accepts duplicate keys. This loader follows YAML 1.2 instead: ``1e3`` is a float,
only ``true``/``false`` are booleans, and a duplicate key is an error. Every value keeps the line
it came from, so a validation error reads::

    configs/stage.yaml:14: multisine.rms_levels[2]: must be > 0
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Type, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from nlsid.errors import InputError

T = TypeVar("T", bound=BaseModel)


class StrictModel(BaseModel):
    """Base of every config schema: unknown keys are errors and types are not coerced."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class ConfigValueError(Exception):
    """A check across keys that a schema cannot express (e.g. a band above Nyquist).

    Raised by a schema's ``check()`` method with the key path it concerns, so the message gets the
    file and line like any other validation error.
    """

    def __init__(self, key_path: tuple, message: str):
        super().__init__(message)
        self.key_path = tuple(key_path)
        self.message = message


class _Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 core-schema booleans and floats."""


_Loader.yaml_implicit_resolvers = {
    first: [(tag, regex) for tag, regex in resolvers if tag not in ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:float")]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"),
    list("-+0123456789."),
)
# Integers keep PyYAML's resolver (it is tried first); a plain digit string stays an int.


def load_yaml(path: str | os.PathLike) -> tuple[Any, dict[tuple, int]]:
    """Load a YAML file; return the data and a map from key path (tuple) to 1-based line number."""
    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), "config file not found")
    text = decode_yaml(path.read_bytes(), str(path))
    loader = None
    try:
        loader = _Loader(text)  # the reader checks for unprintable characters here
        node = loader.get_single_node()
        lines: dict[tuple, int] = {}
        data = _construct(loader, node, (), lines, str(path), ()) if node is not None else None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        raise InputError(f"{path}:{line}", f"invalid YAML: control character U+{code:04X} is not allowed "
                                           "(a binary file?)") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise InputError(f"{path}{line}", f"invalid YAML: {' '.join(problem.split())}") from None
    finally:
        if loader is not None:
            loader.dispose()
    return data, lines


# Byte order marks, and the patterns of NUL bytes an ASCII first character makes without one (YAML
# 1.2 Section 5.2). UTF-32 comes first: its little-endian BOM begins with UTF-16's.
BOMS = ((b"\x00\x00\xfe\xff", "utf-32-be"), (b"\xff\xfe\x00\x00", "utf-32-le"), (b"\xfe\xff", "utf-16-be"),
        (b"\xff\xfe", "utf-16-le"), (b"\xef\xbb\xbf", "utf-8"))


def decode_yaml(data: bytes, where: str) -> str:
    """YAML bytes as text: UTF-8, or UTF-16/32 (either byte order), with or without a byte order mark.

    Without a BOM the encoding follows from the NUL bytes around the first character, which YAML
    requires to be ASCII (YAML 1.2 Section 5.2). Bytes that are not valid text in that encoding
    are refused, naming the line and byte.
    """
    skip, codec = next(((len(bom), codec) for bom, codec in BOMS if data.startswith(bom)), (0, None))
    if codec is None:
        head = data[:4]
        if len(head) == 4 and head[:3] == b"\x00\x00\x00" and head[3]:
            codec = "utf-32-be"
        elif len(head) == 4 and head[0] and head[1:] == b"\x00\x00\x00":
            codec = "utf-32-le"
        elif len(head) >= 2 and head[0] == 0 and head[1]:
            codec = "utf-16-be"
        elif len(head) >= 2 and head[0] and head[1] == 0:
            codec = "utf-16-le"
        else:
            codec = "utf-8"
    body = data[skip:]
    try:
        return body.decode(codec)
    except UnicodeDecodeError as exc:
        line = body[:exc.start].decode(codec, errors="replace").count("\n") + 1
        name = codec.upper().replace("-LE", " little-endian").replace("-BE", " big-endian")
        raise InputError(f"{where}:{line}", f"not a text file in {name} (byte {skip + exc.start}: {exc.reason}); "
                                            "save the config as UTF-8") from None


def _construct(loader: _Loader, node: yaml.Node, key_path: tuple, lines: dict, where: str, inside: tuple) -> Any:
    """Build Python data from a node tree, recording the line of every key and list item.

    ``inside`` holds the collection nodes enclosing ``node``: an alias to one of them (``a: &x [*x]``)
    would make the data contain itself, and is refused."""
    lines.setdefault(key_path, node.start_mark.line + 1)
    if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
        if any(node is outer for outer in inside):
            raise InputError(f"{where}:{node.start_mark.line + 1}", f"{_dotted(key_path) or 'top level'}: "
                                                                    "an alias refers to a collection that contains it")
        inside = inside + (node,)
    if isinstance(node, yaml.MappingNode):
        loader.flatten_mapping(node)
        out: dict[str, Any] = {}
        for key_node, value_node in node.value:
            key = _no_nul(loader.construct_object(key_node, deep=True), key_node, key_path, where)
            if not isinstance(key, str):
                raise InputError(f"{where}:{key_node.start_mark.line + 1}", f"{_dotted(key_path) or 'top level'}: keys must be text, got {key!r}")
            if key in out:
                raise InputError(f"{where}:{key_node.start_mark.line + 1}", f"{_dotted(key_path + (key,))}: duplicate key")
            lines[key_path + (key,)] = key_node.start_mark.line + 1
            out[key] = _construct(loader, value_node, key_path + (key,), lines, where, inside)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_construct(loader, item, key_path + (i,), lines, where, inside) for i, item in enumerate(node.value)]
    return _no_nul(loader.construct_object(node, deep=True), node, key_path, where)


def _no_nul(value: Any, node: yaml.Node, key_path: tuple, where: str) -> Any:
    """Refuse text holding a NUL character (written ``"\\0"`` in YAML): no path, unit or name
    can hold one, and the file system and HDF5 refuse it later with less clear errors."""
    if isinstance(value, str) and "\0" in value:
        raise InputError(f"{where}:{node.start_mark.line + 1}", f"{_dotted(key_path) or 'top level'}: "
                                                                "text holds a NUL character (\\0)")
    return value


def _dotted(key_path: tuple) -> str:
    """Render a key path as ``a.b[2].c``; a key that is empty or holds spaces, dots, brackets or
    unprintable characters is quoted: ``a['x y']``."""
    out = ""
    for part in key_path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif not part or not part.isprintable() or any(ch in part for ch in " .[]'\""):
            out += f"[{part!r}]"
        else:
            out += f".{part}" if out else part
    return out


def _line_of(lines: dict[tuple, int], key_path: tuple) -> int | None:
    for end in range(len(key_path), -1, -1):
        if key_path[:end] in lines:
            return lines[key_path[:end]]
    return None


def _message(error: dict) -> str:
    kind, ctx, value = error["type"], error.get("ctx", {}), error.get("input")
    comparisons = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<", "less_than_equal": "<="}
    if kind in comparisons:
        bound = next(iter(ctx.values()))
        return f"must be {comparisons[kind]} {bound}, got {value!r}"
    if kind == "missing":
        return "required key is missing"
    if kind == "extra_forbidden":
        return "unknown key"
    if kind in ("float_type", "int_type", "bool_type", "string_type", "list_type", "dict_type", "model_type", "int_from_float"):
        expected = {"float_type": "a number", "int_type": "an integer", "int_from_float": "an integer",
                    "bool_type": "true or false", "string_type": "text", "list_type": "a list",
                    "dict_type": "a mapping", "model_type": "a mapping"}[kind]
        return f"expected {expected}, got {value!r}"
    if kind == "literal_error":
        return f"expected {ctx.get('expected')}, got {value!r}"
    if kind in ("too_short", "too_long"):
        return f"expected {'at least' if kind == 'too_short' else 'at most'} " \
               f"{ctx.get('min_length', ctx.get('max_length'))} items, got {ctx.get('actual_length')}"
    if kind == "finite_number":  # written as YAML spells it
        spelled = ".nan" if value != value else ".inf" if value > 0 else "-.inf"
        return f"expected a finite number, got {spelled}"
    if kind == "value_error":
        return str(ctx.get("error", error["msg"]))
    return error["msg"]


def _untagged(loc: tuple, data: Any) -> tuple:
    """The error location without the discriminator values pydantic inserts for tagged unions
    (``model.lpl.branches`` -> ``model.branches``, ``model.poles[0].mode.frequency`` ->
    ``model.poles[0].frequency``): a part that is not a key of the mapping at hand but equals its
    ``type`` or has further parts after it (a missing key ends the location) is dropped, and so is
    a name at a list or a value (no name indexes them)."""
    out, node = [], data
    for i, part in enumerate(loc):
        if isinstance(node, dict) and part not in node and (node.get("type") == part or i < len(loc) - 1):
            continue
        if isinstance(part, str) and node is not None and not isinstance(node, dict):
            continue
        out.append(part)
        if isinstance(node, dict):
            node = node.get(part)
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            node = node[part]
        else:
            node = None
    return tuple(out)


def validate(data: Any, schema: Type[T], path: str | os.PathLike | None, lines: dict[tuple, int] | None = None) -> T:
    """Validate loaded data against ``schema`` (and its ``check()``, if any).

    Raises one :class:`InputError` naming the file, the line, the key path and what was expected
    (``path`` None: a config given as a dict, named by its key path alone).
    """
    if data is not None and not isinstance(data, dict):
        raise InputError("top level" if path is None else str(path),
                         f"{'' if path is None else 'top level: '}expected a mapping of keys, got {type(data).__name__}")
    try:
        config = schema.model_validate(data if data is not None else {})
        check = getattr(config, "check", None)
        if check is not None:
            check()
        return config
    except ValidationError as exc:
        errors = exc.errors()
        key_path, message = _untagged(tuple(errors[0]["loc"]), data), _message(errors[0])
        if len(errors) > 1:
            message += f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})"
    except ConfigValueError as exc:
        key_path, message = exc.key_path, exc.message
    raise config_error(path, lines, key_path, message)


def config_error(path: str | os.PathLike | None, lines: dict[tuple, int] | None, key_path: tuple, message: str) -> InputError:
    """The error of a config key found wrong after validation: ``file:line: a.b[2]: message``; for a
    config given as a dict (``path`` None) the key path is the place: ``a.b[2]: message``."""
    if path is None:
        return InputError(_dotted(tuple(key_path)) or "top level", message)
    line = _line_of(lines or {}, tuple(key_path))
    where = f"{path}:{line}" if line is not None else str(path)
    return InputError(where, f"{_dotted(tuple(key_path)) or 'top level'}: {message}")


def load_config(path: str | os.PathLike, schema: Type[T]) -> T:
    """Load a YAML config file and validate it against ``schema``."""
    data, lines = load_yaml(path)
    return validate(data, schema, path, lines)
