"""CSV and TSV tables (oscilloscope and logger exports): columns by header name or number.

Rules (``docs/commands.md``, "nlsid import"):

- Lines that are empty or start with ``#`` are skipped.
- The delimiter is a tab for ``.tsv`` files; otherwise the first of tab, ``;`` and ``,`` found on
  more than half of the lines, else runs of whitespace.
- Preamble: lines above the header that are not part of the table (``Axis1``, ``Date: ...``) are
  found and skipped when the first row of numbers has the width of most rows and the line above it
  is a header of that width without numbers; ``skip_rows`` (``--skip-rows N``) skips the first N
  lines of the file instead, and the next line is the header or the first row.
- The first row is a header when any of its non-empty cells is not a number. A header cell is a
  name with an optional unit: ``u (N)``, ``y [m/s^2]``. A column is named by its header cell
  (exact, else ignoring case), by the name without its unit (exact, else ignoring case), or by its
  number, counting from 1.
- Group labels: a header cell followed by empty header cells labels all those columns (as long as
  they hold data): ``u`` over 10 columns names 10 realizations of u, like ``u1..u10``. Columns with
  an empty header cell and no label to their left are not read (and listed as ignored).
- Every row below the header has as many cells as the header; every selected cell is a number. A
  header with fewer cells than every row below it is padded with empty cells when the cells beyond
  it are all empty (a delimiter ending each row), and refused when some hold a number (it may name
  the first columns or the last: :func:`_short_header`).
- Without ``--fs`` and ``--time``, a header column called ``t``, ``time`` or ``timestamp`` (ignoring
  case) is the time vector, in seconds unless its unit says ``ms``, ``us``/``µs``, ``ns`` or ``min``.
- Without ``--fs``, a header column called ``fs``, ``sample rate``, ``sampling rate`` or ``sampling
  frequency`` (ignoring case, ``_`` or ``-`` for the space, an optional unit ``(Hz)``, ``[kHz]``, ``(MHz)``)
  gives the sample rate, and a column ``Ts``, ``dt``, ``sample interval`` or ``sampling interval``
  (unit as a time column's) the sampling interval: one value, repeated on every row or on some rows
  with the others empty. A value that varies is refused; several such columns and a time vector
  must agree within 1e-3.
- Realizations side by side: when a signal's name (``u`` by default) is not a header cell, the
  numbered columns ``u1, u2, ...`` (also ``u_1``, ``u-1``, ``u.1``, ``u 1``, ``u(1)``, ``u[1]``) are its
  realizations, in the order of their numbers; a header cell repeated (``u, y, u, y``) gives one
  realization per occurrence, in column order. Every signal read must have the same realizations
  (the same numbers), else the file is refused with the columns listed. A default name (``u``, ``y``,
  ``r`` without ``--u/--y/--r``) that is a header cell *and* has numbered columns is ambiguous, and
  refused, when u is that name or has numbered columns; an explicit ``--u u`` takes the single column.
- No column is dropped silently: the columns not read are listed in ``details["ignored_columns"]``.
"""

from __future__ import annotations

import csv
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from nlsid.errors import InputError
from nlsid.importers.source import NotFound, Source, option, sample_rate, source_from
from nlsid.io.timestamps import REL_TOL

TIME_NAMES = ("t", "time", "timestamp")
RATE_NAME = re.compile(r"^(?:fs|sampl(?:e|ing)[ _-]?rate|sampling[ _-]?frequency)$", re.IGNORECASE)
INTERVAL_NAME = re.compile(r"^(?:ts|dt|sampl(?:e|ing)[ _-]?interval)$", re.IGNORECASE)
RATE_UNITS = {"hz": 1.0, "khz": 1e3, "mhz": 1e6}
TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "\u00b5s": 1e-6, "\u03bcs": 1e-6, "ns": 1e-9, "min": 60.0}
TIME_UNITS_TEXT = "s, ms, us (µs), ns, min"
# A name followed by a unit in brackets: "u (N)", "y [m/s^2]". A bracketed whole number is not a
# unit but a realization number ("u(1)"), so it stays part of the name.
UNIT_CELL = re.compile(r"^(?P<name>.*?\S)\s*[\[(]\s*(?P<unit>[^\[\]()]*?)\s*[\])]$")
UNIT_SUFFIX = r"(?:\s*[\[(][^\])]*[\])])?"  # a trailing unit, as in "u1 (V)"
UNITS_ROW_CELL = re.compile(r"^[\[(][^\[\]()]*[^\[\]()\d\s][^\[\]()]*[\])]$")  # "(ms)", "[V]"; not "(1)"
DELIMITERS = ("\t", ";", ",")
PREVIEW = 80  # characters of a preamble line kept in the details
HEAD_LINES = 200  # lines read cell by cell to find where a table of numbers starts
# Line ends of str.splitlines that a file read in text mode (numpy.loadtxt) does not end a line at
SPLITLINES_ONLY = "\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"


