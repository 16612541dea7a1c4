"""``nlsid import`` of CSV shapes met in benchmark files: group labels over realizations, preamble
lines above the header, units in header cells, time columns in ms, sampling-interval columns.

Every file is written here by numpy from the test's own signals (cosine sums of known lines, an FIR
output); samples are written with 17 significant digits, which round-trip float64 exactly, so the
imported samples must equal the generated ones. Where no column may be lost, the test counts every
column of its own layout as imported or listed as ignored.
"""

from __future__ import annotations

import math
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nlsid.io.hdf5_recording import HDF5Recording
from nlsid.importers.csv_file import read_csv
from nlsid.io.recording import read_runs

FS = 1000.0
N = 128
BINS = np.arange(1, 30, 2)  # an odd multisine on bins 1, 3, ..., 29


def multisine(rng: np.random.Generator, periods: int = 2) -> np.ndarray:
    """``periods`` periods of an odd multisine of rms 1 with random phases, and noise of rms 1e-4."""
    n = np.arange(N)[:, None]
    phases = rng.uniform(0, 2 * np.pi, BINS.size)
    one = math.sqrt(2.0 / BINS.size) * np.cos(2 * np.pi * BINS[None, :] * n / N + phases).sum(axis=1)
    return np.tile(one, periods) + rng.normal(0, 1e-4, periods * N)


def fir(u: np.ndarray) -> np.ndarray:
    return np.convolve(u, [0.5, 0.3, 0.1])[: u.size]


def cell(value: float) -> str:
    return "" if np.isnan(value) else f"{value:.17g}"


def write_table(path: Path, header: list[str] | None, columns: list[np.ndarray], above: list[str] = (),
                delimiter: str = ",") -> Path:
    """A table of ``columns`` (NaN: an empty cell) under ``header``, after the lines ``above``."""
    lines = list(above) + ([delimiter.join(header)] if header is not None else [])
    lines += [delimiter.join(cell(v) for v in row) for row in np.column_stack(columns)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def summary_of(result) -> dict:
    assert result.exit_code == 0, (result.stderr, result.exception)
    return result.json()


def provenance_details(out: Path) -> dict:
    with HDF5Recording(out) as rec:
        return rec.provenance["import"]["details"]


def test_group_labels_over_ten_realizations_import_all_ten(run_cli, tmp_path):
    """``"r",,,,,,,,,,"u",,,,,,,,,,"y",,,,,,,,,,"fs"``: each label names 10 realizations, fs one column."""
    rng = np.random.default_rng(1)
    rs = [multisine(rng) for _ in range(10)]
    us = [r + rng.normal(0, 1e-3, r.size) for r in rs]
    ys = [fir(u) for u in us]
    rate = np.full(rs[0].size, np.nan)
    rate[0] = FS
    header = ['"r"'] + [""] * 9 + ['"u"'] + [""] * 9 + ['"y"'] + [""] * 9 + ['"fs"']
    source = write_table(tmp_path / "bench.csv", header, rs + us + ys + [rate])
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["fs"] == FS and summary["fs_from"] == f"sample-rate column {source}:fs"
    assert summary["run_ids"] == [f"bench_c{c:02d}" for c in range(10)]
    assert summary["ignored_columns"] == {str(source): []}
    runs = read_runs(out)
    assert len(runs) == 10
    for m, run in enumerate(runs):
        assert (run.kind, run.period, run.realization) == ("multisine", N, m)
        np.testing.assert_array_equal(run.excited_bins, BINS)
        np.testing.assert_array_equal(run.r, rs[m])
        np.testing.assert_array_equal(run.u, us[m])
        np.testing.assert_array_equal(run.y, ys[m])
    details = provenance_details(out)
    assert details["columns"]["u"] == [f"u #{k}" for k in range(1, 11)] and details["realizations"] == 10


def test_group_label_pairs_with_numbered_columns_and_a_trailing_empty_column(run_cli, tmp_path):
    """A label ``u`` over 3 columns pairs with ``y1..y3``; empty-headed columns with no label to their
    left (here two leading ones holding data) and an empty last column are listed as ignored."""
    rng = np.random.default_rng(2)
    us = [multisine(rng) for _ in range(3)]
    ys = [fir(u) for u in us]
    stray = [rng.normal(size=us[0].size) for _ in range(2)]
    empty = np.full(us[0].size, np.nan)
    header = ["", "", "t", "u", "", ""] + [f"y{m}" for m in (1, 2, 3)] + [""]
    source = write_table(tmp_path / "rig.csv", header, stray + [np.arange(us[0].size) / FS] + us + ys + [empty])
    out = tmp_path / "rec.h5"
    result = run_cli("import", source, "-o", out, "--json")
    summary = summary_of(result)
    assert summary["ignored_columns"] == {str(source): [1, 2, 10]}
    for m, run in enumerate(read_runs(out)):
        np.testing.assert_array_equal(run.u, us[m])
        np.testing.assert_array_equal(run.y, ys[m])
    # rich wraps the terminal's lines, and breaks a path longer than a line inside it: compared without whitespace
    text = "".join(run_cli("import", source, "-o", tmp_path / "again.h5").stderr.split())
    assert "".join(f"{source}: columns not imported: 1, 2, 10".split()) in text


def test_preamble_lines_above_the_header_are_skipped_and_named(run_cli, tmp_path):
    rng = np.random.default_rng(3)
    u = multisine(rng, periods=3)
    y = fir(u)
    above = ["Axis1", "Date: 2024-05-01, 12:00:00"]
    source = write_table(tmp_path / "scope.csv", ["t", "u", "y"], [np.arange(u.size) / FS, u, y], above=above)
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(FS, rel=1e-9)
    assert summary["preamble_lines"] == {str(source): [{"line": 1, "text": "Axis1"},
                                                       {"line": 2, "text": "Date: 2024-05-01, 12:00:00"}]}
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.periods("u").ravel(), u)
    np.testing.assert_array_equal(run.periods("y").ravel(), y)
    text = " ".join(run_cli("import", source, "-o", tmp_path / "again.h5").stderr.split())
    assert "2 line(s) above the header skipped: line 1 'Axis1', line 2 'Date: 2024-05-01, 12:00:00'" in text

    skipped = tmp_path / "skipped.h5"
    summary_of(run_cli("import", source, "--skip-rows", "2", "-o", skipped, "--json"))
    (run,) = read_runs(skipped)
    np.testing.assert_array_equal(run.periods("y").ravel(), y)
    details = provenance_details(skipped)
    assert details["skipped_rows"] == 2 and "preamble_lines" not in details
    with HDF5Recording(skipped) as rec:
        assert rec.provenance["import"]["overridden"] == {"skip_rows": 2}


