"""``nlsid import`` of several files, two clocks, ``--range``, ``--decimate`` and ``--unit``.

Each file is written here with numpy; the truth (samples, rates, lines) is the generator's own.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.io import savemat

from nlsid.io.recording import read_runs

FS = 1000.0
N = 200


def multisine(rng: np.random.Generator, bins: np.ndarray, period: int, periods: int, rms: float = 1.0) -> np.ndarray:
    n = np.arange(period * periods)[:, None]
    phases = rng.uniform(0, 2 * np.pi, bins.size)
    x = np.cos(2 * np.pi * bins[None, :] * n / period + phases).sum(axis=1)
    return rms * math.sqrt(2.0 / bins.size) * x


def write_csv(path, columns: dict[str, np.ndarray]) -> None:
    rows = np.column_stack(list(columns.values()))
    path.write_text(",".join(columns) + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in rows) + "\n")


def ok(result) -> dict:
    assert result.exit_code == 0, (result.stderr, result.exception)
    return result.json()


def refused(result, *words: str) -> str:
    assert result.exit_code == 2, (result.stdout, result.stderr)
    line = result.stderr.strip()
    assert "Traceback" not in line and len(line.splitlines()) == 1, line
    for word in words:
        assert word in line, line
    return line


def test_u_and_y_in_two_mat_files_on_one_clock(run_cli, tmp_path):
    rng = np.random.default_rng(1)
    u = multisine(rng, np.arange(1, 40, 2), N, 3)
    y = np.convolve(u, [0.4, 0.3, -0.1])[:u.size] + rng.normal(0, 1e-4, u.size)
    savemat(tmp_path / "uval.mat", {"uval": u[:, None]})
    savemat(tmp_path / "yval.mat", {"yval": y[None, :]})
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", tmp_path / "uval.mat", tmp_path / "yval.mat", "--u", "uval", "--y", "yval",
                         "--fs", FS, "-o", out, "--json"))
    assert summary["sources"] == [str(tmp_path / "uval.mat"), str(tmp_path / "yval.mat")]
    assert any("joined sample by sample" in note for note in summary["notes"])
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.u, u)
    np.testing.assert_array_equal(run.y, y)
    assert run.period == N


def test_one_file_per_level_gives_one_experiment_per_file(run_cli, tmp_path):
    bins = np.arange(1, 30, 2)
    files = []
    for index, level in enumerate((0.5, 1.0, 2.0)):
        u = multisine(np.random.default_rng(index), bins, N, 3, rms=level)
        y = np.convolve(u, [0.5, 0.2])[:u.size] + 0.1 * u ** 3
        files.append(tmp_path / f"level{index}.csv")
        write_csv(files[-1], {"t": np.arange(u.size) / FS, "u": u, "y": y})
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", *files, "-o", out, "--json"))
    assert summary["run_ids"] == ["level0", "level1", "level2"]
    runs = read_runs(out)
    # the rms of a multisine of equal-amplitude lines, by construction of the generator
    assert [run.level for run in runs] == pytest.approx([0.5, 1.0, 2.0], rel=1e-9)
    for run in runs:
        np.testing.assert_array_equal(run.excited_bins, bins)


def test_two_instruments_on_different_clocks_are_moved_onto_the_inputs_clock(run_cli, tmp_path):
    f1, f2 = 7.0, 23.0
    t_u = np.arange(10_000) / FS                      # the input: 1 kHz from t = 0
    fs_y, t0_y = 2500.0, 0.0123                       # the output: 2.5 kHz, started 12.3 ms later
    t_y = t0_y + np.arange(24_000) / fs_y

    def truth(t):
        return np.sin(2 * np.pi * f1 * t + 0.3) + 0.5 * np.cos(2 * np.pi * f2 * t)

    # a tone at 1.1 kHz in y's record: above u's Nyquist frequency, it would alias onto 100 Hz
    y_logged = truth(t_y) + 0.1 * np.sin(2 * np.pi * 1100.0 * t_y)
    u = np.random.default_rng(6).normal(size=t_u.size)   # not periodic: the run keeps every sample
    write_csv(tmp_path / "drive.csv", {"time": t_u, "u": u})
    write_csv(tmp_path / "sensor.csv", {"time": t_y, "y": y_logged})
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", tmp_path / "drive.csv", tmp_path / "sensor.csv", "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(FS, rel=1e-9)
    assert any("cubic-spline" in note and "anti-alias" in note for note in summary["notes"])
    (run,) = read_runs(out)
    first = math.ceil(t0_y * FS)                      # the first input sample inside y's span
    last = math.floor(t_y[-1] * FS)
    assert run.u.size == last - first + 1
    t = t_u[first:last + 1]
    np.testing.assert_array_equal(run.u, u[first:last + 1])
    # pass-band ripple of the anti-alias FIR, forward and backward: 2 x 1e-4 of the amplitude 1.5; the
    # 1.1 kHz tone attenuated by 2 x 80 dB; the spline's error (2 pi f / fs)^4 ~ 5e-7; the edges of the
    # forward-backward filter are left out of the bound (the filter's reach, 0.1 s)
    inner = slice(250, -250)
    np.testing.assert_allclose(run.y[inner], truth(t)[inner], atol=4e-4)


def test_range_and_decimate_keep_a_periodic_record_periodic(run_cli, tmp_path):
    k, period, periods = 4, 800, 8
    bins = np.arange(1, 60, 2)                        # below 0.8 of the new Nyquist frequency (bin 80)
    rng = np.random.default_rng(3)
    u = multisine(rng, bins, period, periods)
    n = np.arange(u.size)
    u_logged = u + 0.05 * np.cos(2 * np.pi * 351 * n / period)   # bin 351 would alias onto the excited bin 49
    y = 2.0 * u_logged
    write_csv(tmp_path / "fast.csv", {"u": u_logged, "y": y})
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", tmp_path / "fast.csv", "--fs", 4 * FS, "--range", f"{period}:",
                         "--decimate", k, "-o", out, "--json"))
    assert summary["fs"] == pytest.approx(FS, rel=1e-12)
    (note,) = [note for note in summary["notes"] if note.startswith("decimated by 4")]
    edge = int(note.split("; ")[1].split()[0])        # decimated samples dropped at each end
    (record,) = summary["records"]
    (real,) = record["inference"]["realizations"]
    (run,) = read_runs(out)
    short = period // k
    assert run.period == short
    np.testing.assert_array_equal(run.excited_bins, bins)
    steady = run.periods("u")
    spectrum = np.fft.rfft(steady.mean(axis=0)) / short
    # the steady part starts `offset` decimated samples after the cropped record's start, itself a
    # period boundary of the generator: a delay of `offset` multiplies line b by exp(2j pi b offset / short)
    offset = edge + real["start"] + run.transient_periods * short
    expected = np.fft.rfft(u[:period])[bins] / period * np.exp(2j * np.pi * bins * offset / short)
    # the pass-band ripple of the anti-alias FIR (1e-4 relative); the 351-bin tone is 80 dB down
    np.testing.assert_allclose(spectrum[bins], expected, atol=2e-4 * np.abs(expected).max())
    np.testing.assert_allclose(run.periods("y"), 2.0 * steady, rtol=1e-12, atol=1e-12)


def test_units_from_the_command_line_are_written(run_cli, tmp_path):
    u = multisine(np.random.default_rng(4), np.arange(1, 20), N, 2)
    write_csv(tmp_path / "rig.csv", {"u": u, "y": 0.5 * u})
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", tmp_path / "rig.csv", "--fs", FS, "--unit", "u=N", "--unit", "y=m", "-o", out, "--json"))
    assert summary["units"] == {"u": "N", "y": "m"}
    assert all(run.units == {"u": "N", "y": "m"} for run in read_runs(out))


def test_several_files_refused_with_one_line(run_cli, tmp_path):
    u = multisine(np.random.default_rng(5), np.arange(1, 20), N, 2)
    write_csv(tmp_path / "a.csv", {"u": u, "y": u})
    write_csv(tmp_path / "b.csv", {"y": u})
    out = tmp_path / "rec.h5"
    refused(run_cli("import", tmp_path / "a.csv", tmp_path / "b.csv", "--fs", FS, "-o", out), "signal y is in 2")
    (tmp_path / "c.csv").write_text((tmp_path / "a.csv").read_text())
    refused(run_cli("import", tmp_path / "a.csv", tmp_path / "c.csv", "--fs", FS, "-o", out), "same file")
    write_csv(tmp_path / "late.csv", {"time": 100 + np.arange(u.size) / FS, "y": u})
    write_csv(tmp_path / "early.csv", {"time": np.arange(u.size) / FS, "u": u})
    refused(run_cli("import", tmp_path / "early.csv", tmp_path / "late.csv", "-o", out), "do not overlap")
    refused(run_cli("import", tmp_path / "a.csv", "--fs", FS, "--unit", "z=N", "-o", out), "--unit z=N")
    refused(run_cli("import", tmp_path / "a.csv", "--fs", FS, "--decimate", 50, "-o", out), "--decimate 50")
    refused(run_cli("import", tmp_path / "a.csv", "--fs", FS, "--range", "10:5", "-o", out), "--range")
    assert not out.exists()


def test_one_file_per_level_with_grouped_realization_columns_feeds_bla(run_cli, tmp_path):
    """A benchmark layout: per level a CSV whose header labels groups of 10 columns ("r",,,...,"u",,,...),
    two steady periods per column, and a sample-rate column; bla must see 2 levels of M = 10, P = 2."""
    period, periods, m_real, fs = 256, 2, 10, 78125.0
    bins = np.arange(1, 60)
    files = []
    for level, rms in enumerate((0.5, 1.0)):
        rng = np.random.default_rng(10 + level)
        r = np.column_stack([multisine(rng, bins, period, periods, rms=rms) for _ in range(m_real)])
        u = r + rng.normal(0, 1e-3, r.shape)
        y = np.vstack([np.convolve(col, [0.6, 0.3])[:col.size] for col in u.T]).T + 0.1 * u ** 2
        header = [f'"{name}"' + "," * (m_real - 1) for name in ("r", "u", "y")] + ['"fs"']
        rows = [",".join(f"{v:.12g}" for v in row) + ("," + f"{fs:g}" if i == 0 else ",")
                for i, row in enumerate(np.hstack([r, u, y]))]
        files.append(tmp_path / f"Level{level + 1}.csv")
        files[-1].write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", *files, "-o", out, "--json"))
    assert summary["runs"] == 2 * m_real and summary["fs"] == fs
    runs = read_runs(out)
    assert sorted({run.level for run in runs}) == pytest.approx([0.5, 1.0], rel=1e-9)
    assert sorted(run.realization for run in runs) == list(range(2 * m_real))
    bla = ok(run_cli("bla", out, "-o", tmp_path / "bla.h5", "--json"))
    assert [(level["realizations"], level["periods"]) for level in bla["levels"]] == [(m_real, periods)] * 2


def test_a_matrix_variables_rows_picked_and_the_rest_listed(run_cli, tmp_path):
    rng = np.random.default_rng(7)
    force, acc, volt = rng.normal(size=(512, 1)), rng.normal(size=(3, 512)), rng.normal(size=(1, 512))
    savemat(tmp_path / "gvt.mat", {"Force": force, "Voltage": volt, "Acceleration": acc, "Fs": 400.0})
    out = tmp_path / "rec.h5"
    summary = ok(run_cli("import", tmp_path / "gvt.mat", "--u", "Force", "--y", "Acceleration[0]",
                         "--channel", "a2=Acceleration[2]", "-o", out, "--json"))
    assert summary["fs"] == 400.0
    assert set(summary["ignored_variables"][str(tmp_path / "gvt.mat")]) == {"Voltage", "Acceleration[1]"}
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.y, acc[0])
    np.testing.assert_array_equal(run.channels["a2"], acc[2])