def split_unit(cell: str) -> tuple[str, str | None]:
    """``"u (N)"`` -> ``("u", "N")``; a cell without a unit -> ``(cell, None)``."""
    match = UNIT_CELL.match(cell.strip())
    if match is None or not match.group("unit") or match.group("unit").isdigit():
        return cell.strip(), None
    return match.group("name"), match.group("unit")


def _number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None


def _delimiter_text(delimiter: str | None) -> str:
    return {"\t": "tab", None: "whitespace", "": "nothing (one column)"}.get(delimiter, repr(delimiter))


@dataclass
class Table:
    """The rows of a CSV/TSV file: its header (cells, or None), the rows below it (line number,
    cells), the delimiter (None: whitespace, "": none, one column), the lines above the header
    that were skipped (line number, text), and the line of the units row read into the header.
    ``numbers``: the rows as a (rows, width) matrix when every cell of every row is a number (read
    in one pass, :func:`_numeric_table`); None when some cell is not (then the columns are parsed
    cell by cell, and a cell that is not a number is named)."""

    header: list[str] | None
    body: Sequence[tuple[int, list[str]]]
    delimiter: str | None
    preamble: list[tuple[int, str]]
    units_line: int | None = None
    numbers: np.ndarray | None = None

    @property
    def width(self) -> int:
        return len(self.header) if self.header is not None else len(self.body[0][1])


class NumericRows(Sequence):
    """The rows of a numeric body as (line number, cells), split from the file's text only when one
    is looked at (a message naming a cell): its numbers are in :attr:`Table.numbers`. ``start``,
    ``stop``: the indices of its first line and of the line after its last."""

    def __init__(self, text: str, start: int, stop: int, delimiter: str | None):
        self._text, self._start, self._stop, self._delimiter = text, start, stop, delimiter
        self._lines: list[str] | None = None

    def __len__(self) -> int:
        return self._stop - self._start

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        if not -len(self) <= index < len(self):
            raise IndexError(index)
        if self._lines is None:
            self._lines = self._text.splitlines()
        k = self._start + index % len(self)
        return k + 1, _split(self._lines[k], self._delimiter)


def _text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(str(path), f"not a text file ({exc.reason} at byte {exc.start})") from None


def _head(text: str, count: int) -> list[str]:
    """The first ``count`` lines of ``text`` (all when it has fewer), with their line ends."""
    size = 1 << 16
    while True:
        lines = text[:size].splitlines(keepends=True)
        if size >= len(text):
            return lines[:count]
        if len(lines) > count:  # the last line of the slice may be cut: it is not among them
            return lines[:count]
        size *= 4


def _content_lines(text: str) -> int:
    """The number of lines of ``text`` up to its last that is not blank (a file read in text mode:
    its line ends are ``\\n``, ``\\r\\n`` and ``\\r`` read as ``\\n``)."""
    end = len(text)
    while end and text[end - 1].isspace():
        end -= 1
    return text.count("\n", 0, end) + 1


def _choose_delimiter(path: Path, lines: list[str]) -> str | None:
    """Tab for ``.tsv``; else the first of tab, ``;``, ``,`` on more than half of the lines (the rows
    of the table, not a preamble line), else None (whitespace) when more than half of the lines
    hold whitespace between cells, else ``""``: one column, a line is a cell (``Voltage (V)``)."""
    if path.suffix.lower() == ".tsv":
        return "\t"
    return _delimiter_of(lambda d: sum(d in line for line in lines),
                         lambda: sum(len(line.split(None, 1)) > 1 for line in lines), len(lines))


def _delimiter_of(holding: Callable[[str], int], spaced: Callable[[], int], total: int) -> str | None:
    """The rule of :func:`_choose_delimiter` on counts: of ``total`` lines, ``holding(d)`` hold the
    delimiter d and ``spaced()`` hold whitespace between cells."""
    found = next((d for d in DELIMITERS if 2 * holding(d) > total), None)
    if found is None and 2 * spaced() <= total:
        return ""
    return found


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    if not delimiter:
        return [line.strip()]
    if '"' in line:  # quoted cells: one line is one row, a quote never joins lines
        return [c.strip() for c in next(csv.reader([line], delimiter=delimiter))]
    cells = line.split(delimiter)
    return [c.strip() for c in cells] if " " in line or "\t" in line else cells


def _is_numbers(cells: list[str]) -> bool:
    """A row of data: every non-empty cell a number, and at least one."""
    filled = [c for c in cells if c]
    return bool(filled) and all(_number(c) is not None for c in filled)


