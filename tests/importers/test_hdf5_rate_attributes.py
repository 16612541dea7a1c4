"""The sample rate of a plain HDF5 file from attributes: ``fs``, ``Fs``, ``sample_rate`` (Hz), ``Ts``,
``dt`` (s), ``dt_ms`` (ms) on an imported dataset, on a group holding it, or on the file. Stated as a
rate dataset is (``fs_from``), kept in provenance (``details.rate_attributes``), checked against the
rate datasets, the time vector and each other (a conflict refused naming both sources), overridden by
``--fs``. Every file is written here with h5py; rates, names and samples are compared with what the
test wrote.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from nlsid.io.hdf5_recording import HDF5Recording
from nlsid.io.recording import read_runs

N = 400


def write(path: Path, attributes: dict[str, dict[str, object]], datasets: dict[str, np.ndarray] | None = None) -> dict:
    """/daq/u and /daq/y (noise: an arbitrary record), further ``datasets``, and ``attributes``: object
    path ('/', '/daq', '/daq/u', ...) -> {name: value}. Returns the signals written."""
    rng = np.random.default_rng(7)
    u = rng.standard_normal(N)
    signals = {"u": u, "y": np.convolve(u, [0.6, 0.2])[:N]}
    with h5py.File(path, "w") as handle:
        for key, value in signals.items():
            handle[f"daq/{key}"] = value
        for name, value in (datasets or {}).items():
            handle[name] = value
        for holder, attrs in attributes.items():
            for name, value in attrs.items():
                handle[holder].attrs[name] = value
    return signals


def imported(run_cli, path: Path, *options: str) -> tuple[dict, Path]:
    out = path.with_name(path.stem + "_rec.h5")
    result = run_cli("import", path, "--u", "/daq/u", "--y", "/daq/y", "-o", out, "--json", *options)
    assert result.exit_code == 0, result.stderr
    return result.json(), out


def provenance_details(out: Path) -> dict:
    with HDF5Recording(out) as rec:
        return rec.provenance["import"]["details"]


@pytest.mark.parametrize("holder, name, value, fs, kind", [
    ("/daq", "fs", 2000.0, 2000.0, "group /daq"),
    ("/", "Fs", 1500.0, 1500.0, None),
    ("/daq/u", "sample_rate", 4800.0, 4800.0, "dataset /daq/u"),
    ("/daq/y", "Ts", 2.5e-4, 4000.0, "dataset /daq/y"),
    ("/daq", "dt", 1e-3, 1000.0, "group /daq"),
    ("/daq", "dt_ms", 0.5, 2000.0, "group /daq"),
])
def test_rate_attribute_gives_fs(run_cli, tmp_path, holder, name, value, fs, kind):
    path = tmp_path / "logger.h5"
    signals = write(path, {holder: {name: value}})
    summary, out = imported(run_cli, path)
    assert summary["fs"] == pytest.approx(fs, rel=1e-12)
    label = f"file attribute {name} of {path}" if kind is None else f"attribute {name} of {kind} of {path}"
    assert summary["fs_from"] == label
    assert provenance_details(out)["rate_attributes"] == {f"{holder}@{name}": value}
    (run,) = read_runs(out)
    assert run.fs == pytest.approx(fs, rel=1e-12)
    np.testing.assert_array_equal(run.u, signals["u"])
    np.testing.assert_array_equal(run.y, signals["y"])


def test_attributes_that_agree_and_a_text_time_stamp(run_cli, tmp_path):
    """fs on the file, Ts on the group (1/Ts within 1e-3 of it) and a text attribute ``ts`` (a time
    stamp, not a rate): fs from the file's rate in Hz; both rates kept, the text one not."""
    path = tmp_path / "agree.h5"
    write(path, {"/": {"fs": 1000.0, "ts": "2024-05-01T10:00:00"}, "/daq": {"Ts": 1.0005e-3}})
    summary, out = imported(run_cli, path)
    assert summary["fs"] == 1000.0 and summary["fs_from"] == f"file attribute fs of {path}"
    assert provenance_details(out)["rate_attributes"] == {"/daq@Ts": 1.0005e-3, "/@fs": 1000.0}


@pytest.mark.parametrize("attributes, datasets, first, second", [
    ({"/daq": {"fs": 1000.0}, "/daq/u": {"Ts": 2e-3}}, {},
     "the attribute fs of group /daq of {path} says 1000 Hz", "the attribute Ts of dataset /daq/u of {path} gives 500 Hz"),
    ({"/": {"fs": 2000.0}}, {"daq/fs": 1000.0},
     "the dataset /daq/fs of {path} says 1000 Hz", "the file attribute fs of {path} gives 2000 Hz"),
])
def test_conflicting_rates_are_refused_naming_both(run_cli, tmp_path, attributes, datasets, first, second):
    path = tmp_path / "conflict.h5"
    write(path, attributes, datasets)
    out = tmp_path / "no.h5"
    run_cli("import", path, "--u", "/daq/u", "--y", "/daq/y", "-o", out).assert_one_line_error(
        first.format(path=path), second.format(path=path), "must agree within 0.001", "pass --fs HZ")
    assert not out.exists()


def test_time_vector_checked_against_the_attribute_and_fs_overrides_it(run_cli, tmp_path):
    path = tmp_path / "timed.h5"
    write(path, {"/daq": {"fs": 1000.0}}, {"daq/t": np.arange(N) / 500.0})
    run_cli("import", path, "--u", "/daq/u", "--y", "/daq/y", "--time", "/daq/t",
            "-o", tmp_path / "no.h5").assert_one_line_error(
        f"the attribute fs of group /daq of {path} says 1000 Hz but the time vector {path}:/daq/t gives 500 Hz")
    summary, out = imported(run_cli, path, "--fs", "500")
    assert summary["fs"] == 500.0 and summary["fs_from"] == "--fs"
    assert provenance_details(out)["overridden_fs"] == {"value": 1000.0,
                                                        "from": f"attribute fs of group /daq of {path}"}
