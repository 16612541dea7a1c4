"""Runs with several inputs and outputs (recording format version 3): a 2x2 round trip in HDF5 and
MCAP, runs with one input and one output still written as version 2, the attributes of older
files ignored, and bad ``inputs``/``outputs`` refused in one message naming the run and attribute."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from nlsid.errors import InputError
from nlsid.io.recording import open_recording, read_runs, write_recording
from nlsid.io.run import Run

FS = 500.0
PERIOD = 32


def _run_2x2(run_id: str = "e0", seed: int = 0) -> Run:
    """Two inputs (u, u2) and two outputs (y, y2) of three periods, an unrelated channel d beside them."""
    rng = np.random.default_rng(seed)
    n = 3 * PERIOD
    channels = {"u2": rng.standard_normal(n), "y2": rng.standard_normal(n), "d": rng.standard_normal(n)}
    return Run(run_id, FS, "multisine", rng.standard_normal(n), y=rng.standard_normal(n), period=PERIOD,
               excited_bins=np.array([1, 2, 5]), realization=seed, channels=channels,
               units={"u": "N", "u2": "N", "y": "m", "y2": "m"}, inputs=("u", "u2"), outputs=("y", "y2"))


@pytest.mark.parametrize("suffix", ["h5", "mcap"])
def test_2x2_round_trip(tmp_path, suffix):
    runs = [_run_2x2("e0", 0), _run_2x2("e1", 1)]
    path = write_recording(tmp_path / f"rec.{suffix}", runs)
    with open_recording(path) as recording:
        assert recording.version == 3
        back = list(recording)
    for a, b in zip(runs, back):
        assert b.inputs == ("u", "u2") and b.outputs == ("y", "y2")
        assert sorted(b.channels) == ["d", "u2", "y2"]  # the channel that is neither is kept
        u = np.stack([a.u, a.channels["u2"]])
        y = np.stack([a.y, a.channels["y2"]])
        assert b.input_matrix().shape == (2, 3 * PERIOD)
        np.testing.assert_array_equal(b.input_matrix(), u)
        np.testing.assert_array_equal(b.output_matrix(), y)
        np.testing.assert_array_equal(b.channels["d"], a.channels["d"])
        assert b.units == a.units


def test_single_input_output_stays_version_2(tmp_path):
    siso = _run_2x2()
    siso.inputs, siso.outputs = ("u",), ("y",)
    path = write_recording(tmp_path / "rec.h5", [siso])
    with h5py.File(path) as f:
        assert f.attrs["nlsid_format_version"] == 2
        assert "inputs" not in f["runs/e0"].attrs and "outputs" not in f["runs/e0"].attrs
    (back,) = read_runs(path)
    np.testing.assert_array_equal(back.input_matrix(), back.u[None, :])
    np.testing.assert_array_equal(back.output_matrix(), back.y[None, :])


def test_names_in_a_version_2_file_are_ignored(tmp_path):
    path = write_recording(tmp_path / "rec.h5", [_run_2x2()])
    with h5py.File(path, "a") as f:
        f.attrs["nlsid_format_version"] = 2
    (back,) = read_runs(path)
    assert back.inputs == ("u",) and back.outputs == ("y",)
    assert sorted(back.channels) == ["d", "u2", "y2"]


@pytest.mark.parametrize("inputs, outputs, key, message", [
    (["u2", "u"], ["y"], "inputs", "the first of the inputs must be 'u'"),
    (["u", "nope"], ["y"], "inputs", "'nope' is not a channel of the run (channels: d, u2, y2)"),
    (["u", "u2"], ["y", "u2"], "outputs", "'u2' is named twice"),
    (["u", "u2", "u2"], ["y"], "inputs", "'u2' is named twice"),
    (["u"], ["y2"], "outputs", "the first of the outputs must be 'y'"),
    (["u", "r"], ["y"], "inputs", "'r' is not a channel of the run"),
])
def test_bad_names_refused_by_reader(tmp_path, inputs, outputs, key, message):
    path = write_recording(tmp_path / "rec.h5", [_run_2x2()])
    with h5py.File(path, "a") as f:
        f["runs/e0"].attrs["inputs"] = np.array(inputs, dtype=h5py.string_dtype())
        f["runs/e0"].attrs["outputs"] = np.array(outputs, dtype=h5py.string_dtype())
    with pytest.raises(InputError) as err:
        read_runs(path)
    assert f"rec.h5:/runs/e0.{key}" in str(err.value) and message in str(err.value)


def test_names_not_text_refused(tmp_path):
    path = write_recording(tmp_path / "rec.h5", [_run_2x2()])
    with h5py.File(path, "a") as f:
        f["runs/e0"].attrs["inputs"] = np.array([1, 2])
    with pytest.raises(InputError, match=r"rec.h5:/runs/e0.inputs: expected a non-empty list of names"):
        read_runs(path)


@pytest.mark.parametrize("suffix", ["h5", "mcap"])
def test_writer_refuses_unknown_input_and_writes_nothing(tmp_path, suffix):
    run = _run_2x2()
    run.inputs = ("u", "u3")
    with pytest.raises(InputError, match=r"/runs/e0.inputs: 'u3' is not a channel of the run"):
        write_recording(tmp_path / f"rec.{suffix}", [run])
    assert not (tmp_path / f"rec.{suffix}").exists()
