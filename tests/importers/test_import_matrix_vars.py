"""``nlsid import`` of MATLAB and HDF5 files as benchmark data sets ship them: one record of a matrix
variable picked with ``NAME[i]``, the sample rate from a variable such as ``Fs`` or ``Ts``, and the
variables not imported listed in provenance.

Every file is written here (scipy.io.savemat for v5, h5py for plain HDF5 and for a MATLAB v7.3
stand-in: HDF5 with the 512-byte MATLAB header, arrays column-major). The signals are white noise,
so each record is imported as one ``arbitrary`` run holding every sample unchanged: the run's
samples must equal the chosen row of the source exactly.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy import sparse
from scipy.io import savemat

from generators import assert_refused
from nlsid.io.hdf5_recording import HDF5Recording
from nlsid.io.recording import read_runs

N = 600


def noise(seed: int, *shape: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=shape or (N,))


def write_mat73(path, variables: dict, structs: dict[str, dict] | None = None) -> None:
    """A MATLAB v7.3 file as MATLAB writes it: HDF5 with a 512-byte header, arrays column-major
    (h5py sees them transposed), a struct as a group."""
    with h5py.File(path, "w", userblock_size=512) as handle:
        groups = [(handle, variables)]
        for name, fields in (structs or {}).items():
            group = handle.create_group(name)
            group.attrs["MATLAB_class"] = np.bytes_("struct")
            groups.append((group, fields))
        for group, content in groups:
            for name, value in content.items():
                dataset = group.create_dataset(name, data=np.atleast_2d(np.asarray(value, dtype=np.float64)).T)
                dataset.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as handle:
        handle.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 .")


def imported(result, out) -> tuple[dict, list, dict]:
    """The --json summary, the runs written and the provenance's ``import`` entry."""
    assert result.exit_code == 0, (result.stderr, result.exception)
    with HDF5Recording(out) as rec:
        prov = rec.provenance["import"]
    return result.json(), read_runs(out), prov


def test_mat_v5_row_of_a_matrix_with_fs_from_the_file(run_cli, tmp_path):
    force, acc = noise(1), noise(2, 3, N)
    source = tmp_path / "bench.mat"
    savemat(source, {"Force": force, "Acceleration": acc, "Fs": 750.0, "gain": 2.5, "note": "rig B",
                     "mask": sparse.eye(4, format="csc")})
    out = tmp_path / "rec.h5"
    summary, runs, prov = imported(run_cli("import", source, "--u", "Force", "--y", "Acceleration[1]",
                                           "--channel", "a2=Acceleration[2]", "-o", out, "--json"), out)
    (run,) = runs
    np.testing.assert_array_equal(run.u, force)
    np.testing.assert_array_equal(run.y, acc[1])
    np.testing.assert_array_equal(run.channels["a2"], acc[2])
    assert summary["fs"] == 750.0 and summary["fs_from"] == f"variable Fs of {source}" and run.fs == 750.0
    assert prov["signals"]["y"] == f"{source}:Acceleration[1]"
    assert prov["details"]["rate_variables"] == {"Fs": 750.0}
    assert prov["details"]["ignored_variables"] == {
        "Acceleration[0]": f"{N} samples (record 0 of Acceleration, 3x{N})", "gain": "scalar 2.5", "note": "text",
        "mask": "sparse 4x4"}


def test_mat_v73_struct_field_column_picked_along_matlabs_shape(run_cli, tmp_path):
    # MATLAB N x 3: time runs down the rows, so data.acc[2] is MATLAB's column 3
    u, acc = noise(3), noise(4, N, 3)
    source = tmp_path / "new.mat"
    write_mat73(source, {"u": u}, structs={"data": {"acc": acc, "Ts": 1 / 2048}})
    out = tmp_path / "rec.h5"
    summary, (run,), prov = imported(run_cli("import", source, "--y", "data.acc[2]", "-o", out, "--json"), out)
    np.testing.assert_array_equal(run.y, acc[:, 2])
    np.testing.assert_array_equal(run.u, u)
    # 1/2048 is a power of two: its reciprocal is exact
    assert summary["format"] == "mat v7.3" and summary["fs"] == 2048.0
    assert summary["fs_from"] == f"variable data.Ts of {source}"
    assert prov["details"]["ignored_variables"] == {
        f"data.acc[{i}]": f"{N} samples (record {i} of data.acc, {N}x3)" for i in (0, 1)}