def _is_units_row(cells: list[str]) -> bool:
    """A row of units under the header: every non-empty cell a bracketed unit, ``(ms)``, ``[V]``."""
    filled = [c for c in cells if c]
    return bool(filled) and all(UNITS_ROW_CELL.match(c) for c in filled)


def _header_index(path: Path, rows: list[tuple[int, list[str]]], delimiter: str | None) -> int:
    """Where the table starts: the line above the first row of data of the common width (above its
    units row, if it has one), when that line is a header of the same width without numbers (or a
    shorter one, over a row whose cells beyond it are empty: a delimiter ending each row); else 0
    (the first line). A row of data is one of numbers (empty cells allowed), or, when no row is,
    one with a number (a text column beside the numbers). Two header-like lines above the data are
    refused as ambiguous."""
    widths = Counter(len(cells) for _, cells in rows)
    width = widths.most_common(1)[0][0]
    same = [k for k, (_, cells) in enumerate(rows) if len(cells) == width]
    first = next((k for k in same if _is_numbers(rows[k][1])), None)
    if first is None:
        first = next((k for k in same if any(_number(c) is not None for c in rows[k][1])), None)
    if first is None:
        return 0
    top = first - 1
    if top >= 1 and len(rows[top][1]) == width and _is_units_row(rows[top][1]):
        top -= 1
    if top < 1:
        return 0
    above, data = rows[top][1], rows[first][1]
    if (len(above) > width or any(data[len(above):])) or any(_number(c) is not None for c in above):
        return 0
    higher = rows[top - 1][1]  # a line of the rows' width: preamble lines are often one cell, as a short header
    if len(higher) == width and not any(_number(c) is not None for c in higher):
        raise InputError(f"{path}:{rows[top - 1][0]}", f"lines {rows[top - 1][0]} and {rows[top][0]} both look like the "
                                                       f"header ({width} cells split at {_delimiter_text(delimiter)}, no "
                                                       "numbers); pass --skip-rows N so that the header is the first "
                                                       "line read")
    return top


def _with_units(header: list[str], units: list[str]) -> list[str]:
    """Header cells with the units of the row below them: ``Time`` over ``(ms)`` is ``Time (ms)``
    (a cell that states its own unit keeps it)."""
    return [f"{cell} {unit}" if cell and unit and split_unit(cell)[1] is None else cell
            for cell, unit in zip(header, units)]


@dataclass(frozen=True)
class Start:
    """Where a table starts among its rows: the header's row ``top`` (the preamble is above it), the
    header cells (None: the first row is data; a units row's units joined in), the index of the
    first row of the body, and the line of the units row (None: there is none)."""

    top: int
    header: list[str] | None
    body: int
    units_line: int | None


def _table_lines(lines: list[str], first: int, stop: int) -> list[tuple[int, str]]:
    """(line number, text) of the lines ``first..stop-1`` that are neither empty nor a ``#`` comment."""
    return [(i + 1, line) for i, line in enumerate(lines[first:stop], start=first)
            if line.strip() and not line.lstrip().startswith("#")]


def _start(path: Path, rows: list[tuple[int, list[str]]], delimiter: str | None, skip_rows: int | None) -> Start:
    """The header (found above the first rows of numbers unless ``skip_rows`` says where it is), its
    units row, and where the body starts."""
    top = 0 if skip_rows is not None else _header_index(path, rows, delimiter)
    first = rows[top][1]
    header = None if _is_numbers(first) else first
    body = top + 1 if header is not None else top
    units_line = None
    if header is not None and body < len(rows) and len(rows[body][1]) == len(header) and _is_units_row(rows[body][1]):
        units_line, header = rows[body][0], _with_units(header, rows[body][1])
        body += 1
    return Start(top, header, body, units_line)


