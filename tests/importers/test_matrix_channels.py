"""``nlsid import`` of a matrix variable given whole as a channel: one channel per record.

A benchmark's ``Acceleration`` of 3 x N (three sensors) beside a vector ``Force`` is imported with
``--channel acc=Acceleration`` as the channels ``acc_0``, ``acc_1``, ``acc_2`` (record i as
``Acceleration[i]`` picks it: the slice across the shorter axis, so an N x 3 matrix gives its
columns). Given as u or y, the same matrix would be several inputs or outputs (MIMO), which are u
or y and channels named with --inputs/--outputs: refused in one line that names its shape and the
ways out.

Every file is written here (scipy.io.savemat, h5py); the signals are white noise, so each record is
one ``arbitrary`` run holding every sample unchanged: each channel must equal the matrix record the
test wrote, bit for bit.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from generators import assert_refused
from nlsid.io.hdf5_recording import HDF5Recording
from nlsid.io.recording import read_runs

N = 500
FS = 250.0


def noise(seed: int, *shape: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=shape or (N,))


def write(path, kind: str, variables: dict) -> None:
    if kind == "mat":
        savemat(path, variables)
        return
    with h5py.File(path, "w") as handle:
        for name, value in variables.items():
            handle[name] = value


def records(matrix: np.ndarray) -> list[np.ndarray]:
    """The records of a matrix as the test defines them: rows of 3 x N, columns of N x 3."""
    return list(matrix) if matrix.shape[0] < matrix.shape[1] else list(matrix.T)


@pytest.mark.parametrize("kind", ["mat", "hdf5"])
@pytest.mark.parametrize("transposed", [False, True], ids=["3xN", "Nx3"])
def test_a_matrix_channel_becomes_one_channel_per_record(run_cli, tmp_path, kind, transposed):
    force, y = noise(1), noise(2)
    acc = noise(3, 3, N)
    acc = acc.T if transposed else acc
    source = tmp_path / ("bench.mat" if kind == "mat" else "bench.h5")
    write(source, kind, {"Force": force, "y": y, "Acceleration": acc, "fs": FS})
    out = tmp_path / "rec.h5"
    result = run_cli("import", source, "--u", "Force", "--channel", "acc=Acceleration", "--unit", "acc=m/s^2",
                     "-o", out, "--json")
    assert result.exit_code == 0, (result.stderr, result.exception)
    summary = result.json()
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.u, force)
    np.testing.assert_array_equal(run.y, y)
    assert sorted(run.channels) == ["acc_0", "acc_1", "acc_2"]
    for i, record in enumerate(records(acc)):
        np.testing.assert_array_equal(run.channels[f"acc_{i}"], record)
    assert summary["channels"] == ["acc_0", "acc_1", "acc_2"]
    assert summary["units"] == {"acc_0": "m/s^2", "acc_1": "m/s^2", "acc_2": "m/s^2"}
    shape = "500x3" if transposed else "3x500"
    (note,) = [note for note in summary["notes"] if "--channel acc=Acceleration" in note]
    assert f"Acceleration is {shape}, 3 records of {N} samples" in note
    assert "acc_0 = Acceleration[0], acc_1 = Acceleration[1], acc_2 = Acceleration[2]" in note
    with HDF5Recording(out) as rec:
        prov = rec.provenance["import"]
    key = "variables" if kind == "mat" else "datasets"
    assert prov["details"][key]["channels.acc_2"] == "Acceleration[2]"
    assert prov["signals"]["channels.acc_1"] == f"{source}:Acceleration[1]"
    assert "ignored_variables" not in prov["details"]  # no record left behind
    # the text summary says it too
    text = run_cli("import", source, "--u", "Force", "--channel", "acc=Acceleration", "-o", out, "--force")
    assert text.exit_code == 0 and "channels acc_0, acc_1, acc_2" in text.stdout + text.stderr


@pytest.mark.parametrize("kind", ["mat", "hdf5"])
@pytest.mark.parametrize("option", ["--u", "--y"])
def test_a_matrix_as_input_or_output_is_refused_naming_the_ways_out(run_cli, tmp_path, kind, option):
    source = tmp_path / ("bench.mat" if kind == "mat" else "bench.h5")
    write(source, kind, {"Force": noise(4), "Acceleration": noise(5, N, 3), "fs": FS})
    other = "--y" if option == "--u" else "--u"
    result = run_cli("import", source, option, "Acceleration", other, "Force", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, f"Acceleration is {N} samples x 3 record(s)",
                   f"{option} Acceleration: several inputs or outputs (MIMO) are u or y and channels, listed with --inputs",
                   f"{option} Acceleration[0] (records 0..2",
                   "all of them as channels Acceleration_0 .. Acceleration_2: --channel Acceleration=Acceleration")


def test_a_record_channel_name_given_twice_is_refused(run_cli, tmp_path):
    source = tmp_path / "bench.mat"
    savemat(source, {"u": noise(6), "Acceleration": noise(7, 3, N), "fs": FS})
    result = run_cli("import", source, "--channel", "acc=Acceleration", "--channel", "acc_1=u", "-o",
                     tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "--channel acc=Acceleration", "imported as the channels acc_0 .. acc_2",
                   "a channel acc_1 is given too")


def test_a_matrix_channel_beside_realizations_of_its_shape_stays_their_records(run_cli, tmp_path):
    # u and y of 2 x N are two realizations side by side: a 2 x N channel pairs with them, record by record
    u, y, d = noise(8, 2, N), noise(9, 2, N), noise(10, 2, N)
    source = tmp_path / "pairs.mat"
    savemat(source, {"u": u, "y": y, "d": d, "fs": FS})
    out = tmp_path / "rec.h5"
    result = run_cli("import", source, "--channel", "d=d", "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    runs = read_runs(out)
    assert [run.run_id for run in runs] == ["pairs_c00", "pairs_c01"]
    for c, run in enumerate(runs):
        np.testing.assert_array_equal(run.channels["d"], d[c])