def test_hdf5_dataset_row_and_ignored_datasets(run_cli, tmp_path):
    u, acc = noise(5), noise(6, 2, N)
    source = tmp_path / "daq.h5"
    with h5py.File(source, "w") as handle:
        handle["daq/u"] = u
        handle["daq/acc"] = acc
        handle["daq/fs"] = 400.0
        handle["daq/temperature"] = noise(7, 20)
        handle["setup/serial"] = np.bytes_("SN-17")
    out = tmp_path / "rec.h5"
    summary, (run,), prov = imported(run_cli("import", source, "--u", "/daq/u", "--y", "daq/acc[1]", "-o", out,
                                             "--json"), out)
    np.testing.assert_array_equal(run.y, acc[1])
    assert summary["fs"] == 400.0 and summary["fs_from"] == f"dataset /daq/fs of {source}"
    assert prov["details"]["ignored_variables"] == {
        "/daq/acc[0]": f"{N} samples (record 0 of /daq/acc, 2x{N})", "/daq/temperature": "20", "/setup/serial": "text"}


def test_hdf5_dataset_whose_name_ends_in_brackets_is_taken_whole(run_cli, tmp_path):
    u, y = noise(8), noise(9)
    source = tmp_path / "odd.h5"
    with h5py.File(source, "w") as handle:
        handle["u"] = u
        handle["y[1]"] = y
    out = tmp_path / "rec.h5"
    _, (run,), _ = imported(run_cli("import", source, "--y", "y[1]", "--fs", "10", "-o", out, "--json"), out)
    np.testing.assert_array_equal(run.y, y)


@pytest.mark.parametrize("name, value, fs", [
    ("fs", 1000.0, 1000.0), ("Fs", 1000.0, 1000.0), ("FS", 1000.0, 1000.0), ("fsample", 512.0, 512.0),
    ("SampleRate", 48000.0, 48000.0), ("sample_rate", 8.0, 8.0), ("SamplingFrequency", 100.0, 100.0),
    ("fs_kHz", 2.5, 2500.0), ("Ts", 0.25, 4.0), ("ts", 0.001, 1000.0), ("dt", 1 / 3, 3.0), ("Dt", 0.5, 2.0),
    ("Ts_s", 0.125, 8.0), ("dt_ms", 2.0, 500.0), ("SampleTime", 0.01, 100.0),
])
def test_sample_rate_variable_names(run_cli, tmp_path, name, value, fs):
    source = tmp_path / "rate.mat"
    savemat(source, {"u": noise(10), "y": noise(11), name: value})
    out = tmp_path / "rec.h5"
    summary, (run,), _ = imported(run_cli("import", source, "-o", out, "--json"), out)
    # an interval gives 1/Ts, rounded once: within one unit in the last place
    assert summary["fs"] == pytest.approx(fs, rel=4e-16) and run.fs == summary["fs"]
    assert summary["fs_from"] == f"variable {name} of {source}"


def test_interval_repeated_on_every_sample_is_one_rate(run_cli, tmp_path):
    source = tmp_path / "rep.mat"
    savemat(source, {"u": noise(12), "y": noise(13), "Ts": np.full(N, 0.5)})
    out = tmp_path / "rec.h5"
    summary, _, _ = imported(run_cli("import", source, "-o", out, "--json"), out)
    assert summary["fs"] == 2.0


@pytest.mark.parametrize("name, value, fragments", [
    ("fs", 0.0, ["variable fs of", "sample rate 0: expected a finite number > 0"]),
    ("Fs", -100.0, ["variable Fs of", "sample rate -100: expected a finite number > 0"]),
    ("Ts", np.inf, ["variable Ts of", "sample interval inf: expected a finite number > 0"]),
    ("fs", np.nan, ["variable fs of", "sample rate nan: expected a finite number > 0"]),
    ("dt", np.linspace(0.1, 0.2, N), ["variable dt of", f"holds {N} different values: not one rate"]),
])
def test_bad_sample_rate_variable_is_refused(run_cli, tmp_path, name, value, fragments):
    source = tmp_path / "bad.mat"
    savemat(source, {"u": noise(14), "y": noise(15), name: value})
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source, *fragments)


