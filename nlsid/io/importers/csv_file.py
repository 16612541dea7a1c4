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
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.io.importers.source import NotFound, Source, pick, source_from

TIME_HEADER = re.compile(r"^\s*(t|time|timestamp)\s*([\[(].*[\])])?\s*$", re.IGNORECASE)


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


def read_csv(path: Path, names: dict[str, str], time: str | None, optional: set[str], fs_given: bool) -> Source:
    """Read the selected columns (signal -> column) and the time column of a CSV/TSV table."""
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
    wanted = dict(names, **({"time": time} if time else {}))

    def read(key: str, name: str) -> np.ndarray:
        index = _column(header, width, name, f"{path}: --{key} {name}")
        return _parse(path, body, index, header[index] if header else str(index + 1))

    values = pick(wanted, optional, read)
    return source_from(path, "csv", wanted, values, {"columns": {k: wanted[k] for k in values}, "header": header is not None})


def _parse(path: Path, body: list[tuple[int, list[str]]], index: int, title: str) -> np.ndarray:
    out = np.empty(len(body))
    for i, (line, cells) in enumerate(body):
        value = _number(cells[index])
        if value is None:
            raise InputError(f"{path}:{line}", f"column {title!r}: cell {cells[index][:40]!r} is not a number")
        out[i] = value
    return out