def read_table(path: Path, skip_rows: int | None = None) -> Table:
    """Split ``path`` into header, rows and preamble; check that every row has the header's width.

    A body of numbers only is read in one pass (:func:`_numeric_table`); any other is read cell by
    cell, and the first row or cell that does not fit is named."""
    text = _text(path)
    numeric = _numeric_table(path, text, skip_rows)
    if numeric is not None:
        return numeric
    lines = text.splitlines()
    if skip_rows is not None and skip_rows >= len(lines):
        raise InputError(f"--skip-rows {skip_rows}", f"{path} has only {len(lines)} line(s)")
    numbered = _table_lines(lines, skip_rows or 0, len(lines))
    if not numbered:
        raise InputError(str(path), "holds no rows" + (f" below the {skip_rows} line(s) skipped" if skip_rows else ""))
    delimiter = _choose_delimiter(path, [line for _, line in numbered])
    rows = [(n, _split(line, delimiter)) for n, line in numbered]
    start = _start(path, rows, delimiter, skip_rows)
    body = rows[start.body:]
    if not body:
        raise InputError(str(path), "holds a header but no data rows")
    first_line, first = rows[start.top]
    header = start.header if start.header is None else _short_header(path, start.header, first_line, body, delimiter)
    width = len(header) if header is not None else len(first)
    for line, cells in body:
        if len(cells) != width:
            hint = ("; if lines above the header are not part of the table, pass --skip-rows N"
                    if line == body[0][0] else "")
            raise InputError(f"{path}:{line}", f"row has {len(cells)} cells, the "
                                               f"{'header' if header else 'first row'} "
                                               f"(line {first_line}) has {width} (split at "
                                               f"{_delimiter_text(delimiter)}){hint}")
    preamble = [(n, line.strip()[:PREVIEW]) for n, line in numbered[:start.top]]
    return Table(header=header, body=body, delimiter=delimiter, preamble=preamble, units_line=start.units_line)


def _short_header(path: Path, header: list[str], header_line: int, body: list[tuple[int, list[str]]],
                  delimiter: str | None) -> list[str]:
    """The header of a table whose rows all have more cells than it: padded with empty cells when
    the cells beyond it are empty on every row (a delimiter ending each row: those columns hold
    nothing), else refused at the first row with a number beyond it. Which columns a short header
    names is not said (the first ones, as loggers that add a channel write it, or the last ones, as
    a table with row names has it), and a guess could import one signal as another."""
    width = len(body[0][1])
    if width <= len(header) or any(len(cells) != width for _, cells in body):
        return header  # a row of another width is named by the width check
    named = len(header)
    beyond = next((line for line, cells in body if any(cells[named:])), None)
    if beyond is None:
        return header + [""] * (width - named)
    columns = f"column {width} holds" if width == named + 1 else f"columns {named + 1}..{width} hold"
    raise InputError(f"{path}:{beyond}", f"row has {width} cells (split at {_delimiter_text(delimiter)}), as has every "
                                         f"row below the header (line {header_line}), which has {named}: {columns} "
                                         f"numbers under no header cell, and a short header may name the first "
                                         f"{named} columns or the last {named}; name every column in the header, or "
                                         f"pass --skip-rows {body[0][0] - 1} to read the rows without it and name the "
                                         "columns by number (--u 1 --y 2)")


def _numeric_table(path: Path, text: str, skip_rows: int | None) -> Table | None:
    """The table read the fast way, when the careful reading would find the same: its start found
    cell by cell in the first :data:`HEAD_LINES` lines, then its body, from its first row to the
    last line that is not blank, read from the file in one pass by :func:`numpy.loadtxt` (a C
    parser, which reads a number as ``float`` does). None when the careful reading must decide: a
    cell that is empty, quoted or not a number, a row of another width, a blank or comment line
    inside the body, a delimiter the whole file would not choose, a start found differently on the
    whole file (the head's most common width not the body's), one column, or a line end that
    ``str.splitlines`` knows and a file read in text mode does not (form feed, ``\\x1c``, U+2028,
    ...: the line numbers would differ)."""
    if any(end in text for end in SPLITLINES_ONLY):
        return None
    first_index = skip_rows or 0
    raw = _head(text, first_index + HEAD_LINES)
    head = _table_lines([line.rstrip("\r\n") for line in raw], first_index, len(raw))
    if not head:
        return None
    delimiter = _choose_delimiter(path, [line for _, line in head])
    if delimiter == "":
        return None
    rows = [(n, _split(line, delimiter)) for n, line in head]
    try:
        start = _start(path, rows, delimiter, skip_rows)
    except InputError:  # said by the careful reading, which sees every line
        return None
    width = len(rows[start.top][1])
    common = Counter(len(cells) for _, cells in rows).most_common(1)[0][0]
    if start.body >= len(rows) or width < 2 or (skip_rows is None and common != width):
        return None
    begin = rows[start.body][0] - 1  # the index of the body's first line
    stop = _content_lines(text)  # the index after the last line that is not blank
    try:
        numbers = np.loadtxt(path, dtype=np.float64, delimiter=delimiter, comments=None, skiprows=begin, ndmin=2,
                             encoding="utf-8-sig")
    except ValueError:
        return None
    if numbers.shape != (stop - begin, width):  # a blank line loadtxt passed over is not a row
        return None
    offset = sum(len(line) for line in raw[:begin])
    if not _same_delimiter(path, [line for n, line in head if n <= begin], text, offset, stop - begin, delimiter):
        return None
    preamble = [(n, line.strip()[:PREVIEW]) for n, line in head[:start.top]]
    return Table(header=start.header, body=NumericRows(text, begin, stop, delimiter), delimiter=delimiter,
                 preamble=preamble, units_line=start.units_line, numbers=numbers)


