"""Integer samples (16-bit loggers write int16) are read as float64, exactly, by every reader.

HDF5 datasets of any integer type and byte order, and numbers of foreign MCAP topics, become
float64 arrays holding the same values (every int16 and int32 is a float64 exactly); the nlsid MCAP
layout stores float64 blocks, so integer runs round-trip through it as their float64 values.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from nlsid.io.recording import read_runs, write_recording

FS, N, P = 256.0, 256, 3
BINS = np.arange(1, 40, 2)


def _counts(seed: int, full_scale: int = 20000) -> np.ndarray:
    """One multisine period as ADC counts, repeated P times (transient period included)."""
    spectrum = np.zeros(N // 2 + 1, complex)
    spectrum[BINS] = np.exp(1j * np.random.default_rng(seed).uniform(0, 2 * np.pi, BINS.size))
    period = np.fft.irfft(spectrum, n=N)
    return np.tile(np.round(full_scale * period / np.abs(period).max()), P)


def _write_int_recording(path) -> dict:
    """Two realizations with u int16, y big-endian int16 and r int32, as a 16-bit logger writes them."""
    written = {}
    with h5py.File(path, "w") as f:
        f.attrs["nlsid_format"], f.attrs["nlsid_format_version"] = "recording", 1
        for m in range(2):
            u = _counts(m)
            signals = {"u": u.astype(np.int16), "y": (u // 2 + 7).astype(">i2"), "r": (3 * u).astype(np.int32)}
            group = f.create_group(f"runs/ms_m{m}")
            group.attrs.update({"fs": FS, "kind": "multisine", "period": N, "transient_periods": 1,
                                "realization": m, "level": 1.0, "excited_bins": BINS})
            for name, data in signals.items():
                group.create_dataset(name, data=data)
            written[f"ms_m{m}"] = signals
    return written


def test_hdf5_integer_datasets_are_read_as_float64_exactly(tmp_path):
    path = tmp_path / "logger.h5"
    written = _write_int_recording(path)
    with h5py.File(path) as f:  # the file really holds integers
        assert f["runs/ms_m0/u"].dtype == np.int16 and f["runs/ms_m0/y"].dtype == np.dtype(">i2")
    for run in read_runs(path):
        for name in ("u", "y", "r"):
            signal = getattr(run, name)
            assert signal.dtype == np.float64
            assert np.array_equal(signal, written[run.run_id][name].astype(np.int64))
        assert run.u.min() < -10000 and run.u.max() > 10000  # int16 counts, not rescaled


def test_integer_recording_feeds_bla_and_its_numbers_are_those_of_the_counts(run_cli, tmp_path):
    path = tmp_path / "logger.h5"
    written = _write_int_recording(path)
    info = run_cli("info", path, "--json")
    assert info.exit_code == 0, info.stderr
    assert info.json()["stages"]["bla"] == {"feeds": True, "reason": None,
                                            "notes": ["--method auto uses the reference method (r) for level 1"]}
    result = run_cli("-q", "bla", path, "-o", tmp_path / "bla.h5", "--method", "io", "--json")
    assert result.exit_code == 0, result.stderr
    (level,) = result.json()["levels"]
    steady = np.concatenate([written[k]["u"][N:].astype(np.float64) for k in sorted(written)])
    assert level["u_rms"] == pytest.approx(np.sqrt(np.mean(steady**2)), rel=1e-12)
    # y = u // 2 + 7 counts: |G| is 1/2 (-6.02 dB) up to the rounding of u // 2
    assert abs(level["bla_db"] - 20 * np.log10(0.5)) < 0.01


def test_integer_runs_round_trip_through_the_mcap_layout_as_float64(tmp_path):
    _write_int_recording(tmp_path / "logger.h5")
    runs = read_runs(tmp_path / "logger.h5")
    write_recording(tmp_path / "logger.mcap", runs)
    back = read_runs(tmp_path / "logger.mcap")
    for a, b in zip(runs, back):
        for name in ("u", "y", "r"):
            assert getattr(b, name).dtype == np.float64
            assert getattr(a, name).tobytes() == getattr(b, name).tobytes()


def test_foreign_mcap_integer_numbers_are_read_as_float64(tmp_path):
    from mcap.writer import Writer

    u = np.random.default_rng(1).integers(-32768, 32768, 500)
    path = tmp_path / "adc.mcap"
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start(profile="", library="test-logger")
        channel = writer.register_channel("/adc", "json", writer.register_schema("S", "jsonschema", b"{}"))
        for k, value in enumerate(u):
            t = 1_000_000 * k
            writer.add_message(channel, t, json.dumps({"counts": int(value), "y": int(value) // 3}).encode(), t)
        writer.finish()
    (run,) = read_runs(path, mapping={"u": "/adc:counts", "y": "/adc:y"})
    assert run.u.dtype == np.float64 and run.y.dtype == np.float64
    assert np.array_equal(run.u, u) and np.array_equal(run.y, u // 3)
