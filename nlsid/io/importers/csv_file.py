"""CSV and TSV tables (oscilloscope and logger exports): columns by header name or number.

Rules (``docs/drafts/import.md``):

- Lines that are empty or start with ``#`` are skipped.
- The delimiter is a tab for ``.tsv`` files; otherwise the first of tab, ``;`` and ``,`` found in the
  first row, else runs of whitespace.
- The first row is a header when any of its cells is not a number. A column is named by its header
  cell (exact text, else ignoring case) or by its number, counting from 1.
- Every row has as many cells as the first row; every selected cell is a number.
- Without ``--fs`` and ``--time``, a header column called ``t``, ``time`` or ``timestamp`` (ignoring
  case and a trailing unit such as ``time (s)``, ``Time [s]``) is the time vector, in seconds.
- Without ``--fs``, a header column called ``fs``, ``sample rate``, ``sampling rate`` or ``sampling
  frequency`` (ignoring case, ``_`` or ``-`` for the space, an optional unit ``(Hz)``, ``[kHz]``, ``(MHz)``)
  gives the sample rate: one value, repeated on every row or on some rows with the others empty. A
  rate that varies is refused; with a time vector as well, both rates must agree within 1e-3.
- Realizations side by side: when a signal's name (``u`` by default) is not a header cell, the
  numbered columns ``u1, u2, ...`` (also ``u_1``, ``u-1``, ``u.1``, ``u 1``, ``u(1)``, ``u[1]``) are its
  realizations, in the order of their numbers; a header cell repeated (``u, y, u, y``) gives one
  realization per occurrence, in column order. Every signal read must have the same realizations
  (the same numbers), else the file is refused with the columns listed. A default name (``u``, ``y``,
  ``r`` without ``--u/--y/--r``) that is a header cell *and* has numbered columns is ambiguous, and
  refused, when u is that name or has numbered columns; an explicit ``--u u`` takes the single column.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.io.importers.source import NotFound, Source, option, sample_rate, source_from
from nlsid.io.timestamps import REL_TOL

TIME_HEADER = re.compile(r"^\s*(t|time|timestamp)\s*([\[(].*[\])])?\s*$", re.IGNORECASE)
RATE_HEADER = re.compile(r"^\s*(?:fs|sampl(?:e|ing)[ _-]?rate|sampling[ _-]?frequency)\s*"
                         r"(?:[\[(]\s*(?P<unit>hz|khz|mhz)\s*[\])])?\s*$", re.IGNORECASE)
RATE_UNITS = {"hz": 1.0, "khz": 1e3, "mhz": 1e6}
UNIT_SUFFIX = r"(?:\s*[\[(][^\])]*[\])])?"  # a trailing unit, as in "u1 (V)"


def _number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None


def _delimiter(path: Path, first: str) -> str | None:
    if path.suffix.lower() == ".tsv":
        return "\t"
    return next((d for d in ("\t", ";", ",") if d in first), None)


def _rows(path: Path) -> list[tuple[int, list[str]]]:
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise InputError(str(path), f"not a text file ({exc.reason} at byte {exc.start})") from None
    numbered = [(i + 1, line) for i, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")]
    if not numbered:
        raise InputError(str(path), "holds no rows")
    delimiter = _delimiter(path, numbered[0][1])
    if delimiter is None:
        return [(n, line.split()) for n, line in numbered]
    parsed = csv.reader((line for _, line in numbered), delimiter=delimiter)
    return [(n, [c.strip() for c in cells]) for (n, _), cells in zip(numbered, parsed)]


def _column(header: list[str] | None, width: int, name: str, where: str) -> int:
    if header is not None:
        if name in header:
            return header.index(name)
        folded = [h.casefold() for h in header]
        if name.casefold() in folded:
            return folded.index(name.casefold())
    if name.isdigit() and 1 <= int(name) <= width:
        return int(name) - 1
    columns = f"columns are {', '.join(repr(h) for h in header)} or " if header else "columns are "
    raise NotFound(where, f"no column {name!r}; {columns}numbers 1..{width}")


def _numbered(header: list[str], name: str) -> list[tuple[int, int]]:
    """(number, column index) of the header cells that are ``name`` and a number (``u1``, ``u_1``,
    ``u(1)``, ...; ignoring case and a trailing unit). After a name ending in a digit the number
    needs a separator, so ``u1`` does not number ``u10``."""
    separator = r"[ _.\-]" if name[-1:].isdigit() else r"[ _.\-]?"
    pattern = re.compile(rf"^\s*{re.escape(name)}(?:{separator}(\d+)|\s*[\[(]\s*(\d+)\s*[\])]){UNIT_SUFFIX}\s*$",
                         re.IGNORECASE)
    found = []
    for index, cell in enumerate(header):
        match = pattern.match(cell)
        if match:
            found.append((int(match.group(1) or match.group(2)), index))
    return sorted(found)


def _columns(header: list[str] | None, width: int, name: str, where: str) -> tuple[list[int], list[int] | None, list[int]]:
    """The column(s) of one signal, for numbered columns their numbers, and the numbered columns
    passed over for a column named exactly ``name`` (whether that is ambiguous is decided by the caller).

    One column: the header cell ``name`` (exact, else ignoring case), else column number ``name``.
    Several (realizations side by side): ``name`` repeated in the header, or, when it is not a header
    cell, the numbered columns ``name1, name2, ...``.
    """
    if header is not None:
        exact = [i for i, h in enumerate(header) if h == name] or \
                [i for i, h in enumerate(header) if h.casefold() == name.casefold()]
        numbered = [] if name.isdigit() else _numbered(header, name)
        if exact:
            return exact, None, [i for _, i in numbered] if len(exact) == 1 else []
        if numbered:
            numbers = [n for n, _ in numbered]
            for (n, i), (m, j) in zip(numbered, numbered[1:]):
                if n == m:
                    raise InputError(where, f"columns {header[i]!r} and {header[j]!r} both have number {n}")
            return [i for _, i in numbered], numbers, []
    if name.isdigit() and 1 <= int(name) <= width:
        return [int(name) - 1], None, []
    columns = f"columns are {', '.join(repr(h) for h in header)} or " if header else "columns are "
    raise NotFound(where, f"no column {name!r}; {columns}numbers 1..{width}")


def _check_ambiguous(path: Path, header: list[str] | None, names: dict[str, str], chosen: dict, passed_over: dict,
                     defaulted: frozenset[str]) -> None:
    """Refuse a default name that is a column *and* has numbered columns (``u, u2, u3``) when the
    numbered reading would give realizations: the input u has numbered columns, or is that name. An
    explicit ``--u u`` takes the one column; ``t, u, y, y2`` (one input, a second sensor) is no
    question: y is the column y."""
    u_numbered = passed_over.get("u") or ("u" in chosen and chosen["u"][1] is not None)
    for key, others in passed_over.items():
        if others and key in defaulted and (key == "u" or u_numbered):
            column = header[chosen[key][0][0]]
            listed = ", ".join(repr(header[i]) for i in others)
            raise InputError(f"{path}: --{key} {names[key]}", f"ambiguous: a column {column!r} and the numbered columns "
                                                              f"{listed}; pass --{key} {column} for the one column, or "
                                                              "rename it to import the numbered ones as realizations")


def _paired(path: Path, header: list[str] | None, chosen: dict[str, tuple[list[int], list[int] | None]]) -> int:
    """The number of realizations the chosen columns hold; refuse columns that do not pair up."""
    counts = {len(indices) for indices, _ in chosen.values()}
    numbers = {tuple(numbered) for _, numbered in chosen.values() if numbered is not None}
    kinds = {numbered is None for _, numbered in chosen.values()}  # repeated (or single) / numbered
    if len(counts) == 1 and len(numbers) <= 1 and (counts == {1} or len(kinds) == 1):
        return counts.pop()
    listed = "; ".join(f"{key}: {', '.join(repr(header[i]) for i in indices)}" for key, (indices, _) in chosen.items())
    raise InputError(str(path), f"the signal columns do not pair into realizations ({listed}): each realization "
                                "needs one column of every signal, numbered alike (u1, y1, u2, y2, ...); "
                                "name the columns with --u/--y/--r")


def read_csv(path: Path, names: dict[str, str], time: str | None, optional: set[str], fs_given: bool,
             defaulted: frozenset[str] = frozenset()) -> Source:
    """Read the selected columns (signal -> column), the time column and the sample-rate column of a
    CSV/TSV table. ``defaulted``: the signals whose names were not given (``u``, ``y``, ``r``).

    Several columns of one signal (realizations side by side) give a (realizations, samples) matrix,
    which :func:`nlsid.io.importers.source.records_of` cuts into one record per realization.
    """
    rows = _rows(path)
    first_line, first = rows[0]
    header = first if any(_number(c) is None for c in first) else None
    body = rows[1:] if header is not None else rows
    width = len(first)
    for line, cells in body:
        if len(cells) != width:
            raise InputError(f"{path}:{line}", f"row has {len(cells)} cells, the {'header' if header else 'first row'} "
                                               f"(line {first_line}) has {width}")
    if not body:
        raise InputError(str(path), "holds a header but no data rows")
    if time is None and not fs_given and header is not None:
        time = next((h for h in header if TIME_HEADER.match(h)), None)
    rate_index = None if fs_given or header is None else next((i for i, h in enumerate(header) if RATE_HEADER.match(h)), None)
    chosen: dict[str, tuple[list[int], list[int] | None]] = {}
    passed_over: dict[str, list[int]] = {}
    for key, name in names.items():
        try:
            indices, numbers, passed_over[key] = _columns(header, width, name, f"{path}: {option(key, name)}")
        except NotFound:
            if key not in optional:
                raise
            continue
        chosen[key] = indices, numbers
    _check_ambiguous(path, header, names, chosen, passed_over, defaulted)
    realizations = _paired(path, header, chosen)
    if realizations > len(body):
        raise InputError(str(path), f"{realizations} realizations side by side but only {len(body)} row(s) of samples")

    def title(index: int) -> str:
        return header[index] if header else str(index + 1)

    values = {key: _parse(path, body, indices[0], title(indices[0])) if realizations == 1 else
              np.vstack([_parse(path, body, i, title(i)) for i in indices]) for key, (indices, _) in chosen.items()}
    labels = {key: names[key] if realizations == 1 else _label([title(i) for i in indices], name=names[key])
              for key, (indices, _) in chosen.items()}
    columns = {key: names[key] if realizations == 1 else [title(i) for i in indices] for key, (indices, _) in chosen.items()}
    if time:
        index = _column(header, width, time, f"{path}: --time {time}")
        values["time"], labels["time"], columns["time"] = _parse(path, body, index, title(index)), time, time
    details: dict = {"columns": columns, "header": header is not None}
    if realizations > 1:
        details["realizations"] = realizations
    source = source_from(path, "csv", labels, values, details)
    if rate_index is not None:
        _apply_rate_column(source, path, body, rate_index, header[rate_index])
    return source


def _label(titles: list[str], name: str) -> str:
    """How a set of realization columns is named in messages: ``u1..u10`` or ``u (columns 2, 4, 6)``."""
    if len(set(titles)) == len(titles):
        return f"{titles[0]}..{titles[-1]}"
    return f"{name} (columns {len(titles)})"


def _apply_rate_column(source: Source, path: Path, body: list[tuple[int, list[str]]], index: int, title: str) -> None:
    """Set the source's sample rate from a sample-rate column (one value; empty cells allowed)."""
    unit = RATE_HEADER.match(title).group("unit")
    scale = RATE_UNITS[unit.lower()] if unit else 1.0
    first: tuple[float, int] | None = None
    for line, cells in body:
        cell = cells[index]
        if not cell:
            continue
        value = _number(cell)
        if value is None or not np.isfinite(value) or value <= 0:
            raise InputError(f"{path}:{line}", f"column {title!r}: cell {cell[:40]!r} is not a sample rate "
                                               f"(a number > 0, in {unit or 'Hz'})")
        if first is None:
            first = (value, line)
        elif value != first[0]:
            raise InputError(f"{path}:{title}", f"the sample rate varies: {first[0]:.9g} on line {first[1]}, "
                                                f"{value:.9g} on line {line}; a file holds one rate (split the file, "
                                                "or pass --fs HZ)")
    if first is None:
        raise InputError(f"{path}:{title}", "the sample-rate column holds no value")
    fs = first[0] * scale
    source.fs, source.fs_from = fs, f"sample-rate column {path}:{title}"
    source.details["sample_rate_column"] = title
    if source.time is not None:
        from_time = sample_rate(source.time, source.time_where)
        if abs(from_time / fs - 1) > REL_TOL:
            raise InputError(str(path), f"the sample-rate column {title!r} says {fs:.9g} Hz but the time vector "
                                        f"{source.time_where} gives {from_time:.9g} Hz "
                                        f"(they must agree within {REL_TOL:g}); pass --fs HZ to choose")
        source.details["time_vector_fs"] = from_time


def _parse(path: Path, body: list[tuple[int, list[str]]], index: int, title: str) -> np.ndarray:
    out = np.empty(len(body))
    for i, (line, cells) in enumerate(body):
        value = _number(cells[index])
        if value is None:
            raise InputError(f"{path}:{line}", f"column {title!r}: cell {cells[index][:40]!r} is not a number")
        out[i] = value
    return out