@pytest.mark.parametrize("delimiter", ["\t", " ", ";"])
def test_preamble_with_commas_does_not_choose_the_delimiter(run_cli, tmp_path, delimiter):
    rng = np.random.default_rng(4)
    u = multisine(rng)
    above = ["Axis1", "Date: 2024-05-01, 12:00:00", "Operator: A, B"]
    source = write_table(tmp_path / "log.txt", ["u", "y"], [u, fir(u)], above=above, delimiter=delimiter)
    out = tmp_path / "rec.h5"
    summary_of(run_cli("import", source, "--fs", "1000", "-o", out, "--json"))
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.periods("u").ravel(), u)


def test_skip_rows_beyond_the_file_and_on_a_mat_file(run_cli, tmp_path):
    source = write_table(tmp_path / "short.csv", ["u"], [np.arange(5.0)])
    run_cli("import", source, "--skip-rows", "6", "--fs", "1", "-o", tmp_path / "rec.h5").assert_one_line_error(
        "--skip-rows 6", "short.csv has only 6 line(s)")
    mat = tmp_path / "x.mat"
    from scipy.io import savemat

    savemat(mat, {"u": np.arange(10.0)})
    run_cli("import", mat, "--skip-rows", "1", "--fs", "1", "-o", tmp_path / "rec.h5").assert_one_line_error(
        "--skip-rows 1", "applies to CSV/TSV files")


def test_two_header_like_lines_above_the_data_are_refused(run_cli, tmp_path):
    """A units row under the header (``t,u,y`` / ``s,V,V``): which is the header is not guessed."""
    rng = np.random.default_rng(5)
    u = multisine(rng)
    source = write_table(tmp_path / "two.csv", ["s", "V", "V"], [np.arange(u.size) / FS, u, u], above=["t,u,y"])
    run_cli("import", source, "-o", tmp_path / "rec.h5").assert_one_line_error(
        "two.csv:1", "lines 1 and 2 both look like the header (3 cells split at ',', no numbers)", "--skip-rows")
    assert not (tmp_path / "rec.h5").exists()