def _same_delimiter(path: Path, above: list[str], text: str, offset: int, rows: int, delimiter: str | None) -> bool:
    """Whether :func:`_choose_delimiter` over every line of the table (``above`` the body, and the
    body: ``rows`` rows of numbers from ``text[offset:]``, split at ``delimiter``, at least 2 per
    row) picks ``delimiter`` too. A body that holds no other delimiter is counted at once: each
    of its rows holds ``delimiter`` (whitespace between cells, for None) and no other."""
    if path.suffix.lower() == ".tsv":
        return delimiter == "\t"
    if any(text.find(other, offset) >= 0 for other in DELIMITERS if other != delimiter):
        body = text[offset:].splitlines()[:rows]
        return _choose_delimiter(path, above + body) == delimiter
    return delimiter == _delimiter_of(lambda d: sum(d in line for line in above) + (rows if d == delimiter else 0),
                                      lambda: sum(len(line.split(None, 1)) > 1 for line in above) + rows,
                                      len(above) + rows)


@dataclass(frozen=True)
class Group:
    """The columns one header cell labels: itself and the empty-headed columns holding data to its
    right (a label over several columns), with the cell's name and unit."""

    columns: tuple[int, ...]
    cell: str
    name: str
    unit: str | None


def groups_of(table: Table) -> tuple[list[Group], list[str | int]]:
    """The labelled groups of columns, and the title of every column: its header cell, ``label #k``
    for the k-th column under a label over several, or its number (from 1) when it has no title."""
    width = table.width
    if table.header is None:
        return [], list(range(1, width + 1))
    holds_data = ([True] * width if table.numbers is not None else
                  [any(cells[i] for _, cells in table.body) for i in range(width)])
    spans: list[list[int]] = []
    current: list[int] | None = None
    for i, cell in enumerate(table.header):
        if cell:
            current = [i]
            spans.append(current)
        elif current is not None and holds_data[i]:
            current.append(i)
        else:  # an empty column ends a label's span; unlabelled columns are nobody's
            current = None
    groups = [Group(tuple(span), table.header[span[0]], *split_unit(table.header[span[0]])) for span in spans]
    titles: list[str | int] = list(range(1, width + 1))
    for group in groups:
        several = len(group.columns) > 1
        for k, i in enumerate(group.columns, start=1):
            titles[i] = f"{group.cell} #{k}" if several else group.cell
    return groups, titles


def _matching(groups: list[Group], name: str) -> list[Group]:
    """The groups labelled ``name``: the header cell exactly, else ignoring case, else its name
    without the unit exactly, else ignoring case."""
    folded = name.casefold()
    for test in (lambda g: g.cell == name, lambda g: g.cell.casefold() == folded,
                 lambda g: g.name == name, lambda g: g.name.casefold() == folded):
        found = [g for g in groups if test(g)]
        if found:
            return found
    return []


def _numbered(groups: list[Group], name: str, where: str) -> list[tuple[int, Group]]:
    """(number, group) of the header cells that are ``name`` and a number (``u1``, ``u_1``,
    ``u(1)``, ...; ignoring case and a trailing unit). After a name ending in a digit the number
    needs a separator, so ``u1`` does not number ``u10``."""
    separator = r"[ _.\-]" if name[-1:].isdigit() else r"[ _.\-]?"
    pattern = re.compile(rf"^\s*{re.escape(name)}(?:{separator}(\d+)|\s*[\[(]\s*(\d+)\s*[\])]){UNIT_SUFFIX}\s*$",
                         re.IGNORECASE)
    found = []
    for group in groups:
        match = pattern.match(group.cell)
        if match:
            if len(group.columns) > 1:
                raise InputError(where, f"the numbered column {group.cell!r} labels {len(group.columns)} columns; "
                                        "a label over several columns names the realizations of one signal: "
                                        f"call it {name!r}, or number every column")
            found.append((int(match.group(1) or match.group(2)), group))
    return sorted(found, key=lambda item: (item[0], item[1].columns))


@dataclass(frozen=True)
class Chosen:
    """The columns of one signal, their realization numbers (None: one column, or repeated cells),
    the numbered columns passed over for a column named exactly, and the groups read."""

    indices: list[int]
    numbers: list[int] | None
    passed_over: list[int]
    groups: list[Group]


