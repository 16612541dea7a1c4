"""Bad sources for ``nlsid import``: one clear line naming the file and the problem, exit 2, nothing written."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mcap.writer import Writer
from scipy.io import savemat

GOOD = [f"{0.001 * k:.3f},{np.sin(k / 3):.6f},{np.cos(k / 3):.6f}" for k in range(40)]


def assert_refused(result, tmp_path, source, *fragments) -> None:
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("nlsid: error: "), lines
    assert "Traceback" not in result.stderr and result.stdout == ""
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == [source.name], "nothing written"


def csv_source(tmp_path, rows: list[str], name: str = "bad.csv"):
    path = tmp_path / name
    path.write_text("\n".join(["t,u,y", *rows]) + "\n")
    return path


@pytest.mark.parametrize("rows, fragments", [
    (GOOD[:5] + ["0.005,1.0"] + GOOD[6:], ["bad.csv:7", "row has 2 cells, the header (line 1) has 3"]),
    (GOOD[:9] + ["0.009,abc,1.0"] + GOOD[10:], ["bad.csv:11", "column 'u': cell 'abc' is not a number"]),
    (GOOD[:20] + [f"{0.0205:.4f}" + GOOD[20][5:]] + GOOD[21:], ["bad.csv:t", "timestamps are not uniformly sampled"]),
])
def test_bad_csv(run_cli, tmp_path, rows, fragments):
    source = csv_source(tmp_path, rows)
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source, *fragments)


def test_csv_unknown_column_lists_the_columns(run_cli, tmp_path):
    source = csv_source(tmp_path, GOOD)
    result = run_cli("import", source, "--y", "CH2", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "--y CH2", "no column 'CH2'; columns are 't', 'u', 'y' or numbers 1..3")


def test_csv_without_a_sample_rate(run_cli, tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("u,y\n" + "\n".join(f"{k},{k}" for k in range(10)) + "\n")
    assert_refused(run_cli("import", path, "-o", tmp_path / "rec.h5"), tmp_path, path, "pass --fs HZ or --time NAME")


def test_mat_missing_variable_lists_the_variables(run_cli, tmp_path):
    source = tmp_path / "bad.mat"
    savemat(source, {"input": np.ones(10), "output": np.ones(10)})
    result = run_cli("import", source, "--u", "input", "--y", "out", "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "bad.mat", "no variable 'out'; variables: input, output")


def test_mat_matrices_of_inconsistent_size(run_cli, tmp_path):
    source = tmp_path / "bad.mat"
    savemat(source, {"u": np.ones((100, 4)), "y": np.ones((100, 3))})
    result = run_cli("import", source, "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "matrices of inconsistent size", "bad.mat:u is 100 samples x 4 record(s)",
                   "bad.mat:y is 100 samples x 3 record(s)")


def test_hdf5_missing_dataset_lists_the_datasets(run_cli, tmp_path):
    source = tmp_path / "bad.h5"
    with h5py.File(source, "w") as handle:
        handle["daq/ch0"] = np.ones(10)
        handle["daq/ch1"] = np.ones(10)
    result = run_cli("import", source, "--u", "/daq/ch0", "--y", "/daq/ch9", "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "'/daq/ch9' does not exist; datasets in the file: /daq/ch0, /daq/ch1")


@pytest.fixture
def mcap_source(tmp_path):
    path = tmp_path / "log.mcap"
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start(profile="", library="test-logger")
        channels = {t: writer.register_channel(t, "json", 0) for t in ("/cmd", "/joint")}
        for k in range(20):
            for topic, obj in (("/cmd", {"effort": k}), ("/joint", {"state": {"position": k}})):
                writer.add_message(channels[topic], k * 1_000_000, json.dumps(obj).encode(), k * 1_000_000)
        writer.finish()
    return path


def test_mcap_missing_topic_lists_the_topics(run_cli, tmp_path, mcap_source):
    result = run_cli("import", mcap_source, "--u", "/nope:effort", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, mcap_source, "no topic '/nope'; topics in the file: /cmd, /joint")


def test_mcap_missing_field_lists_the_fields(run_cli, tmp_path, mcap_source):
    result = run_cli("import", mcap_source, "--u", "/cmd:effort", "--y", "/joint:state.pos", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, mcap_source, "field 'state.pos' not found: fields in state are position")


def sine_csv(tmp_path, samples: int):
    """A CSV with one column u: a sine of period 100 samples."""
    source = tmp_path / "sine.csv"
    u = np.sin(2 * np.pi * np.arange(samples) / 100)
    source.write_text("u\n" + "\n".join(f"{v:.17g}" for v in u) + "\n")
    return source


def test_given_period_that_does_not_fit(run_cli, tmp_path):
    source = sine_csv(tmp_path, 2000)
    result = run_cli("import", source, "--fs", "100", "--period", "99", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "sine.csv:u", "not periodic with the given period of 99 samples")


def test_too_many_transient_periods(run_cli, tmp_path):
    source = sine_csv(tmp_path, 400)
    result = run_cli("import", source, "--fs", "100", "--transient-periods", "4", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "--transient-periods", "4 leaves no steady period")


def test_unknown_kind_of_file(run_cli, tmp_path):
    source = tmp_path / "data.xyz"
    source.write_bytes(b"\x00\x01")
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source, "unknown kind of file")


def test_existing_output_is_kept(run_cli, tmp_path):
    source = csv_source(tmp_path, GOOD, name="good.csv")
    out = tmp_path / "rec.h5"
    out.write_bytes(b"precious")
    result = run_cli("import", source, "-o", out)
    assert result.exit_code == 2 and "pass --force" in result.stderr and out.read_bytes() == b"precious"
