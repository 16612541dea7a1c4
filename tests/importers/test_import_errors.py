"""Bad sources for ``nlsid import``: one clear line naming the file and the problem, exit 2, nothing written."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mcap.writer import Writer
from scipy.io import savemat

from generators import assert_refused

GOOD = [f"{0.001 * k:.3f},{np.sin(k / 3):.6f},{np.cos(k / 3):.6f}" for k in range(40)]


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


def table(tmp_path, header: list[str], columns: list[list[str]], name: str = "bad.csv"):
    """A CSV from a header and cell columns of equal length."""
    path = tmp_path / name
    path.write_text("\n".join([",".join(header)] + [",".join(row) for row in zip(*columns)]) + "\n")
    return path


def cells(k: int, rows: int = 40) -> list[str]:
    return [f"{np.sin(n / (3 + k)):.6f}" for n in range(rows)]


@pytest.mark.parametrize("header, fragments", [
    (["t", "u1", "y1", "u2", "y2", "u3"], ["do not pair into realizations", "u: 'u1', 'u2', 'u3'; y: 'y1', 'y2'"]),
    (["t", "u1", "u2", "y"], ["do not pair into realizations", "u: 'u1', 'u2'; y: 'y'"]),
    (["t", "u1", "y1", "u2", "y3"], ["do not pair into realizations", "u: 'u1', 'u2'; y: 'y1', 'y3'"]),
    (["t", "u", "u", "y"], ["do not pair into realizations", "u: 'u', 'u'; y: 'y'"]),
    (["t", "u1", "y2"], ["do not pair into realizations", "u: 'u1'; y: 'y2'"]),
    (["t", "u", "u", "y1", "y2"], ["do not pair into realizations", "u: 'u', 'u'; y: 'y1', 'y2'"]),
    (["t", "u", "u2", "y"], ["--u u: ambiguous: a column 'u' and the numbered columns 'u2'", "pass --u u for the one column"]),
    (["t", "u1", "u2", "y", "y2"], ["--y y: ambiguous: a column 'y' and the numbered columns 'y2'"]),
    (["t", "u1", "U_1", "y"], ["--u u: columns 'u1' and 'U_1' both have number 1"]),
])
def test_csv_columns_that_do_not_pair(run_cli, tmp_path, header, fragments):
    time = [f"{0.001 * k:.3f}" for k in range(40)]
    source = table(tmp_path, header, [time] + [cells(k) for k in range(len(header) - 1)])
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source, "bad.csv", *fragments)


@pytest.mark.parametrize("header, args", [(["t", "u", "u2", "y"], ["--u", "u"]), (["t", "u", "y", "y2"], [])])
def test_csv_one_column_where_it_is_no_question(run_cli, tmp_path, header, args):
    """An explicit --u u takes the one column; a second sensor y2 beside one input u is not a realization."""
    time = [f"{0.001 * k:.3f}" for k in range(40)]
    source = table(tmp_path, header, [time, cells(0), cells(1), cells(2)], name="ok.csv")
    from nlsid.io.hdf5_recording import HDF5Recording

    result = run_cli("import", source, *args, "-o", tmp_path / "rec.h5", "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["run_ids"] == ["ok"] and result.json()["signals"] == ["u", "y"]
    with HDF5Recording(tmp_path / "rec.h5") as recording:
        assert recording.provenance["import"]["details"]["columns"] == {"u": "u", "y": "y", "time": "t"}


@pytest.mark.parametrize("rate, time, fragments", [
    (["1000"] * 20 + ["2000"] * 20, None, ["bad.csv:fs", "the sample rate varies: 1000 on line 2, 2000 on line 22"]),
    (["1000"] * 10 + ["abc"] + [""] * 29, None, ["bad.csv:12", "column 'fs': cell 'abc' is not a sample rate"]),
    (["-5"] + [""] * 39, None, ["bad.csv:2", "cell '-5' is not a sample rate (a number > 0, in Hz)"]),
    ([""] * 40, None, ["bad.csv:fs", "the sample-rate column holds no value"]),
    (["1000"] * 40, [f"{0.002 * k:.3f}" for k in range(40)],
     ["the sample-rate column 'fs' says 1000 Hz but the time vector", "gives 500 Hz"]),
])
def test_csv_bad_sample_rate_column(run_cli, tmp_path, rate, time, fragments):
    header, columns = ["fs", "u", "y"], [rate, cells(0), cells(1)]
    if time is not None:
        header, columns = ["time"] + header, [time] + columns
    source = table(tmp_path, header, columns)
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source, *fragments)


def test_csv_samples_too_large_to_be_measured(run_cli, tmp_path):
    source = csv_source(tmp_path, GOOD[:7] + ["0.007,1e200,1.0"] + GOOD[8:])
    assert_refused(run_cli("import", source, "-o", tmp_path / "rec.h5"), tmp_path, source,
                   "bad.csv:u", "1 samples of magnitude above 1e+100 (largest 1e+200)")


@pytest.mark.parametrize("content, fragment", [
    (b"u,y\n1,2\n3,4\n", "not a MATLAB file (no MAT-file header"),
    (b"", "not a MATLAB file"),
    (b"MATLAB 5.0 MAT-file, Platform: GLNXA64", "truncated MAT-file header (38 of 128 bytes)"),
    (b"MATLAB 5.0 MAT-file".ljust(126) + b"XX", "damaged MAT-file header (no endian indicator IM or MI"),
])
def test_mat_that_is_not_matlab(run_cli, tmp_path, content, fragment):
    source = tmp_path / "data.mat"
    source.write_bytes(content)
    result = run_cli("import", source, "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "data.mat", fragment)


def test_mat_truncated_data(run_cli, tmp_path):
    source = tmp_path / "cut.mat"
    savemat(source, {"u": np.sin(np.arange(400) / 7.0), "y": np.cos(np.arange(400) / 7.0)})
    source.write_bytes(source.read_bytes()[:-1000])
    # 128-byte header; each variable: tag (8) + flags (16) + dims (16) + name (8) + data tag (8) + 3200
    # bytes = 8 + 3248; y starts at 128 + 8 + 3248 = 3384; the cut file holds 6640 - 1000 bytes
    result = run_cli("import", source, "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "cut.mat", "truncated or damaged MAT-file: the variable at byte 3384 "
                   "claims 3248 bytes, the file holds 2248 after its tag")


def test_mat_that_crashes_scipy_is_refused(run_cli, tmp_path):
    """A data element of reserved type 8 where u's doubles are: scipy's compiled reader dereferences
    a missing dtype and the interpreter dies (SIGSEGV); read in a child process, it is one line."""
    source = tmp_path / "crash.mat"
    savemat(source, {"u": np.sin(np.arange(400) / 7.0)})
    data = bytearray(source.read_bytes())
    # 128-byte header; miMATRIX tag (8), array flags (16), dimensions (16), name 'u' (small, 8)
    assert data[176:184] == (9).to_bytes(4, "little") + (400 * 8).to_bytes(4, "little")  # miDOUBLE, 3200 bytes
    data[176] = 8
    source.write_bytes(bytes(data))
    result = run_cli("import", source, "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "crash.mat", "scipy's MAT-file reader crashed on it, signal")


def test_mat_v4_header_with_sizes_beyond_the_file(run_cli, tmp_path):
    """A v4 file (no header; five int32 per variable) whose first variable claims 10^6 x 10^3 doubles."""
    source = tmp_path / "old4.mat"
    savemat(source, {"u": np.ones(10)}, format="4")
    data = bytearray(source.read_bytes())
    assert data[:20] == np.array([0, 1, 10, 0, 2], dtype="<i4").tobytes()  # MOPT 0 (little-endian doubles), 1 x 10, "u"
    data[4:12] = np.array([10 ** 6, 10 ** 3], dtype="<i4").tobytes()
    source.write_bytes(bytes(data))
    result = run_cli("import", source, "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "old4.mat", "truncated or damaged MAT-file (v4): the variable at byte 0 "
                   "(1000000 x 1000) needs 8000000000 bytes of data, the file holds 80")


def test_mat_array_of_a_class_matlab_does_not_have(run_cli, tmp_path):
    source = tmp_path / "odd.mat"
    savemat(source, {"u": np.sin(np.arange(400) / 7.0)})
    data = bytearray(source.read_bytes())
    # after the 128-byte header and the miMATRIX tag: the array flags element (miUINT32, 8 bytes),
    # whose first byte is the class (6: double); MATLAB's classes end at 17
    assert data[136:145] == (6).to_bytes(4, "little") + (8).to_bytes(4, "little") + bytes([6])
    data[144] = 18
    source.write_bytes(bytes(data))
    result = run_cli("import", source, "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "odd.mat", "cannot read as a MATLAB file (an array of a class MATLAB does not have)")


def test_mat_struct_with_field_names_of_length_zero(run_cli, tmp_path):
    source = tmp_path / "zero.mat"
    savemat(source, {"data": {"y": np.ones(10), "t": np.arange(10.0)}})
    data = bytearray(source.read_bytes())
    # header (128), miMATRIX tag (8), flags (16), dims (16), name 'data' (small element, 8), then the
    # field name length as a small int32 element: type 5, 4 bytes, value 2 (one letter and its NUL)
    assert data[168:184] == b"\x01\x00\x04\x00data" + b"\x05\x00\x04\x00\x02\x00\x00\x00"
    data[180] = 0  # scipy divides the field names' bytes by this length
    source.write_bytes(bytes(data))
    result = run_cli("import", source, "--u", "data.y", "--fs", "10", "-o", tmp_path / "rec.h5")
    assert_refused(result, tmp_path, source, "zero.mat", "cannot read as a MATLAB file (a damaged count or index: "
                   "ZeroDivisionError: integer division or modulo by zero)")