def _columns(groups: list[Group], titles: list[str | int], header: bool, width: int, name: str, where: str) -> Chosen:
    """The column(s) of one signal (whether passed-over numbered columns are ambiguous is decided by
    the caller).

    One column: the header cell ``name`` (exact, else ignoring case, else without its unit), else
    column number ``name``. Several (realizations side by side): a label over several columns,
    ``name`` repeated in the header, or, when it is not a header cell, the numbered columns
    ``name1, name2, ...``.
    """
    if header:
        exact = _matching(groups, name)
        numbered = [] if name.isdigit() else _numbered(groups, name, where)
        if len(exact) == 1 and len(exact[0].columns) > 1:
            columns = list(exact[0].columns)
            return Chosen(columns, list(range(1, len(columns) + 1)), [], exact)
        if exact:
            passed = [g.columns[0] for _, g in numbered] if len(exact) == 1 else []
            return Chosen([i for g in exact for i in g.columns], None, passed, exact)
        if numbered:
            for (n, a), (m, b) in zip(numbered, numbered[1:]):
                if n == m:
                    raise InputError(where, f"columns {a.cell!r} and {b.cell!r} both have number {n}")
            return Chosen([g.columns[0] for _, g in numbered], [n for n, _ in numbered], [], [g for _, g in numbered])
    if name.isdigit() and 1 <= int(name) <= width:
        index = int(name) - 1
        return Chosen([index], None, [], [g for g in groups if index in g.columns])
    named = ", ".join(repr(t) for t in titles if isinstance(t, str))
    columns = f"columns are {named} or " if named else "columns are "
    raise NotFound(where, f"no column {name!r}; {columns}numbers 1..{width}")


def _check_ambiguous(path: Path, titles: list[str | int], names: dict[str, str], chosen: dict[str, Chosen],
                     defaulted: frozenset[str]) -> None:
    """Refuse a default name that is a column *and* has numbered columns (``u, u2, u3``) when the
    numbered reading would give realizations: the input u has numbered columns, or is that name. An
    explicit ``--u u`` takes the one column; ``t, u, y, y2`` (one input, a second sensor) is no
    question: y is the column y."""
    u_numbered = "u" in chosen and (chosen["u"].passed_over or chosen["u"].numbers is not None)
    for key, picked in chosen.items():
        if picked.passed_over and key in defaulted and (key == "u" or u_numbered):
            column = titles[picked.indices[0]]
            listed = ", ".join(repr(titles[i]) for i in picked.passed_over)
            raise InputError(f"{path}: --{key} {names[key]}", f"ambiguous: a column {column!r} and the numbered columns "
                                                              f"{listed}; pass --{key} {column} for the one column, or "
                                                              "rename it to import the numbered ones as realizations")


def _paired(path: Path, titles: list[str | int], chosen: dict[str, Chosen]) -> int:
    """The number of realizations the chosen columns hold; refuse columns that do not pair up."""
    counts = {len(c.indices) for c in chosen.values()}
    numbers = {tuple(c.numbers) for c in chosen.values() if c.numbers is not None}
    kinds = {c.numbers is None for c in chosen.values()}  # repeated (or single) / numbered
    if len(counts) == 1 and len(numbers) <= 1 and (counts == {1} or len(kinds) == 1):
        return counts.pop()
    listed = "; ".join(f"{key}: {', '.join(repr(titles[i]) for i in c.indices)}" for key, c in chosen.items())
    raise InputError(str(path), f"the signal columns do not pair into realizations ({listed}): each realization "
                                "needs one column of every signal, numbered alike (u1, y1, u2, y2, ...); "
                                "name the columns with --u/--y/--r")


def _unit(path: Path, key: str, picked: Chosen, titles: list[str | int]) -> str | None:
    """The unit the header gives a signal: the one unit of all its columns; None when some have
    none; refused when its columns state different units."""
    units = {g.unit for g in picked.groups}
    if None in units or not units:
        return None
    if len(units) > 1:
        listed = ", ".join(repr(titles[g.columns[0]]) for g in picked.groups)
        raise InputError(str(path), f"the columns of {key} state different units ({listed}); the realizations of "
                                    "a signal share one unit")
    return units.pop()


def _time_scale(path: Path, group: Group | None, title: str | int) -> tuple[float, str | None]:
    """Seconds per unit of a time column's header (``time (ms)``: 1e-3), and the unit."""
    if group is None or group.unit is None:
        return 1.0, None
    scale = TIME_UNITS.get(group.unit.casefold())
    if scale is None:
        raise InputError(f"{path}:{title}", f"unknown time unit {group.unit!r}; units understood: {TIME_UNITS_TEXT}")
    return scale, group.unit


