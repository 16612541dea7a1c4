"""``nlsid import`` end to end: foreign files of known structure, metadata stripped, imported and checked.

Every source is built here from explicit cosine sums with a known period, lines, lead-in and
realization boundaries; the written recording must hold exactly those runs, the samples of the
source unchanged (float64 written as %.18e text round-trips exactly), and provenance naming the
source, its SHA-256 and what was inferred or overridden.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from generators.mcap_cases import write_json_mcap  # noqa: E402

from nlsid.io.hdf5_recording import HDF5Recording  # noqa: E402
from nlsid.io.recording import read_runs  # noqa: E402

FS = 1000.0
N = 256
BINS = np.arange(1, 60, 2)  # an odd multisine on bins 1, 3, ..., 59


def period_of(rng: np.random.Generator, bins: np.ndarray = BINS, period: int = N) -> np.ndarray:
    n = np.arange(period)[:, None]
    phases = rng.uniform(0, 2 * np.pi, bins.size)
    return math.sqrt(2.0 / bins.size) * np.cos(2 * np.pi * bins[None, :] * n / period + phases).sum(axis=1)


def experiment(seed: int = 0, realizations: int = 3, periods: int = 3, lead: int = 100, noise: float = 1e-3):
    """u: lead-in then back-to-back realizations; y: u through an FIR filter (its own, not inferred)."""
    rng = np.random.default_rng(seed)
    u = np.concatenate([rng.normal(0, 0.2, lead)] + [np.tile(period_of(rng), periods) for _ in range(realizations)])
    u = u + rng.normal(0, noise, u.size)
    y = np.convolve(u, [0.5, 0.3, 0.1])[: u.size]
    return u, y


def write_csv(path, columns: dict[str, np.ndarray], delimiter=",", header=True) -> None:
    lines = [delimiter.join(columns)] if header else []
    rows = np.column_stack(list(columns.values()))
    lines += [delimiter.join(f"{v:.18e}" for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")


def summary_of(result) -> dict:
    assert result.exit_code == 0, (result.stderr, result.exception)
    return result.json()


def test_csv_with_time_column_lead_in_and_realizations(run_cli, tmp_path):
    u, y = experiment(lead=100)
    source = tmp_path / "scope.csv"
    write_csv(source, {"Time (s)": np.arange(u.size) / FS, "CH1": u, "CH2": y})
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--u", "CH1", "--y", "CH2", "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(FS, rel=1e-9) and "Time (s)" in summary["fs_from"]
    assert summary["run_ids"] == ["scope_m00", "scope_m01", "scope_m02"]
    runs = read_runs(out)
    for m, run in enumerate(runs):
        start = 100 + 3 * N * m
        assert (run.kind, run.period, run.n_periods, run.realization) == ("multisine", N, 3, m)
        np.testing.assert_array_equal(run.excited_bins, BINS)
        steady = slice(start, start + 3 * N)
        np.testing.assert_array_equal(run.periods("u").ravel(), u[steady])
        np.testing.assert_array_equal(run.periods("y").ravel(), y[steady])
    with HDF5Recording(out) as rec:
        prov = rec.provenance
    digest = hashlib.sha256(source.read_bytes()).hexdigest()
    assert prov["inputs"] == {str(source): digest} and prov["import"]["sha256"] == digest
    inferred = prov["import"]["records"][0]["inference"]
    assert inferred["period"] == N and inferred["grid"] == "odd" and prov["import"]["overridden"] == {}


def test_headerless_tsv_by_column_number_with_overrides(run_cli, tmp_path):
    u, y = experiment(seed=1, realizations=1, periods=4, lead=0)
    source = tmp_path / "log.tsv"
    write_csv(source, {"y": y, "u": u}, delimiter="\t", header=False)
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--u", "2", "--y", "1", "--fs", "2000", "--period", str(N),
                                 "--transient-periods", "1", "-o", out, "--json"))
    (run,) = read_runs(out)
    assert run.fs == 2000.0 and run.period == N and run.transient_periods == 1 and run.n_periods == 3
    np.testing.assert_array_equal(run.u, u)
    with HDF5Recording(out) as rec:
        assert rec.provenance["import"]["overridden"] == {"period": N, "transient_periods": 1, "fs": 2000.0}
    assert summary["records"][0]["inference"]["realizations"][0]["periods"] == 4


def test_mat_v5_struct_with_realizations_as_columns(run_cli, tmp_path):
    rng = np.random.default_rng(2)
    u = np.column_stack([np.tile(period_of(rng), 3) for _ in range(4)])  # 768 samples x 4 realizations
    source = tmp_path / "old.mat"
    savemat(source, {"data": {"u": u, "y": 2 * u, "fs": FS}})
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--u", "data.u", "--y", "data.y", "--fs", "1000", "-o", out, "--json"))
    assert summary["format"] == "mat v5" and summary["run_ids"] == [f"old_c{c:02d}" for c in range(4)]
    for c, run in enumerate(read_runs(out)):
        assert run.period == N and run.n_periods == 3
        np.testing.assert_array_equal(run.u, u[:, c])


def write_mat73(path, variables: dict[str, np.ndarray]) -> None:
    """A MATLAB v7.3 file as MATLAB writes it: HDF5 with a 512-byte header, arrays column-major."""
    with h5py.File(path, "w", userblock_size=512) as handle:
        for name, value in variables.items():
            dataset = handle.create_dataset(name, data=np.asarray(value, dtype=np.float64).T)
            dataset.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as handle:
        handle.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 .")


def test_mat_v73_matrix_of_periods_and_time_vector(run_cli, tmp_path):
    rng = np.random.default_rng(3)
    one = period_of(rng)
    u = np.column_stack([one] * 5) + rng.normal(0, 1e-3, (N, 5))  # MATLAB N x 5: columns are periods
    source = tmp_path / "new.mat"
    write_mat73(source, {"u": u, "y": -u, "t": (np.arange(N) / FS)[:, None]})
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--time", "t", "--matrix", "periods", "-o", out, "--json"))
    assert summary["format"] == "mat v7.3" and summary["fs"] == pytest.approx(FS, rel=1e-9)
    (run,) = read_runs(out)
    assert run.period == N and run.n_periods == 5
    np.testing.assert_array_equal(run.u, u.T.ravel())  # columns joined in order
    np.testing.assert_array_equal(run.excited_bins, BINS)


def test_foreign_hdf5_by_dataset_path(run_cli, tmp_path):
    u, y = experiment(seed=4, realizations=2, periods=2, lead=37)
    source = tmp_path / "daq.h5"
    with h5py.File(source, "w") as handle:
        handle["daq/ch0"] = u
        handle["daq/ch1"] = y
    out = tmp_path / "rec.mcap"
    summary = summary_of(run_cli("import", source, "--u", "/daq/ch0", "--y", "daq/ch1", "--fs", "1000", "-o", out, "--json"))
    runs = read_runs(out)
    assert [r.run_id for r in runs] == summary["run_ids"] == ["daq_m00", "daq_m01"]
    steady = [37 + 2 * N * m for m in range(2)]
    for run, start in zip(runs, steady):
        np.testing.assert_array_equal(run.periods("u").ravel(), u[start:start + 2 * N])


def test_foreign_mcap_by_topic_and_field(run_cli, tmp_path):
    u, y = experiment(seed=5, realizations=1, periods=3, lead=0)
    source = tmp_path / "log.mcap"
    write_json_mcap(source, FS, u, y)
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--u", "/cmd:effort", "--y", "/joint:state.position", "-o", out, "--json"))
    # fs from log times rounded to whole ns: relative error at most 1 ns / (t_last - t_first) = 1.3e-9
    assert summary["fs"] == pytest.approx(FS, rel=2e-9) and summary["fs_from"] == "MCAP log times"
    (run,) = read_runs(out)
    assert run.period == N and run.n_periods == 3
    np.testing.assert_array_equal(run.y, y)


def test_sine_record_becomes_a_sine_run(run_cli, tmp_path):
    n = np.arange(4096)
    u = 0.5 * np.sin(2 * np.pi * 8 * n / 4096) + np.random.default_rng(6).normal(0, 1e-3, n.size)
    source = tmp_path / "sine.csv"
    write_csv(source, {"u": u, "y": u})
    out = tmp_path / "rec.h5"
    run_cli("import", source, "--fs", "4096", "-o", out, "--json")
    (run,) = read_runs(out)
    # 8 cycles in 4096 samples: the smallest period is 512 samples with the sine on bin 1, 8 Hz
    assert (run.kind, run.period, run.n_periods, run.frequency) == ("sine", 512, 8, 8.0)
    assert run.excited_bins.tolist() == [1]


def test_noise_record_is_arbitrary_with_a_note(run_cli, tmp_path):
    u = np.random.default_rng(7).normal(size=3000)
    source = tmp_path / "noise.csv"
    write_csv(source, {"u": u, "y": u})
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "--fs", "100", "-o", out, "--json"))
    assert summary["records"][0]["inference"]["kind"] == "arbitrary"
    assert "not periodic" in summary["records"][0]["inference"]["notes"][0]
    (run,) = read_runs(out)
    assert run.kind == "arbitrary" and run.n_samples == 3000


def test_no_split_keeps_the_record_whole(run_cli, tmp_path):
    u, y = experiment(seed=8, realizations=2, periods=3, lead=0)
    source = tmp_path / "two.csv"
    write_csv(source, {"u": u, "y": y})
    out = tmp_path / "rec.h5"
    run_cli("import", source, "--fs", "1000", "--no-split-realizations", "-o", out)
    (run,) = read_runs(out)
    assert run.kind == "arbitrary" and run.n_samples == u.size


def test_human_summary_names_what_was_inferred(run_cli, tmp_path):
    u, y = experiment(seed=9)
    source = tmp_path / "scope.csv"
    write_csv(source, {"u": u, "y": y})
    result = run_cli("import", source, "--fs", "1000", "-o", tmp_path / "rec.h5")
    assert result.exit_code == 0
    text = " ".join(result.stderr.split())
    assert "multisine (odd), period 256 samples" in text and "3 realizations back to back" in text


def side_by_side(rng: np.random.Generator, realizations: int, periods: int = 3, noise: float = 1e-3):
    """Realizations of one odd multisine (the same lines and amplitudes, new phases), and y through an FIR."""
    us = [np.tile(period_of(rng), periods) + rng.normal(0, noise, periods * N) for _ in range(realizations)]
    return us, [np.convolve(u, [0.5, 0.3, 0.1])[: u.size] for u in us]


@pytest.mark.parametrize("u_name, y_name", [("u{}", "y{}"), ("u_{}", "Y_{}"), ("u({}) [N]", "y({}) [m]")])
def test_csv_realizations_side_by_side_are_one_level_for_bla(run_cli, tmp_path, u_name, y_name):
    us, ys = side_by_side(np.random.default_rng(10), 10)
    columns = {"Time (s)": np.arange(us[0].size) / FS}
    for m, (u, y) in enumerate(zip(us, ys), start=1):
        columns[u_name.format(m)], columns[y_name.format(m)] = u, y
    source = tmp_path / "pairs.csv"
    write_csv(source, columns)
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["run_ids"] == [f"pairs_c{c:02d}" for c in range(10)] and "Time (s)" in summary["fs_from"]
    runs = read_runs(out)
    own_levels = [record["inference"]["level"] for record in summary["records"]]
    for c, run in enumerate(runs):
        assert (run.kind, run.period, run.n_periods, run.realization) == ("multisine", N, 3, c)
        np.testing.assert_array_equal(run.excited_bins, BINS)
        np.testing.assert_array_equal(run.u, us[c])
        np.testing.assert_array_equal(run.y, ys[c])
        assert run.level == pytest.approx(np.mean(own_levels), rel=1e-12)
    # every realization has rms 1 by construction (30 lines of amplitude sqrt(2/30)), up to the noise,
    # which makes each record's own level differ a little: the runs get one level in their place
    assert max(abs(level - 1) for level in own_levels) < 1e-3 and len(set(own_levels)) == 10
    bla = summary_of(run_cli("bla", out, "-o", tmp_path / "bla.h5", "--json"))
    assert [(level["realizations"], level["periods"]) for level in bla["levels"]] == [(10, 3)]


def test_csv_realizations_in_number_order_with_a_sample_rate_column(run_cli, tmp_path):
    us, ys = side_by_side(np.random.default_rng(11), 2)
    source = tmp_path / "logger.csv"
    rate = np.full(us[0].size, np.nan)
    rate[0] = 2.0  # kHz, on the first row only; the other cells are empty
    write_csv(source, {"Sample rate (kHz)": rate, "u2": us[1], "y2": ys[1], "u1": us[0], "y1": ys[0]})
    source.write_text(source.read_text().replace("nan", ""))
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["fs"] == 2000.0 and summary["fs_from"] == f"sample-rate column {source}:Sample rate (kHz)"
    first, second = read_runs(out)
    np.testing.assert_array_equal(first.u, us[0])  # u1 is realization 0, though its columns come later
    np.testing.assert_array_equal(second.y, ys[1])
    assert (first.fs, first.realization, second.realization) == (2000.0, 0, 1)


def test_csv_repeated_header_cells_pair_in_column_order(run_cli, tmp_path):
    us, ys = side_by_side(np.random.default_rng(12), 3)
    source = tmp_path / "scope.csv"
    header = ["fs"] + ["u", "y"] * 3
    rows = np.column_stack([np.full(us[0].size, FS)] + [x for pair in zip(us, ys) for x in pair])
    source.write_text("\n".join([",".join(header)] + [",".join(f"{v:.18e}" for v in row) for row in rows]) + "\n")
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["fs"] == FS and summary["runs"] == 3
    for c, run in enumerate(read_runs(out)):
        np.testing.assert_array_equal(run.u, us[c])
        np.testing.assert_array_equal(run.y, ys[c])


def test_csv_rate_column_agreeing_with_the_time_column(run_cli, tmp_path):
    u, y = experiment(seed=13, realizations=1, lead=0)
    source = tmp_path / "scope.csv"
    write_csv(source, {"t": np.arange(u.size) / FS, "fs": np.full(u.size, FS), "u": u, "y": y})
    out = tmp_path / "rec.h5"
    summary = summary_of(run_cli("import", source, "-o", out, "--json"))
    assert summary["fs"] == FS and summary["fs_from"].startswith("sample-rate column")
    with HDF5Recording(out) as rec:
        assert rec.provenance["import"]["details"]["time_vector_fs"] == pytest.approx(FS, rel=1e-9)
