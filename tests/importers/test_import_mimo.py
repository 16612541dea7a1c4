"""``nlsid import --inputs/--outputs``: one input and three outputs (a force and three
accelerations, as in a ground vibration test) in one recording, listed by ``nlsid info``; bad
names refused in one line with nothing written.

The CSV is written here from white noise with ``repr`` of each float, so the record is one
``arbitrary`` run and every sample must come back bit for bit in the output matrix.
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import assert_refused
from nlsid.io.recording import read_runs

N = 400
FS = 250.0


def write_csv(path) -> np.ndarray:
    """Columns F, A1, A2, A3 of white noise; returns them as a (4, N) array."""
    data = np.random.default_rng(7).normal(size=(4, N))
    lines = ["F,A1,A2,A3"] + [",".join(repr(float(x)) for x in row) for row in data.T]
    path.write_text("\n".join(lines) + "\n")
    return data


ONE_BY_THREE = ("--u", "F", "--y", "A1", "--channel", "a2=A2", "--channel", "a3=A3", "--fs", str(FS))


def test_one_input_three_outputs_in_one_recording(run_cli, tmp_path, monkeypatch):
    source = tmp_path / "gvt.csv"
    data = write_csv(source)
    out = tmp_path / "rec.h5"
    result = run_cli("import", source, *ONE_BY_THREE, "--outputs", "y,a2,a3", "-o", out, "--json")
    assert result.exit_code == 0, (result.stderr, result.exception)
    summary = result.json()
    assert summary["inputs"] == ["u"] and summary["outputs"] == ["y", "a2", "a3"]
    (run,) = read_runs(out)
    assert run.kind == "arbitrary" and run.inputs == ("u",) and run.outputs == ("y", "a2", "a3")
    np.testing.assert_array_equal(run.input_matrix(), data[:1])
    np.testing.assert_array_equal(run.output_matrix(), data[1:])

    listed = run_cli("info", out, "--json").json()["runs"][0]
    assert listed["inputs"] == ["u"] and listed["outputs"] == ["y", "a2", "a3"]
    monkeypatch.setenv("COLUMNS", "200")  # the table in full, one row a line
    table = run_cli("info", out)
    assert table.exit_code == 0
    lines = table.stderr.splitlines()
    header = [cell.strip() for cell in next(line for line in lines if "┃ run" in line).split("┃")]
    body = [line.split("│") for line in lines[[i for i, line in enumerate(lines) if line.startswith("┡")][0] + 1:]]
    body = body[:next(i for i, cells in enumerate(body) if len(cells) == 1)]  # to the table's end
    assert header[-3:-1] == ["inputs", "outputs"]
    columns = [[cells[k].strip() for cells in body if cells[k].strip()] for k in (-3, -2)]
    assert columns == [["u"], ["y", "a2", "a3"]]


def test_single_output_import_lists_the_defaults(run_cli, tmp_path):
    source = tmp_path / "gvt.csv"
    write_csv(source)
    out = tmp_path / "rec.h5"
    assert run_cli("import", source, *ONE_BY_THREE, "-o", out).exit_code == 0
    listed = run_cli("info", out, "--json").json()["runs"][0]
    assert listed["inputs"] == ["u"] and listed["outputs"] == ["y"]
    assert "outputs" not in run_cli("info", out).stderr  # no column for one input and one output


@pytest.mark.parametrize("extra, fragments", [
    (("--outputs", "y,a4"), ("--outputs y,a4", "'a4' is not a channel of the run (channels: a2, a3)")),
    (("--outputs", "a2,y"), ("--outputs a2,y", "the first of the outputs must be 'y'")),
    (("--inputs", "u,a2", "--outputs", "y,a2"), ("--outputs y,a2", "'a2' is named twice")),
    (("--outputs", "y,,a2"), ("--outputs", "expected comma-separated names")),
])
def test_bad_names_refused_in_one_line(run_cli, tmp_path, extra, fragments):
    source = tmp_path / "gvt.csv"
    write_csv(source)
    result = run_cli("import", source, *ONE_BY_THREE, *extra, "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, *fragments)