@pytest.mark.parametrize("above", [[], ["Axis1"]])
def test_units_row_under_the_header(run_cli, tmp_path, above):
    """An oscilloscope export: ``Time,Channel A,Channel B`` over ``(ms),(V),(mV)``, then an empty line."""
    rng = np.random.default_rng(14)
    u = multisine(rng)
    y = fir(u)
    source = write_table(tmp_path / "pico.csv", None, [np.arange(u.size) * 0.25, u, y],
                         above=above + ["Time,Channel A,Channel B", "(ms),(V),(mV)", ""])
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--u", "Channel A", "--y", "channel b", "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(4000.0, rel=1e-8) and summary["units"] == {"u": "V", "y": "mV"}
    assert summary["fs_from"] == f"time vector {source}:Time (ms)"
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.periods("y").ravel(), y)
    details = provenance_details(out)
    assert details["units_row"] == len(above) + 2 and details["ignored_columns"] == []


def test_units_in_header_cells(run_cli, tmp_path):
    """``u (N)`` and ``y [m/s^2]`` are found as u and y by default; their units are recorded."""
    rng = np.random.default_rng(6)
    u = multisine(rng)
    source = write_table(tmp_path / "units.csv", ["t", "u (N)", "y [m/s^2]"], [np.arange(u.size) / FS, u, fir(u)])
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    (run,) = read_runs(out)
    assert run.units == {"u": "N", "y": "m/s^2"} and summary["units"] == {"u": "N", "y": "m/s^2"}
    np.testing.assert_array_equal(run.periods("u").ravel(), u)
    assert summary_of(run_cli("import", source, "--u", "u", "--y", "Y", "-o", tmp_path / "again.h5", "--json"))["runs"] == 1


def test_units_of_numbered_realizations(run_cli, tmp_path):
    rng = np.random.default_rng(7)
    us = [multisine(rng) for _ in range(2)]
    columns = [us[0], fir(us[0]), us[1], fir(us[1])]
    source = write_table(tmp_path / "num.csv", ["u1 (V)", "y1 (mm)", "u2 (V)", "y2 (mm)"], columns)
    out = tmp_path / "rec.h5"
    summary_of(run_cli("import", source, "--fs", "1000", "-o", out, "--json"))
    assert [run.units for run in read_runs(out)] == [{"u": "V", "y": "mm"}] * 2

    bad = write_table(tmp_path / "mixed.csv", ["u1 (V)", "y1", "u2 (mV)", "y2"], columns)
    run_cli("import", bad, "--fs", "1000", "-o", tmp_path / "rec2.h5").assert_one_line_error(
        "mixed.csv", "the columns of u state different units ('u1 (V)', 'u2 (mV)')")


@pytest.mark.parametrize("unit, per_second", [("s", 1.0), ("ms", 1e3), ("us", 1e6), ("µs", 1e6), ("ns", 1e9),
                                               ("min", 1 / 60)])
def test_time_column_unit(run_cli, tmp_path, unit, per_second):
    """A time column in ``unit``: the samples are 0.5 ms apart, so fs = 2000 Hz whatever the unit."""
    rng = np.random.default_rng(8)
    u = multisine(rng)
    seconds = np.arange(u.size) / 2000.0
    source = write_table(tmp_path / "t.csv", [f"time ({unit})", "u", "y"], [seconds * per_second, u, fir(u)])
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    # times rounded to whole ns over 0.128 s: relative error of fs at most 1 ns / 0.1275 s < 1e-8
    assert summary["fs"] == pytest.approx(2000.0, rel=1e-8)
    assert summary["fs_from"] == f"time vector {source}:time ({unit})"
    assert provenance_details(out).get("time_unit") == unit


@pytest.mark.parametrize("title, fragments", [
    ("Time [fortnights]", ["t.csv:Time [fortnights]", "unknown time unit 'fortnights'", "s, ms, us (µs), ns, min"]),
    ("Ts (fortnights)", ["t.csv:Ts (fortnights)", "unknown unit 'fortnights' of a sampling interval",
                         "s, ms, us (µs), ns, min"]),
    ("fs (rpm)", ["t.csv:fs (rpm)", "unknown unit 'rpm' of a sample rate; units understood: Hz, kHz, MHz"]),
])
def test_unknown_unit_of_a_time_or_rate_column_is_refused(run_cli, tmp_path, title, fragments):
    u = multisine(np.random.default_rng(9))
    source = write_table(tmp_path / "t.csv", [title, "u"], [np.arange(1, u.size + 1), u])
    run_cli("import", source, "-o", tmp_path / "rec.h5").assert_one_line_error(*fragments)


