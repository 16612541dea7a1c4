"""A CSV header with fewer cells than the rows below it: no column is dropped, and none is guessed.

Empty cells beyond the header on every row (a delimiter ending each row) are empty columns, listed as
not imported. Numbers beyond the header are refused, naming the file, the first row holding one and
the fix (``--skip-rows`` and columns by number): a short header may name the first columns (a logger
that added a channel) or the last (a table with row names), and a guess could import one signal as
another. The samples read back are the ones the test wrote.
"""

from __future__ import annotations

import numpy as np

from nlsid.io.recording import read_runs

FS = 1000.0
N = 300


def signals(seed: int) -> dict[str, np.ndarray]:
    """Noise (an arbitrary record): u, y a filtered u, and a further column d."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(N)
    return {"u": u, "y": np.convolve(u, [0.5, 0.3])[:N], "d": rng.standard_normal(N)}


def text_of(header: str, columns: list[np.ndarray], end: str = "") -> str:
    rows = [",".join(repr(float(v)) for v in row) + end for row in np.column_stack(columns)]
    return header + "\n" + "\n".join(rows) + "\n"


def test_three_named_columns_over_four_are_refused_with_the_fix(run_cli, tmp_path):
    """Header ``t,u,y`` over rows ``t,u,y,d``: refused at the first row, line 2, with --skip-rows 1;
    following it (columns by number) imports all four columns as written."""
    s = signals(1)
    t = np.arange(N) / FS
    path = tmp_path / "rig.csv"
    path.write_text(text_of("t,u,y", [t, s["u"], s["y"], s["d"]]))
    run_cli("import", path, "-o", tmp_path / "no.h5").assert_one_line_error(
        "rig.csv:2: row has 4 cells (split at ','), as has every row below the header (line 1), which has 3",
        "column 4 holds numbers under no header cell", "the first 3 columns or the last 3",
        "--skip-rows 1 to read the rows without it and name the columns by number")
    assert not (tmp_path / "no.h5").exists()
    out = tmp_path / "rec.h5"
    result = run_cli("import", path, "--skip-rows", "1", "--time", "1", "--u", "2", "--y", "3", "--channel", "d=4",
                     "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["fs"] == FS and summary["ignored_columns"] == {str(path): []}
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.u, s["u"])
    np.testing.assert_array_equal(run.y, s["y"])
    np.testing.assert_array_equal(run.channels["d"], s["d"])


def test_numbers_beyond_the_header_on_some_rows_name_the_first(run_cli, tmp_path):
    """Every row has a fourth cell, empty but on line 7 (the 6th row): refused there."""
    s = signals(2)
    path = tmp_path / "some.csv"
    lines = text_of("u,y,d", [s["u"], s["y"], s["d"]], end=",").splitlines()
    lines[6] += "0.25"
    path.write_text("\n".join(lines) + "\n")
    run_cli("import", path, "--fs", "1000", "-o", tmp_path / "no.h5").assert_one_line_error(
        "some.csv:7: row has 4 cells", "which has 3: column 4 holds numbers under no header cell")


def test_a_delimiter_ending_every_row_is_an_empty_column_listed_as_ignored(run_cli, tmp_path):
    """Header ``u,y`` over rows ``u,y,``: imported as written, the empty third column listed."""
    s = signals(3)
    path = tmp_path / "logger.csv"
    path.write_text(text_of("u,y", [s["u"], s["y"]], end=","))
    out = tmp_path / "rec.h5"
    result = run_cli("import", path, "--fs", "1000", "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["ignored_columns"] == {str(path): [3]}
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.u, s["u"])
    np.testing.assert_array_equal(run.y, s["y"])


def test_two_empty_columns_beyond_a_header_of_group_labels(run_cli, tmp_path):
    """``u,,y,`` labels two realizations each; two more delimiters end every row: columns 5 and 6
    are empty and listed, the realizations imported as written."""
    a, b = signals(4), signals(5)
    path = tmp_path / "groups.csv"
    path.write_text(text_of("u,,y,", [a["u"], b["u"], a["y"], b["y"]], end=",,"))
    out = tmp_path / "rec.h5"
    result = run_cli("import", path, "--fs", "1000", "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["ignored_columns"] == {str(path): [5, 6]}
    runs = read_runs(out)
    assert len(runs) == 2
    for run, s in zip(runs, (a, b)):
        np.testing.assert_array_equal(run.u, s["u"])
        np.testing.assert_array_equal(run.y, s["y"])


def test_a_preamble_above_a_header_over_rows_ending_in_a_delimiter(run_cli, tmp_path):
    """``Axis1`` / ``Date: ...`` above ``t,u,y`` over rows ``t,u,y,``: the preamble is found as above
    a full header, fs comes from t, and column 4 is listed."""
    s = signals(6)
    path = tmp_path / "scope.csv"
    path.write_text("Axis1\nDate: 2024-05-01\n" + text_of("t,u,y", [np.arange(N) / FS, s["u"], s["y"]], end=","))
    out = tmp_path / "rec.h5"
    result = run_cli("import", path, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["fs"] == FS and summary["ignored_columns"] == {str(path): [4]}
    assert [line["line"] for line in summary["preamble_lines"][str(path)]] == [1, 2]
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.u, s["u"])
    np.testing.assert_array_equal(run.y, s["y"])


def test_one_cell_preamble_lines_above_a_one_cell_header(run_cli, tmp_path):
    """``Axis1`` / ``Date: ...`` / ``u`` over rows ``u,``: the line just above the data is the
    header (preamble lines of the header's one cell are not a second header)."""
    s = signals(7)
    path = tmp_path / "one.csv"
    path.write_text("Axis1\nDate: 2024-05-01\n" + text_of("u", [s["u"]], end=","))
    out = tmp_path / "rec.h5"
    result = run_cli("import", path, "--fs", "1000", "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["ignored_columns"] == {str(path): [2]}
    assert [line["line"] for line in summary["preamble_lines"][str(path)]] == [1, 2]
    (run,) = read_runs(out, require_y=False)
    np.testing.assert_array_equal(run.u, s["u"])