def _time_column(path: Path, groups: list[Group], titles: list[str | int], header: bool, width: int,
                 time: str) -> tuple[int, float, str | None]:
    """The index of the time column ``time``, its seconds per unit, and its unit (None: seconds)."""
    where = f"{path}: --time {time}"
    picked = _columns(groups, titles, header, width, time, where)
    if len(picked.indices) > 1:
        raise InputError(where, f"{len(picked.indices)} columns ({', '.join(repr(titles[i]) for i in picked.indices)}); "
                                "a time vector is one column")
    index = picked.indices[0]
    scale, unit = _time_scale(path, picked.groups[0] if picked.groups else None, titles[index])
    return index, scale, unit


def read_csv(path: Path, names: dict[str, str], time: str | None, optional: set[str], fs_given: bool,
             defaulted: frozenset[str] = frozenset(), skip_rows: int | None = None) -> Source:
    """Read the selected columns (signal -> column), the time column and the sample-rate and
    sampling-interval columns of a CSV/TSV table. ``defaulted``: the signals whose names were not
    given (``u``, ``y``, ``r``); ``skip_rows``: lines above the header (None: found).

    Several columns of one signal (realizations side by side) give a (realizations, samples) matrix,
    which :func:`nlsid.importers.source.records_of` cuts into one record per realization.
    """
    table = read_table(path, skip_rows)
    header, body, width = table.header, table.body, table.width
    groups, titles = groups_of(table)
    if time is None and not fs_given:
        time = next((g.cell for g in groups if g.name.casefold() in TIME_NAMES), None)
    chosen: dict[str, Chosen] = {}
    for key, name in names.items():
        try:
            chosen[key] = _columns(groups, titles, header is not None, width, name, f"{path}: {option(key, name)}")
        except NotFound:
            if key not in optional:
                raise
    _check_ambiguous(path, titles, names, chosen, defaulted)
    realizations = _paired(path, titles, chosen)
    if realizations > len(body):
        raise InputError(str(path), f"{realizations} realizations side by side but only {len(body)} row(s) of samples")

    def title(index: int) -> str:
        return str(titles[index])

    def parse(index: int) -> np.ndarray:
        return _parse(path, table, index, titles[index])

    values = {key: parse(c.indices[0]) if realizations == 1 else np.vstack([parse(i) for i in c.indices])
              for key, c in chosen.items()}
    columns = {key: (title(c.indices[0]) if header else names[key]) if realizations == 1 else
               [title(i) for i in c.indices] for key, c in chosen.items()}
    labels = {key: columns[key] if realizations == 1 else _label(columns[key], name=names[key])
              for key in chosen}
    used = {i for c in chosen.values() for i in c.indices}
    details: dict = {"columns": columns, "header": header is not None}
    if time:
        index, scale, unit = _time_column(path, groups, titles, header is not None, width, time)
        values["time"] = parse(index) * scale
        labels["time"] = columns["time"] = title(index) if header else time
        used.add(index)
        if unit is not None:
            details["time_unit"] = unit
    if realizations > 1:
        details["realizations"] = realizations
    source = source_from(path, "csv", labels, values, details)
    source.units = {key: unit for key, c in chosen.items() if (unit := _unit(path, key, c, titles)) is not None}
    if not fs_given:
        rate_groups = [g for g in groups if (RATE_NAME.match(g.name) or INTERVAL_NAME.match(g.name))
                       and not used.intersection(g.columns)]
        if rate_groups:
            _apply_rate_columns(source, path, table, rate_groups, titles)
            used.update(i for g in rate_groups for i in g.columns)
    details["ignored_columns"] = [titles[i] for i in range(width) if i not in used]
    if table.preamble:
        details["preamble_lines"] = [{"line": n, "text": text} for n, text in table.preamble]
    if skip_rows is not None:
        details["skipped_rows"] = skip_rows
    if table.units_line is not None:
        details["units_row"] = table.units_line
    return source


def _label(titles: list[str], name: str) -> str:
    """How a set of realization columns is named in messages: ``u1..u10`` or ``u (columns 2, 4, 6)``."""
    if len(set(titles)) == len(titles):
        return f"{titles[0]}..{titles[-1]}"
    return f"{name} (columns {len(titles)})"


@dataclass(frozen=True)
class Rate:
    """The sample rate one column gives, and how to name it."""

    fs: float
    title: str
    kind: str  # "sample-rate" or "sampling-interval"