def test_fs_option_overrides_the_rate_variable_even_a_bad_one(run_cli, tmp_path):
    source = tmp_path / "over.mat"
    savemat(source, {"u": noise(16), "y": noise(17), "Fs": 100.0})
    out = tmp_path / "rec.h5"
    summary, _, prov = imported(run_cli("import", source, "--fs", "250", "-o", out, "--json"), out)
    assert summary["fs"] == 250.0 and summary["fs_from"] == "--fs"
    assert prov["details"]["overridden_fs"] == {"value": 100.0, "from": f"variable Fs of {source}"}
    savemat(source, {"u": noise(16), "y": noise(17), "Fs": 0.0})
    summary, _, prov = imported(run_cli("import", source, "--fs", "250", "-o", out, "--json", "--force"), out)
    assert summary["fs"] == 250.0 and "overridden_fs" not in prov["details"]


def test_time_vector_and_rate_variable_must_agree(run_cli, tmp_path):
    source = tmp_path / "both.mat"
    t = np.arange(N) / 1000.0
    savemat(source, {"u": noise(18), "y": noise(19), "t": t, "Fs": 1000.0})
    out = tmp_path / "rec.h5"
    summary, _, prov = imported(run_cli("import", source, "--time", "t", "-o", out, "--json"), out)
    # fs from the ends of t (599 intervals of 1 ms as rounded in float64): well within 1e-12
    assert summary["fs"] == pytest.approx(1000.0, rel=1e-12) and summary["fs_from"] == f"time vector {source}:t"
    assert prov["details"]["rate_variable_fs"] == 1000.0
    (tmp_path / "rec.h5").unlink()
    savemat(source, {"u": noise(18), "y": noise(19), "t": t, "Fs": 1002.0})  # 2e-3 off: beyond 1e-3
    assert_refused(run_cli("import", source, "--time", "t", "-o", tmp_path / "rec.h5"), tmp_path, source,
                   "the variable Fs of", "says 1002 Hz but the time vector", "gives 1000 Hz",
                   "must agree within 0.001")


def test_two_rate_variables_that_disagree_are_refused(run_cli, tmp_path):
    source = tmp_path / "two.mat"
    savemat(source, {"u": noise(20), "y": noise(21), "Fs": 1000.0, "Ts": 1 / 1000.0})
    out = tmp_path / "rec.h5"
    summary, _, _ = imported(run_cli("import", source, "-o", out, "--json"), out)
    assert summary["fs"] == 1000.0 and summary["fs_from"] == f"variable Fs of {source}"  # the rate, not 1/Ts
    out.unlink()
    savemat(source, {"u": noise(20), "y": noise(21), "Fs": 1000.0, "Ts": 1 / 500.0})
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source,
                   "the variable Fs of", "says 1000 Hz but the variable Ts of", "gives 500 Hz")


def test_rate_variable_next_to_the_signals_comes_first(run_cli, tmp_path):
    source = tmp_path / "runs.mat"
    savemat(source, {"run1": {"u": noise(22), "y": noise(23), "fs": 200.0},
                     "run2": {"u": noise(24), "y": noise(25), "fs": 300.0}})
    out = tmp_path / "rec.h5"
    summary, _, prov = imported(run_cli("import", source, "--u", "run2.u", "--y", "run2.y", "-o", out, "--json"), out)
    assert summary["fs"] == 300.0 and summary["fs_from"] == f"variable run2.fs of {source}"
    assert prov["details"]["ignored_variables"] == {"run1.u": f"{N}", "run1.y": f"{N}", "run1.fs": "scalar 200"}


def test_no_sample_rate_lists_the_scalars(run_cli, tmp_path):
    source = tmp_path / "none.mat"
    savemat(source, {"u": noise(26), "y": noise(27), "N": float(N), "rate_hz": 1000.0})
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source,
                   "no sample rate: pass --fs HZ or --time NAME",
                   f"scalar variables in the file: N = {N}, rate_hz = 1000")


@pytest.mark.parametrize("option, name", [("--y", "Acceleration[3]"), ("--channel", "a=Acceleration[7]")])
def test_index_out_of_range(run_cli, tmp_path, option, name):
    source = tmp_path / "bench.mat"
    savemat(source, {"u": noise(28), "Acceleration": noise(29, 3, N)})
    result = run_cli("import", source, option, name, "--fs", "100", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, f"{option} {name}", f"Acceleration is 3x{N}",
                   f"3 record(s) of {N} samples", "out of range, valid 0..2")