@pytest.mark.parametrize("title, value, fs", [("Ts", 1e-3, 1000.0), ("Ts (s)", 5e-4, 2000.0), ("dt [ms]", 0.25, 4000.0),
                                              ("dt", 1 / 3000, 3000.0), ("Sampling interval (us)", 125.0, 8000.0)])
def test_sampling_interval_column(run_cli, tmp_path, title, value, fs):
    rng = np.random.default_rng(10)
    u = multisine(rng)
    interval = np.full(u.size, np.nan)
    interval[0] = value
    source = write_table(tmp_path / "ts.csv", [title, "u", "y"], [interval, u, fir(u)])
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(fs, rel=1e-12)
    assert summary["fs_from"] == f"sampling-interval column {source}:{title} (fs = 1/Ts)"
    assert read_runs(out)[0].fs == pytest.approx(fs, rel=1e-12)


def test_sampling_interval_checked_against_time_and_rate(run_cli, tmp_path):
    rng = np.random.default_rng(11)
    u = multisine(rng)
    t = np.arange(u.size) / FS
    good = write_table(tmp_path / "good.csv", ["t", "dt (ms)", "fs", "u", "y"],
                       [t, np.full(u.size, 1.0), np.full(u.size, FS), u, fir(u)])
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", good, "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(FS, rel=1e-12) and summary["ignored_columns"] == {str(good): []}
    details = provenance_details(out)
    assert details["rate_columns"] == ["dt (ms)", "fs"] and details["time_vector_fs"] == pytest.approx(FS, rel=1e-9)

    bad = write_table(tmp_path / "bad.csv", ["Ts", "fs", "u"], [np.full(u.size, 1e-3), np.full(u.size, 500.0), u])
    run_cli("import", bad, "-o", tmp_path / "rec2.h5").assert_one_line_error(
        "bad.csv", "the sampling-interval column 'Ts' gives 1000 Hz but the sample-rate column 'fs' 500 Hz")
    varying = write_table(tmp_path / "vary.csv", ["ts", "u"], [1.0 + t, u])
    run_cli("import", varying, "-o", tmp_path / "rec3.h5").assert_one_line_error(
        "vary.csv:ts", "the sampling interval varies", "or --time ts if it is a time vector")
    summary = summary_of(run_cli("import", varying, "--time", "ts", "-o", tmp_path / "rec4.h5", "--json"))
    assert summary["fs"] == pytest.approx(FS, rel=1e-9)


@pytest.mark.parametrize("delimiter, named", [(",", "','"), (";", "';'"), ("\t", "tab"), (" ", "whitespace")])
def test_row_of_another_width_names_the_delimiter(run_cli, tmp_path, delimiter, named):
    u = multisine(np.random.default_rng(12))
    source = write_table(tmp_path / "bad.txt", ["t", "u", "y"], [np.arange(u.size) / FS, u, u], delimiter=delimiter)
    lines = source.read_text().splitlines()
    lines[7] += delimiter + "1.5"
    source.write_text("\n".join(lines) + "\n")
    run_cli("import", source, "-o", tmp_path / "rec.h5").assert_one_line_error(
        "bad.txt:8", f"row has 4 cells, the header (line 1) has 3 (split at {named})")


def test_decimal_commas_are_named_with_the_delimiter(run_cli, tmp_path):
    """``1,5;2,25`` split at ';' leaves cells with decimal commas: the message says so."""
    u = multisine(np.random.default_rng(13))
    source = write_table(tmp_path / "eu.csv", ["u", "y"], [u, u], delimiter=";")
    source.write_text(source.read_text().replace(".", ","))
    run_cli("import", source, "--fs", "1000", "-o", tmp_path / "rec.h5").assert_one_line_error(
        "eu.csv:2", "column 'u': cell", "is not a number (cells split at ';'); decimal commas are not read")


# --- every column accounted for, over random header layouts -------------------------------------

ROWS = 7


