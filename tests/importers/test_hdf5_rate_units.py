"""The unit of an HDF5 sample rate given apart from its name: an attribute ``units`` (or ``unit``)
of a rate dataset, or ``NAME_units`` / ``NAME_unit`` / ``NAMEUnits`` beside a rate attribute
``NAME``. Hz, kHz, MHz for a rate; s, ms, us, µs for an interval. Applied and stated in ``fs_from``,
kept in ``details.rate_units``; an unknown unit, or one that contradicts the unit in the name, is
refused in one line; ``--fs`` overrides it. Every file is written here with h5py; the expected rate
is the value written times the unit's factor, computed here.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from generators import assert_refused
from nlsid.io.hdf5_recording import HDF5Recording

N = 300


def write(path: Path, attributes: dict[str, dict[str, object]],
          datasets: dict[str, tuple[object, dict]] | None = None) -> None:
    """/daq/u and /daq/y (noise), ``datasets`` (path -> (value, its attributes)) and ``attributes``
    (object path -> {name: value})."""
    rng = np.random.default_rng(11)
    with h5py.File(path, "w") as handle:
        handle["daq/u"] = rng.standard_normal(N)
        handle["daq/y"] = rng.standard_normal(N)
        for name, (value, attrs) in (datasets or {}).items():
            handle[name] = value
            handle[name].attrs.update(attrs)
        for holder, attrs in attributes.items():
            handle[holder].attrs.update(attrs)


def run(run_cli, path: Path, *options: str):
    out = path.with_name("rec.h5")
    return run_cli("import", path, "--u", "/daq/u", "--y", "/daq/y", "-o", out, "--json", *options), out


@pytest.mark.parametrize("attributes, datasets, fs, said, key", [
    ({"/daq": {"fs": 2.5, "fs_units": "kHz"}}, None, 2500.0,
     "attribute fs of group /daq of {path}, in kHz (attribute fs_units)", "/daq@fs"),
    ({"/": {"Fs": 0.125, "FsUnits": np.bytes_("MHz")}}, None, 125000.0,
     "file attribute Fs of {path}, in MHz (attribute FsUnits)", "/@Fs"),
    ({"/daq/u": {"dt": 250.0, "dt_unit": "us"}}, None, 4000.0,
     "attribute dt of dataset /daq/u of {path}, in us (attribute dt_unit)", "/daq/u@dt"),
    ({"/daq": {"Ts": 500.0, "Ts_units": "\u00b5s"}}, None, 2000.0,
     "attribute Ts of group /daq of {path}, in \u00b5s (attribute Ts_units)", "/daq@Ts"),
    ({}, {"/daq/fs": (4.0, {"units": "kHz"})}, 4000.0,
     "dataset /daq/fs of {path}, in kHz (its attribute units)", "/daq/fs"),
    ({}, {"/daq/Ts": (0.5, {"Unit": np.bytes_("ms")})}, 2000.0,
     "dataset /daq/Ts of {path}, in ms (its attribute Unit)", "/daq/Ts"),
    ({}, {"/daq/fs_kHz": (2.0, {"units": "kHz"})}, 2000.0,
     "dataset /daq/fs_kHz of {path}, in kHz (its attribute units)", "/daq/fs_kHz"),
])
def test_a_unit_attribute_scales_the_rate(run_cli, tmp_path, attributes, datasets, fs, said, key):
    path = tmp_path / "daq.h5"
    write(path, attributes, datasets)
    result, out = run(run_cli, path)
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    # kHz/MHz scale exactly; an interval gives 1/(value x 1e-6 or 1e-3), one rounding
    assert summary["fs"] == pytest.approx(fs, rel=4e-16)
    assert summary["fs_from"] == said.format(path=path)
    unit = said.split(", in ")[1].split(" ")[0]
    with HDF5Recording(out) as rec:
        assert rec.provenance["import"]["details"]["rate_units"] == {key: unit}


def test_a_rate_without_a_unit_attribute_stays_in_hz(run_cli, tmp_path):
    path = tmp_path / "daq.h5"
    write(path, {"/daq": {"fs": 2500.0, "note_units": "kHz"}})  # a unit of something else
    result, out = run(run_cli, path)
    assert result.exit_code == 0 and result.json()["fs"] == 2500.0
    with HDF5Recording(out) as rec:
        assert "rate_units" not in rec.provenance["import"]["details"]


@pytest.mark.parametrize("attributes, datasets, fragments", [
    ({"/daq": {"fs": 2.5, "fs_units": "furlongs"}}, None,
     ["attribute fs of group /daq of", "unit 'furlongs' (attribute fs_units) is not a unit of a sample rate",
      "Hz, kHz", "MHz"]),
    ({"/daq": {"fs": 2.5, "fs_units": "mhz"}}, None,
     ["unit 'mhz' (attribute fs_units) is not a unit of a sample rate"]),
    ({}, {"/daq/Ts": (0.5, {"units": "kHz"})},
     ["dataset /daq/Ts of", "unit 'kHz' (its attribute units) is not a unit of a sample interval", "ms"]),
    ({}, {"/daq/fs_kHz": (2.0, {"units": "Hz"})},
     ["dataset /daq/fs_kHz of", "is named in kHz but its attribute units says Hz"]),
])
def test_an_unknown_or_contradicting_unit_is_refused(run_cli, tmp_path, attributes, datasets, fragments):
    path = tmp_path / "daq.h5"
    write(path, attributes, datasets)
    result, _ = run(run_cli, path)
    assert_refused(result, tmp_path, path, *fragments, "pass --fs HZ")


def test_fs_overrides_an_unknown_unit(run_cli, tmp_path):
    path = tmp_path / "daq.h5"
    write(path, {"/daq": {"fs": 2.5, "fs_units": "furlongs"}})
    result, _ = run(run_cli, path, "--fs", "100")
    assert result.exit_code == 0 and result.json()["fs"] == 100.0
