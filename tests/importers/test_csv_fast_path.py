"""A table of numbers is read in one pass (numpy.loadtxt) and must read exactly as the careful
cell-by-cell reading does: the same header, preamble, rows and numbers, and, where the fast reading
cannot be sure (an empty, quoted or text cell, a row of another width, a blank or comment line inside
the body), the careful reading's message. Each table is read both ways: the careful reading is
forced by making the fast one decline. The numbers are checked against Python's ``float`` of the
text the test wrote."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nlsid.errors import InputError
from nlsid.importers import csv_file
from nlsid.importers.csv_file import read_csv, read_table

ROWS = 40


def read_both(path: Path, **kwargs):
    """(fast, careful): what read_table and read_csv give, or the InputError they raise, each way."""

    def outcome(reader):
        try:
            return reader()
        except InputError as exc:
            return f"InputError: {exc}"

    def readings():
        table = outcome(lambda: read_table(path, kwargs.get("skip_rows")))
        source = outcome(lambda: read_csv(path, {"u": "u", "y": "y", "r": "r"}, None, {"y", "r"}, fs_given=False,
                                          defaulted=frozenset({"u", "y", "r"}), **kwargs))
        return table, source

    fast = readings()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(csv_file, "_numeric_table", lambda *args: None)
        slow = readings()
    return fast, slow


def assert_same(fast, slow):
    (fast_table, fast_source), (slow_table, slow_source) = fast, slow
    if isinstance(slow_table, str):
        assert fast_table == slow_table
    else:
        assert fast_table.header == slow_table.header
        assert fast_table.delimiter == slow_table.delimiter
        assert fast_table.preamble == slow_table.preamble
        assert fast_table.units_line == slow_table.units_line
        assert list(fast_table.body) == list(slow_table.body)
    if isinstance(slow_source, str):
        assert fast_source == slow_source
        return
    assert fast_source.details == slow_source.details
    assert (fast_source.fs, fast_source.fs_from) == (slow_source.fs, slow_source.fs_from)
    assert fast_source.arrays.keys() == slow_source.arrays.keys()
    for key in slow_source.arrays:
        np.testing.assert_array_equal(fast_source.arrays[key], slow_source.arrays[key])
    np.testing.assert_array_equal(fast_source.time, slow_source.time)


SPECIAL = ["-0", "+1.5", " 2.5 ", "1e-320", "1.7976931348623157e308", "4.9e-324", ".5", "5.", "1E3", "12"]


def number_text(rng: np.random.Generator) -> str:
    """A number as loggers write it: shortest round trip, 17 digits, fixed exponent, or a special form."""
    value = float(rng.standard_normal() * 10.0 ** rng.integers(-30, 30))
    form = rng.integers(4)
    return [repr(value), f"{value:.17g}", f"{value:.6e}", SPECIAL[rng.integers(len(SPECIAL))]][form]


FLAWS = ["none", "blank", "comment", "empty cell", "quoted", "text", "extra cell", "short row", "tab", "decimal comma",
         "nan", "fs varies", "trailing blanks", "inline comment", "form feed", "byte order mark"]


@st.composite
def tables(draw):
    """A CSV text: optional preamble, header (or none), rows of numbers, and one flaw somewhere."""
    delimiter = draw(st.sampled_from([",", ";", "\t", " "]))
    header = draw(st.sampled_from([["t", "u", "y"], ["u", "y"], ["u", "y", "fs"], None]))
    width = len(header) if header else 2
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    cells = [[number_text(rng) for _ in range(width)] for _ in range(ROWS)]
    if header and header[0] == "t":
        cells = [[repr(k / 1000.0)] + row[1:] for k, row in enumerate(cells)]
    if header and header[-1] == "fs":
        cells = [row[:-1] + ["1000"] for row in cells]
    if delimiter == " ":
        cells = [[c.strip() for c in row] for row in cells]
    flaw = draw(st.sampled_from(FLAWS))
    at = draw(st.integers(0, ROWS - 1))
    lines = [delimiter.join(row) for row in cells]
    flawed = {"blank": "", "comment": "# a note", "empty cell": delimiter.join([""] + cells[at][1:]),
              "quoted": delimiter.join([f'"{cells[at][0]}"'] + cells[at][1:]),
              "text": delimiter.join(["n/a"] + cells[at][1:]), "inline comment": lines[at] + " # note",
              "form feed": lines[at] + "\x0c", "extra cell": lines[at] + delimiter + "1",
              "short row": delimiter.join(cells[at][1:]), "tab": lines[at].replace(delimiter, "\t" + delimiter, 1),
              "decimal comma": delimiter.join(["1,5"] + cells[at][1:]), "nan": delimiter.join(["nan"] + cells[at][1:]),
              "fs varies": delimiter.join(cells[at][:-1] + ["2000"]) if header and header[-1] == "fs" else lines[at]}
    if flaw == "blank" or flaw == "comment":
        lines.insert(at, flawed[flaw])
    elif flaw in flawed:
        lines[at] = flawed[flaw]
    top = ([delimiter.join(header)] if header else [])
    preamble = draw(st.sampled_from([[], ["Axis1"], ["Date: 2024-05-01, 10:00", "Device; DAQ 1"]]))
    end = "\n\n\n" if flaw == "trailing blanks" else "\n"
    text = ("\ufeff" if flaw == "byte order mark" else "") + "\n".join(preamble + top + lines) + end
    return text.replace("\n", draw(st.sampled_from(["\n", "\r\n", "\r"]))), delimiter


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tables())
def test_fast_reading_is_the_careful_reading(table):
    text, delimiter = table
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / ("table.tsv" if delimiter == "\t" and len(text) % 2 else "table.csv")
        path.write_bytes(text.encode("utf-8"))
        assert_same(*read_both(path))
        if "Axis1" in text:
            assert_same(*read_both(path, skip_rows=1))


def test_numbers_are_those_float_reads_from_the_text(tmp_path):
    """Correctly rounded as Python's float: shortest round-trip texts, 17 digits, subnormals, the
    largest double, signed zero, exponents without digits after the point."""
    rng = np.random.default_rng(1)
    values = np.concatenate([rng.standard_normal(500) * 10.0 ** rng.integers(-300, 300, 500),
                             [5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, -0.0, 0.1, 1 / 3]])
    texts = [[repr(float(v)), f"{v:.17g}", f"{v:.3e}"] for v in values]
    texts[0] = ["+1.", "-.5", "1E+2"]
    path = tmp_path / "numbers.csv"
    path.write_text("u,y,r\n" + "\n".join(", ".join(row) for row in texts) + "\n\n\n")  # blank lines at the end
    table = read_table(path)
    assert table.numbers is not None  # the fast reading took it
    expected = np.array([[float(cell) for cell in row] for row in texts])
    np.testing.assert_array_equal(table.numbers, expected)
    assert np.array_equal(np.signbit(table.numbers), np.signbit(expected))


def test_a_flaw_deep_in_a_long_body_is_named_on_its_line(run_cli, tmp_path):
    """The fast reading declines at row 4000 of 5000; the careful one names line 4002 (header on
    line 1) and the delimiter, as it does for a short file."""
    rows = [f"{k},{k * 0.5}" for k in range(5000)]
    rows[4000] = "7,8,9"
    path = tmp_path / "long.csv"
    path.write_text("u,y\n" + "\n".join(rows) + "\n")
    run_cli("import", path, "--fs", "1000", "-o", tmp_path / "rec.h5").assert_one_line_error(
        "long.csv:4002", "row has 3 cells, the header (line 1) has 2 (split at ',')")


def test_a_rate_column_varying_deep_in_a_long_body_names_both_lines(tmp_path):
    rows = ["1,2,1000"] * 3000
    rows[2500] = "1,2,999"
    path = tmp_path / "rate.csv"
    path.write_text("# exported\nu,y,fs\n" + "\n".join(rows) + "\n")
    assert read_table(path).numbers is not None
    with pytest.raises(InputError, match=r"the sample rate varies: 1000 on line 3, 999 on line 2503"):
        read_csv(path, {"u": "u", "y": "y"}, None, set(), fs_given=False)


def test_a_delimiter_the_whole_file_chooses_over_the_head(tmp_path):
    """The first 300 rows split at commas, the 1000 after them hold a tab too: the file's delimiter
    is the tab (on more than half of the lines), so cells such as '1,' are not numbers, as the
    careful reading says, although the head alone reads as commas."""
    path = tmp_path / "mixed.csv"
    path.write_text("u,y\n" + "\n".join(["1,2"] * 300 + ["1,\t2"] * 1000) + "\n")
    fast, slow = read_both(path)
    assert_same(fast, slow)
    assert "split at tab" in slow[1]


def test_a_preamble_longer_than_the_head_is_read_carefully(tmp_path):
    path = tmp_path / "long_preamble.csv"
    preamble = "\n".join(f"setting {k}" for k in range(250))
    path.write_text(preamble + "\nu,y\n" + "\n".join(f"{k},{-k}" for k in range(600)))
    fast, slow = read_both(path)
    assert_same(fast, slow)
    np.testing.assert_array_equal(fast[1].arrays["y"], -np.arange(600.0))
    assert [line["line"] for line in fast[1].details["preamble_lines"]] == list(range(1, 251))


@pytest.mark.parametrize("flawed, outcome", [
    ("3,4 # note", "long.csv:102: column 'y': cell '4 # note' is not a number"),
    (",4", "long.csv:102: column 'u': cell '' is not a number"),
    ("3;4", "long.csv:102: row has 1 cells, the header (line 1) has 2"),
    ('"3",4', 3.0),  # a quoted number is a number
    ("3,4\x0c", 3.0),  # a form feed ends a line for str.splitlines: an empty line after it
    ("", None),
    ("# paused", None),
])
def test_flaws_deep_in_the_body_read_as_the_careful_reading_does(tmp_path, flawed, outcome):
    """Each flaw at line 102 of 301: the fast reading declines, and the table reads as the careful
    reading has it (the message, or the numbers written, the flawed row's u where it is a row)."""
    rows = [f"{k},{k / 8}" for k in range(300)]
    rows.insert(100, flawed)
    path = tmp_path / "long.csv"
    path.write_text("u,y\n" + "\n".join(rows) + "\n")
    fast, slow = read_both(path)
    assert_same(fast, slow)
    if isinstance(outcome, str):
        assert outcome in fast[1]
    else:
        u = np.arange(300.0) if outcome is None else np.insert(np.arange(300.0), 100, outcome)
        np.testing.assert_array_equal(fast[1].arrays["u"], u)