def test_index_of_an_array_of_three_dimensions(run_cli, tmp_path):
    source = tmp_path / "cube.h5"
    with h5py.File(source, "w") as handle:
        handle["u"] = noise(30)
        handle["cube"] = noise(31, 2, 3, N)
    result = run_cli("import", source, "--y", "/cube[1]", "--fs", "100", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "--y /cube[1]", f"/cube has shape 2x3x{N}")


def test_matrix_signal_with_a_vector_input_is_refused_with_the_choice(run_cli, tmp_path):
    source = tmp_path / "bench.mat"
    savemat(source, {"Force": noise(32), "Acceleration": noise(33, 3, N), "Fs": 100.0})
    result = run_cli("import", source, "--u", "Force", "--y", "Acceleration", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "matrices of inconsistent size",
                   f"bench.mat:Force is {N} samples x 1 record(s)", f"bench.mat:Acceleration is {N} samples x 3 record(s)",
                   "--y Acceleration: several inputs or outputs (MIMO) are u or y and channels, listed with --inputs",
                   "all of them as channels Acceleration_0 .. Acceleration_2: --channel Acceleration=Acceleration",
                   "--y Acceleration[0]", "--channel Acceleration_1=Acceleration[1]",
                   "--channel Acceleration_2=Acceleration[2]")


def test_hdf5_channel_matrix_beside_realizations_of_another_count_is_refused(run_cli, tmp_path):
    source = tmp_path / "daq.h5"
    with h5py.File(source, "w") as handle:
        handle["u"] = noise(34, 2, N)  # two realizations side by side
        handle["y"] = noise(35, 2, N)
        handle["daq/acc"] = noise(36, N, 6)  # time down the rows: 6 records
    result = run_cli("import", source, "--channel", "a=/daq/acc", "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "/daq/acc is 600 samples x 6 record(s)", "--channel a=/daq/acc[0]",
                   "(records 0..5;", "--channel acc_3=/daq/acc[3] ...")
    assert "all of them as channels" not in result.stderr  # not beside realizations of u and y


def test_matrices_of_one_shape_stay_records_side_by_side(run_cli, tmp_path):
    u, y = noise(37, 2, N), noise(38, 2, N)
    source = tmp_path / "pairs.mat"
    savemat(source, {"u": u, "y": y, "fs": 50.0})
    out = tmp_path / "rec.h5"
    summary, runs, prov = imported(run_cli("import", source, "-o", out, "--json"), out)
    assert summary["run_ids"] == ["pairs_c00", "pairs_c01"] and summary["fs"] == 50.0
    for c, run in enumerate(runs):
        np.testing.assert_array_equal(run.u, u[c])
        np.testing.assert_array_equal(run.y, y[c])
    assert "ignored_variables" not in prov["details"]


def test_time_and_signal_as_rows_of_one_matrix(run_cli, tmp_path):
    # a logger's [t; y] block: row 0 the time in seconds (fs 500 Hz), row 1 the samples
    u, y = noise(39), noise(40)
    source = tmp_path / "block.mat"
    savemat(source, {"u": u, "TY": np.vstack([np.arange(N) / 500.0, y])})
    out = tmp_path / "rec.h5"
    summary, (run,), prov = imported(run_cli("import", source, "--time", "TY[0]", "--y", "TY[1]", "-o", out,
                                             "--json"), out)
    np.testing.assert_array_equal(run.y, y)
    # fs from the ends of the time row: 599 intervals of 2 ms as rounded in float64, well within 1e-12
    assert summary["fs"] == pytest.approx(500.0, rel=1e-12) and summary["fs_from"] == f"time vector {source}:TY[0]"
    assert "ignored_variables" not in prov["details"]


def test_rate_in_the_signals_struct_comes_before_the_top_level(run_cli, tmp_path):
    source = tmp_path / "nested.mat"
    savemat(source, {"fs": 1000.0, "slow": {"u": noise(41), "y": noise(42), "Ts": 0.01}})
    out = tmp_path / "rec.h5"
    summary, _, prov = imported(run_cli("import", source, "--u", "slow.u", "--y", "slow.y", "-o", out, "--json"), out)
    assert summary["fs"] == pytest.approx(100.0, rel=4e-16) and summary["fs_from"] == f"variable slow.Ts of {source}"
    assert prov["details"]["ignored_variables"] == {"fs": "scalar 1000"}