def _rate_of(path: Path, table: Table, group: Group, titles: list[str | int]) -> Rate:
    """The sample rate of a sample-rate (``fs``) or sampling-interval (``Ts``, ``dt``) column: one
    value over all its cells (empty cells allowed)."""
    title = str(titles[group.columns[0]]) if len(group.columns) == 1 else group.cell
    interval = INTERVAL_NAME.match(group.name) is not None
    units = TIME_UNITS if interval else RATE_UNITS
    default = "s" if interval else "Hz"
    what = "sampling interval" if interval else "sample rate"
    scale = units.get(group.unit.casefold()) if group.unit else 1.0
    if scale is None:
        understood = TIME_UNITS_TEXT if interval else "Hz, kHz, MHz"
        raise InputError(f"{path}:{title}", f"unknown unit {group.unit!r} of a {what}; units understood: {understood}")
    first: tuple[float, int] | None = None
    for line, cells in _rate_rows(table, group):
        for index in group.columns:
            cell = cells[index]
            if not cell:
                continue
            value = _number(cell)
            if value is None or not np.isfinite(value) or value <= 0:
                raise InputError(f"{path}:{line}", f"column {titles[index]!r}: cell {cell[:40]!r} is not a {what} "
                                                   f"(a number > 0, in {group.unit or default})")
            if first is None:
                first = (value, line)
            elif value != first[0]:
                raise InputError(f"{path}:{title}", f"the {what} varies: {first[0]:.9g} on line {first[1]}, "
                                                    f"{value:.9g} on line {line}; a file holds one rate (split the "
                                                    "file, or pass --fs HZ" + (f", or --time {title} if it is a time "
                                                                               "vector)" if interval else ")"))
    if first is None:
        raise InputError(f"{path}:{title}", f"the {what.replace(' ', '-')} column holds no value")
    value = first[0] * scale
    fs = 1.0 / value if interval else value
    return Rate(fs, title, "sampling-interval" if interval else "sample-rate")


def _rate_rows(table: Table, group: Group) -> Sequence[tuple[int, list[str]]]:
    """The rows a rate column's cells must be read from: all of them, or, in a table of numbers,
    those up to the first that holds a value not > 0 or other than the first row's (the others
    repeat the first row's value)."""
    if table.numbers is None:
        return table.body
    values = table.numbers[:, list(group.columns)]
    odd = np.flatnonzero((~np.isfinite(values) | (values <= 0) | (values != values[0, 0])).any(axis=1))
    return table.body[: int(odd[0]) + 1 if odd.size else 1]


def _apply_rate_columns(source: Source, path: Path, table: Table, groups: list[Group],
                        titles: list[str | int]) -> None:
    """Set the source's sample rate from its sample-rate and sampling-interval columns, which must
    agree with each other and with the time vector."""
    rates = [_rate_of(path, table, group, titles) for group in groups]
    first = rates[0]
    for other in rates[1:]:
        if abs(other.fs / first.fs - 1) > REL_TOL:
            raise InputError(str(path), f"the {first.kind} column {first.title!r} gives {first.fs:.9g} Hz but the "
                                        f"{other.kind} column {other.title!r} {other.fs:.9g} Hz (they must agree "
                                        f"within {REL_TOL:g}); pass --fs HZ to choose")
    source.fs = first.fs
    source.fs_from = f"{first.kind} column {path}:{first.title}"
    if first.kind == "sampling-interval":
        source.fs_from += " (fs = 1/Ts)"
    source.details["sample_rate_column"] = first.title
    source.details["rate_columns"] = [rate.title for rate in rates]
    if source.time is not None:
        from_time = sample_rate(source.time, source.time_where)
        for rate in rates:
            if abs(from_time / rate.fs - 1) > REL_TOL:
                raise InputError(str(path), f"the {rate.kind} column {rate.title!r} says {rate.fs:.9g} Hz but the time "
                                            f"vector {source.time_where} gives {from_time:.9g} Hz "
                                            f"(they must agree within {REL_TOL:g}); pass --fs HZ to choose")
        source.details["time_vector_fs"] = from_time


def _parse(path: Path, table: Table, index: int, title: str | int) -> np.ndarray:
    """The numbers of one column; a cell that is not a number is refused naming its line and the
    delimiter (a wrong delimiter, or decimal commas, show there)."""
    if table.numbers is not None:
        return np.ascontiguousarray(table.numbers[:, index])
    body = table.body
    try:  # the fast path; a cell that is not a number is found and named below
        return np.fromiter(map(float, [cells[index] for _, cells in body]), dtype=np.float64, count=len(body))
    except ValueError:
        pass
    out = np.empty(len(body))
    for i, (line, cells) in enumerate(body):
        value = _number(cells[index])
        if value is None:
            cell = cells[index]
            hint = ("; decimal commas are not read: write numbers with a point"
                    if "," in cell and _number(cell.replace(",", ".", 1)) is not None else "")
            raise InputError(f"{path}:{line}", f"column {title!r}: cell {cell[:40]!r} is not a number (cells split at "
                                               f"{_delimiter_text(table.delimiter)}){hint}")
        out[i] = value
    return out
