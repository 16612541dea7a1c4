"""The HDF5 recording format: files written by plain h5py (as a lab would) are read, and ours round-trip."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from nlsid.errors import InputError
from nlsid.io.recording import open_recording, read_runs, write_recording
from nlsid.io.run import Run


def test_plain_h5py_file_with_matlab_style_types(tmp_path):
    """A file written with plain h5py, with doubles where ints are meant and bytes strings, is accepted."""
    path = tmp_path / "lab.h5"
    n = np.arange(4 * 100)
    with h5py.File(path, "w") as f:
        f.attrs["nlsid_format"] = np.bytes_(b"recording")
        f.attrs["nlsid_format_version"] = 1.0
        run = f.create_group("runs/level_1")
        run.attrs.update({"fs": 1000, "kind": b"multisine", "period": 100.0, "transient_periods": np.int32(1),
                          "excited_bins": [1.0, 3.0], "params": json.dumps({"K_fc": 0.12}), "level": 0.5})
        u = np.sin(2 * np.pi * n / 100).astype(np.float32)
        run.create_dataset("u", data=u).attrs["unit"] = "V"
        run.create_dataset("y", data=(2 * u).astype(np.int16))
    (r,) = read_runs(path)
    assert r.fs == 1000.0 and r.period == 100 and r.transient_periods == 1 and r.n_periods == 3
    assert r.params == {"K_fc": 0.12} and r.units == {"u": "V"}
    assert r.excited_bins.dtype == np.int64 and list(r.excited_bins) == [1, 3]
    assert r.u.dtype == np.float64 and r.periods("y").shape == (3, 100)


def make_run(i: int, with_r: bool = False) -> Run:
    rng = np.random.default_rng(i)
    u = rng.standard_normal(3 * 50)
    return Run(run_id=f"run_{i}", fs=200.0, kind="multisine", u=u, y=rng.standard_normal(150),
               r=rng.standard_normal(150) if with_r else None, period=50, transient_periods=1,
               realization=i, level=0.3, excited_bins=np.array([1, 2, 7]), params={"K_fc": 0.1 * i},
               units={"u": "V", "y": "m"})


def test_round_trip_is_exact(tmp_path):
    runs = [make_run(0), make_run(1, with_r=True)]
    path = write_recording(tmp_path / "rec.h5", runs, provenance={"tool": "nlsid"})
    with open_recording(path) as rec:
        assert rec.format == "recording" and rec.provenance == {"tool": "nlsid"}
        back = list(rec)
    for a, b in zip(runs, back):
        for name in ("u", "y", "r"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None and y is None) or np.array_equal(x, y)
        assert a.attrs().keys() == b.attrs().keys()
        assert all(np.array_equal(a.attrs()[k], b.attrs()[k]) for k in a.attrs())
        assert a.units == b.units


def test_excitation_is_refused_where_output_is_needed(tmp_path):
    run = make_run(0)
    run.y = None
    path = write_recording(tmp_path / "exc.h5", [run])
    with pytest.raises(InputError, match="excitation without measured output y"):
        read_runs(path)
    assert read_runs(path, require_y=False)[0].y is None


def test_periods_view(tmp_path):
    run = make_run(3)
    assert np.array_equal(run.periods("u")[1], run.u[100:150])


def test_samples_read_below_h5py_are_what_h5py_reads(tmp_path):
    """Datasets of numbers are read with h5py's low-level calls (nlsid.io.hdf5_recording._dataset):
    the values and type of ``group[name][()]``, whatever the byte order, width or shape; anything
    else (a scalar, an empty dataspace, strings, booleans, complex numbers) is read by h5py itself,
    and a group where a dataset belongs is refused."""
    from nlsid.io.hdf5_recording import _dataset

    path = tmp_path / "types.h5"
    with h5py.File(path, "w") as f:
        group = f.create_group("run")
        for dtype in ("<f8", ">f8", "<f4", "f2", ">i2", "<u1", "<i8", ">u4"):
            group.create_dataset(f"x{dtype}", data=np.arange(-3, 5).astype(dtype))
        group.create_dataset("matrix", data=np.ones((2, 3)))
        group.create_dataset("none", data=np.zeros(0))
        group.create_dataset("scalar", data=3.0)
        group.create_dataset("empty", data=h5py.Empty("f8"))
        group.create_dataset("strings", data=np.array([b"a", b"b"]))
        group.create_dataset("flags", data=np.array([True, False]))
        group.create_dataset("complex", data=np.array([1 + 2j]))
        group.create_dataset("v", data=np.arange(3.0)).attrs["unit"] = "V"
        group.create_dataset("m", data=np.arange(3.0)).attrs["unit"] = b"m"
        group.create_group("folder")
    with h5py.File(path, "r") as f:
        group, units = f["run"], {}
        for name in group:
            if name == "folder":
                with pytest.raises(InputError, match="run/folder: expected a dataset"):
                    _dataset(group, name, "run/folder", units)
                continue
            ours, theirs = _dataset(group, name, f"run/{name}", units), group[name][()]
            if isinstance(theirs, h5py.Empty):
                assert isinstance(ours, h5py.Empty)
                continue
            assert np.asarray(ours).dtype.str == np.asarray(theirs).dtype.str, name
            assert np.shape(ours) == np.shape(theirs) and np.array_equal(ours, theirs), name
        assert units == {"v": "V", "m": "m"}