@st.composite
def layouts(draw):
    """A header layout and its columns: (header cell, samples, what the reader must make of it), with
    the expected title of each column and, per signal, its realizations in order."""
    realizations = draw(st.integers(1, 4))
    signals = ["u"] + [key for key in ("y", "r") if draw(st.booleans())]
    styles = ["numbered", "group", "repeated"] + (["single"] if realizations == 1 else [])
    repeated = draw(st.sampled_from(styles)) == "repeated"
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    blocks: list[list[tuple[str, np.ndarray, str, str | int]]] = []  # (cell, values, role, title)
    truth: dict[str, list[np.ndarray]] = {key: [] for key in signals}
    numbered_truth: dict[str, dict[int, np.ndarray]] = {key: {} for key in signals}
    for key in signals:
        style = "repeated" if repeated else draw(st.sampled_from([s for s in styles if s != "repeated"]))
        unit = draw(st.sampled_from(["", " (V)", " [m/s^2]"]))
        data = [rng.normal(size=ROWS) for _ in range(realizations)]
        if style in ("single", "repeated"):
            blocks += [[(key + unit, x, key, key + unit)] for x in data]
        elif style == "numbered":
            blocks += [[(f"{key}{m}{unit}", x, key, f"{key}{m}{unit}")] for m, x in enumerate(data, start=1)]
            numbered_truth[key] = dict(enumerate(data, start=1))
        else:
            titles = [key + unit] if realizations == 1 else [f"{key}{unit} #{k}" for k in range(1, realizations + 1)]
            blocks.append([(key + unit if k == 0 else "", x, key, titles[k]) for k, x in enumerate(data)])
    step = np.arange(ROWS) / FS
    first_only = np.where(np.arange(ROWS) == 0, FS, np.nan)
    extras = {"time": [("t", step, "time", "t")], "time ms": [("time (ms)", step * 1e3, "time", "time (ms)")],
              "fs": [("fs", first_only, "rate", "fs")], "Ts": [("Ts (ms)", np.full(ROWS, 1.0), "rate", "Ts (ms)")],
              "CH7": [("CH7", rng.normal(size=ROWS), "ignored", "CH7")],
              "group x": [("x" if k == 0 else "", rng.normal(size=ROWS), "ignored", f"x #{k + 1}") for k in range(3)],
              "empty": [("", np.full(ROWS, np.nan), "ignored", None)]}
    chosen = draw(st.lists(st.sampled_from(sorted(extras)), unique=True))
    if "time" in chosen and "time ms" in chosen:
        chosen.remove("time ms")
    blocks += [extras[name] for name in chosen]
    order = draw(st.permutations(range(len(blocks))))
    lead = [("", rng.normal(size=ROWS), "ignored", None) for _ in range(draw(st.integers(0, 2)))]
    # empty columns beyond a header that ends before them (a delimiter ending each row)
    unheaded = [("", np.full(ROWS, np.nan), "ignored", None) for _ in range(draw(st.integers(0, 2)))]
    columns = lead + [column for i in order for column in blocks[i]] + unheaded
    for key in signals:  # repeated cells pair in column order; numbered columns in number order
        truth[key] = ([numbered_truth[key][m] for m in sorted(numbered_truth[key])] if numbered_truth[key] else
                      [x for cell_, x, role, _ in columns if role == key])
    titles = [title if title is not None else j + 1 for j, (_, _, _, title) in enumerate(columns)]
    preamble = draw(st.booleans()) and len(columns) >= 2
    return columns, titles, truth, realizations, preamble, len(unheaded)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(layouts())
def test_every_column_is_imported_or_listed_as_ignored(layout):
    columns, titles, truth, realizations, preamble, unheaded = layout
    header = [c for c, _, _, _ in columns][: len(columns) - unheaded]
    with tempfile.TemporaryDirectory() as folder:
        path = write_table(Path(folder) / "layout.csv", header, [x for _, x, _, _ in columns],
                           above=["Axis1", "Date: 2024-05-01"] if preamble else [])
        source = read_csv(path, {"u": "u", "y": "y", "r": "r"}, None, {"y", "r"}, fs_given=False,
                          defaulted=frozenset({"u", "y", "r"}))
    details = source.details
    imported = []
    for key, value in details["columns"].items():
        imported += value if isinstance(value, list) else [value]
    imported += details.get("rate_columns", [])
    assert Counter(imported) + Counter(details["ignored_columns"]) == Counter(titles), (titles, details)
    assert not set(imported) & set(details["ignored_columns"])
    expected_ignored = [title for title, (_, _, role, _) in zip(titles, columns) if role == "ignored"]
    assert details["ignored_columns"] == expected_ignored
    assert set(source.arrays) == set(truth)
    for key, parts in truth.items():
        got = np.atleast_2d(source.arrays[key])
        assert got.shape == (realizations, ROWS)
        np.testing.assert_array_equal(got, np.vstack(parts))
    if details.get("rate_columns"):
        assert source.fs == pytest.approx(FS, rel=1e-12)
    if source.time is not None:
        np.testing.assert_allclose(source.time, np.arange(ROWS) / FS, rtol=1e-15, atol=1e-18)
    assert ("preamble_lines" in details) == preamble
