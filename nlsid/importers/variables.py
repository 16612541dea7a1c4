"""The variables of a MAT or HDF5 file around the imported ones.

- ``NAME[i]`` names record ``i`` (from 0) of a matrix variable: the slice across the axis along
  which time runs (the longer one, as :func:`nlsid.importers.source.as_matrix` decides), so row
  1 of a 3 x N ``Acceleration`` is ``Acceleration[1]``, and column 1 of an N x 3 one too.
- A channel given a matrix of several records, beside u, y, r of one record each, becomes one
  channel per record, ``NAME_0``, ``NAME_1``, ... (:func:`matrix_channels`).
- Signals whose matrices differ in shape do not pair into records: they are refused with the
  ``NAME[i]`` options that pick one record (:func:`check_pairing`); a matrix as u, y or r beside
  signals of another shape would be several inputs or outputs: u or y and channels, named with
  ``--inputs``/``--outputs``.
- Every other variable of the file is surveyed (:func:`survey`): one named as a sample rate or
  interval (:data:`nlsid.importers.source.RATE_NAME`, ``INTERVAL_NAME``) is a rate variable of
  the source; numeric scalars are kept to be listed when no sample rate is found; the rest, and the
  records of an indexed matrix that were not picked, go to ``details["ignored_variables"]``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from nlsid.errors import InputError
from nlsid.importers.source import INTERVAL_NAME, RATE_NAME, RateVariable, Source, option, time_axis
from nlsid.io.run import CHANNEL_KEY, check_channel_name

INDEXED = re.compile(r"^(?P<base>.+)\[(?P<index>\d+)\]$")
LISTED_IGNORED = 500  # a logger file can hold thousands of datasets: the rest are counted
LISTED_RECORDS = 3  # records named in the hint of a refused matrix


def split_index(name: str) -> tuple[str, int | None]:
    """``Acceleration[1]`` -> (``Acceleration``, 1); a name without an index -> (name, None)."""
    match = INDEXED.match(name)
    if match is None:
        return name, None
    return match.group("base"), int(match.group("index"))


def shape_text(dims: tuple[int, ...]) -> str:
    """``3x1000``; ``scalar`` for a single value."""
    return "scalar" if int(np.prod(dims)) == 1 else "x".join(map(str, dims))


def record_of(value: np.ndarray, index: int, name: str, where: str) -> np.ndarray:
    """Record ``index`` of the vector or matrix ``value`` of variable ``name`` (a vector is record 0)."""
    arr = np.asarray(value)
    squeezed = np.squeeze(arr)
    if squeezed.ndim > 2:
        raise InputError(where, f"{name} has shape {shape_text(arr.shape)}; NAME[i] picks a record of a vector or "
                                "a 2-D matrix")
    matrix = squeezed.reshape(1, -1) if squeezed.ndim < 2 else squeezed
    axis = time_axis(matrix.shape)
    records, samples = matrix.shape[1 - axis], matrix.shape[axis]
    if index >= records:
        raise InputError(where, f"{name} is {shape_text(arr.shape)} ({records} record(s) of {samples} samples; time "
                                f"runs along the longer axis): index {index} is out of range, valid 0..{records - 1}")
    return np.take(matrix, index, axis=1 - axis)


def _records_samples(dims: tuple[int, ...]) -> tuple[int, int] | None:
    """(records, samples) of an array of shape ``dims`` as as_matrix cuts it (None: not 1-D or 2-D)."""
    kept = tuple(d for d in dims if d != 1)
    if len(kept) <= 1:
        return 1, int(np.prod(dims))
    if len(kept) == 2:
        axis = time_axis(kept)
        return kept[1 - axis], kept[axis]
    return None  # as_matrix says what is wrong with it


Split = tuple[dict[str, str], dict[str, np.ndarray], dict[str, list[str]], list[str]]


def matrix_channels(names: dict[str, str], values: dict[str, np.ndarray], where: Callable[[str, str], str]) -> Split:
    """A channel given a matrix of several records, beside u, y, r of one record each, as one
    channel per record: ``--channel acc=Acceleration`` of a 3 x N ``Acceleration`` gives the
    channels ``acc_0``, ``acc_1``, ``acc_2`` (record ``i`` as ``Acceleration[i]`` picks it).

    Where u, y or r hold several records (realizations side by side), a channel of their shape
    stays their records, and one of another shape is left to :func:`check_pairing`, which refuses
    it. Returns the names and values with each such channel replaced by its records, the channels
    split (name -> the names of its records' channels), and one note per channel split. A record's
    channel name must be free: a ``--channel acc_1=...`` beside it is refused. ``where(key, name)``
    names the option for messages.
    """
    signals = [_records_samples(np.shape(values[key])) for key in values if key in ("u", "y", "r")]
    if any(shape is None or shape[0] > 1 for shape in signals):
        return names, values, {}, []
    names, values, split, notes = dict(names), dict(values), {}, []
    for key in [k for k in values if k.startswith(CHANNEL_KEY)]:
        shape = _records_samples(np.shape(values[key]))
        if shape is None or shape[0] == 1 or split_index(names[key])[1] is not None:
            continue
        records, samples = shape
        channel, source = key[len(CHANNEL_KEY):], names[key]
        parts = [f"{channel}_{i}" for i in range(records)]
        for part in parts:
            check_channel_name(part, where(key, source))
            if CHANNEL_KEY + part in names:
                raise InputError(where(key, source), f"{source} is {shape_text(np.shape(values[key]))} ({records} "
                                                     f"records of {samples} samples), imported as the channels "
                                                     f"{parts[0]} .. {parts[-1]}, but a channel {part} is given too; "
                                                     f"rename one of them")
        matrix = values.pop(key)
        del names[key]
        split[channel] = parts
        for i, part in enumerate(parts):
            names[CHANNEL_KEY + part] = f"{source}[{i}]"
            values[CHANNEL_KEY + part] = record_of(matrix, i, source, where(key, source))
        notes.append(f"{where(key, source)}: {source} is {shape_text(np.shape(matrix))}, {records} records of "
                     f"{samples} samples (time along the longer axis): imported as {records} channels "
                     f"{', '.join(f'{part} = {source}[{i}]' for i, part in enumerate(parts))}")
    return names, values, split, notes


def check_pairing(path: Path, names: dict[str, str], values: dict[str, np.ndarray]) -> None:
    """Refuse signals that are matrices of several records unless every signal has the same shape
    (records side by side); say how to pick one record of each matrix with ``NAME[i]``, or to
    import it as channels. A matrix given as u, y or r beside signals of another shape would be
    several inputs or outputs (MIMO): one record as u or y, the others as channels listed with
    ``--inputs``/``--outputs``."""
    shapes = {}
    for key, value in values.items():
        if key == "time":
            continue
        shape = _records_samples(np.shape(value))
        if shape is None:
            return
        shapes[key] = shape
    if len(set(shapes.values())) <= 1 or all(records == 1 for records, _ in shapes.values()):
        return
    detail = ", ".join(f"{path}:{names[key]} is {samples} samples x {records} record(s)"
                       for key, (records, samples) in shapes.items())
    # every record as a channel is a way out where the other signals hold one record each
    single = {key: all(shapes[k][0] == 1 for k in ("u", "y", "r") if k in shapes and k != key) for key in shapes}
    hints = [_pick_hint(key, names[key], records, single[key]) for key, (records, _) in shapes.items() if records > 1]
    mimo = [option(key, names[key]) for key, (records, _) in shapes.items() if records > 1 and key in ("u", "y", "r")]
    why = (f"{' and '.join(mimo)}: several inputs or outputs (MIMO) are u or y and channels, listed with "
           "--inputs u,NAME,... or --outputs y,NAME,...; " if mimo else "")
    raise InputError(str(path), f"matrices of inconsistent size: {detail}; {why}name one record (from 0, across the "
                                f"shorter axis) of a matrix: {'; '.join(hints)}")


def _pick_hint(key: str, name: str, records: int, as_channels: bool) -> str:
    leaf = re.sub(r"\W", "_", re.split(r"[./]", name)[-1]) or "c"
    leaf = leaf if not leaf[0].isdigit() else f"c{leaf}"
    others = " ".join(f"--channel {leaf}_{i}={name}[{i}]" for i in range(1, min(records, LISTED_RECORDS + 1)))
    more = " ..." if records > LISTED_RECORDS + 1 else ""
    whole = (f"; or all of them as channels {leaf}_0 .. {leaf}_{records - 1}: --channel {leaf}={name}"
             if as_channels else "")
    return f"{option(key, f'{name}[0]')} (records 0..{records - 1}; the others as channels: {others}{more}{whole})"


@dataclass(frozen=True)
class Leaf:
    """A variable (or struct field, or dataset) of the file: ``name`` as the user names it, ``scope``
    the struct or group holding it ("" at the top), ``dims`` its shape when it holds numbers (else
    None, and ``kind`` says what it is), ``values`` reads them."""

    name: str
    scope: str
    kind: str
    dims: tuple[int, ...] | None = None
    values: Callable[[], np.ndarray] | None = None

    @property
    def description(self) -> str:
        if self.dims is None:
            return self.kind
        return shape_text(self.dims) if self.kind == "real" else f"{shape_text(self.dims)} {self.kind}"


def survey(source: Source, noun: str, leaves: list[Leaf], used: dict[str, str], scope_of: Callable[[str], str]) -> None:
    """Fill the source's rate variables, scalars and ``details["ignored_variables"]`` from the file's
    ``leaves``, given the ``used`` names (signal or ``time`` -> name, with ``[i]`` when indexed).
    ``noun`` names a leaf in messages (``variable``, ``dataset``); ``scope_of(name)`` is its struct or group.

    Rate variables are looked for next to the imported signals (in their structs or groups), then
    at the top level, then anywhere in the file: the first place that has any gives them all.
    """
    by_name = {leaf.name: leaf for leaf in leaves}
    bases: dict[str, set[int]] = {}
    for name in used.values():
        base, index = (name, None) if name in by_name else split_index(name)
        bases.setdefault(base, set())
        if index is not None:
            bases[base].add(index)
    scopes = {scope_of(base) for base in bases}
    rated = [leaf for leaf in leaves if leaf.name not in bases and _is_rate_name(leaf.name)]
    chosen = [leaf for leaf in rated if leaf.scope in scopes] or [leaf for leaf in rated if not leaf.scope] or rated
    rate_names = {leaf.name for leaf in chosen}
    source.rate_variables = [RateVariable(leaf.name, f"{noun} {leaf.name} of {source.path}",
                                          leaf.values() if leaf.values else np.asarray(leaf.kind)) for leaf in chosen]
    if chosen:
        source.details["rate_variables"] = {leaf.name: _stored(leaf) for leaf in chosen}
    ignored: dict[str, str] = {}
    for leaf in leaves:
        if leaf.name in bases or leaf.name in rate_names:
            continue
        ignored[leaf.name] = leaf.description
        if leaf.values is not None and leaf.dims is not None and int(np.prod(leaf.dims)) == 1 and leaf.kind == "real":
            source.scalars[leaf.name] = float(np.asarray(leaf.values()).ravel()[0])
            ignored[leaf.name] = f"scalar {source.scalars[leaf.name]:.9g}"
    for base, indices in bases.items():
        leaf = by_name.get(base)
        if not indices or leaf is None or leaf.dims is None:
            continue
        shape = _records_samples(leaf.dims)
        if shape is None:
            continue
        for i in range(shape[0]):
            if i not in indices:
                ignored[f"{base}[{i}]"] = f"{shape[1]} samples (record {i} of {base}, {shape_text(leaf.dims)})"
    if ignored:
        names = list(ignored)
        source.details["ignored_variables"] = {name: ignored[name] for name in names[:LISTED_IGNORED]}
        if len(names) > LISTED_IGNORED:
            source.details["ignored_variables_not_listed"] = len(names) - LISTED_IGNORED


def _is_rate_name(name: str) -> bool:
    leaf = re.split(r"[./]", name)[-1]
    return bool(RATE_NAME.match(leaf) or INTERVAL_NAME.match(leaf))


def _stored(leaf: Leaf) -> float | str:
    """A rate variable as provenance keeps it: its value when it is one real number, else what it is."""
    if leaf.values is not None and leaf.kind == "real" and leaf.dims is not None and int(np.prod(leaf.dims)) == 1:
        value = float(np.asarray(leaf.values()).ravel()[0])
        if np.isfinite(value):
            return value
    return leaf.description
