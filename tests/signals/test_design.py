"""The design stage: every designed signal checked by its DFT against what the config asked for.

Expected numbers come from the multisine definition (book (2-8)): a line of amplitude A has DFT
coefficient |U(k)| = A N / 2 over a whole period, and rms^2 = sum A_k^2 / 2 (Parseval). Floating
point round-off in an N-point FFT is about 1e-15 relative, so "exact" here means 1e-12.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from nlsid.io.recording import read_runs
from nlsid.signals.lines import band_bins, log_bins
from nlsid.signals.multisine import crest_factor, flat_amplitudes, random_phases, reduce_crest_factor, synthesize

FS = 1024.0
N = 1024


def write_config(tmp_path, **overrides) -> str:
    config = {
        "fs": FS,
        "seed": 11,
        "multisine": {
            "period": N, "band": [2.0, 100.0], "lines": "random-odd", "group_size": 3,
            "realizations": 3, "periods": 2, "transient_periods": 1, "rms_levels": [0.2, 1.5],
        },
    }
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(config.get(key), dict):
            config[key] = {**config[key], **value}
        elif value is None:
            config.pop(key, None)
        else:
            config[key] = value
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(config))
    return str(path)


def design(run_cli, tmp_path, name="exc.h5", **overrides):
    out = tmp_path / name
    result = run_cli("design", write_config(tmp_path, **overrides), "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    return read_runs(out, require_y=False), result.json()


def one_period_spectrum(run):
    periods = run.periods("u")
    assert np.array_equal(periods, np.broadcast_to(periods[0], periods.shape)), "periods must repeat exactly"
    return np.fft.rfft(periods[0])


def test_random_odd_multisine_spectrum_levels_and_lines(run_cli, tmp_path):
    runs, summary = design(run_cli, tmp_path)
    assert len(runs) == 2 * 3
    candidates = np.arange(3, 101, 2)  # odd lines 3..99 Hz at 1 Hz resolution ("band" 2..100 Hz)
    excited = runs[0].excited_bins
    assert np.all(excited % 2 == 1)
    # One line of every consecutive group of 3 odd candidates is a detection line (book 6.1.2.B);
    # the final group of 1 (49 candidates = 16 x 3 + 1) stays excited.
    for start in range(0, 48, 3):
        assert np.isin(candidates[start:start + 3], excited).sum() == 2
    assert candidates[-1] in excited
    assert excited.size == 49 - 16
    assert summary["multisine"]["detection_bins"] == sorted(set(candidates) - set(excited))
    for run in runs:
        assert np.array_equal(run.excited_bins, excited), "same lines for every realization and level"
        assert run.n_samples == 3 * N and run.transient_periods == 1
        spectrum = one_period_spectrum(run)
        amplitude = run.level * np.sqrt(2.0 / excited.size)
        np.testing.assert_allclose(2 * np.abs(spectrum[excited]) / N, amplitude, rtol=1e-12)
        others = np.delete(np.abs(spectrum), excited)
        assert others.max() < 1e-12 * amplitude * N
        assert np.sqrt(np.mean(run.u**2)) == pytest.approx(run.level, rel=1e-12)
        # An odd multisine satisfies u(t + T/2) = -u(t) (book (5-9)).
        np.testing.assert_allclose(run.u[N // 2:N], -run.u[:N // 2], atol=1e-12 * run.level)


def test_realizations_have_independent_phases(run_cli, tmp_path):
    runs, _ = design(run_cli, tmp_path)
    phases = np.array([np.angle(one_period_spectrum(r)[r.excited_bins]) for r in runs])
    # Independent U[0, 2pi) phases: the mean resultant length over F lines of the phase differences
    # is about 1/sqrt(F) ~ 0.17 for F = 33; identical phases would give 1.
    for a in range(len(runs)):
        for b in range(a + 1, len(runs)):
            assert abs(np.mean(np.exp(1j * (phases[a] - phases[b])))) < 0.6


def test_same_seed_same_signal_other_seed_other_signal(run_cli, tmp_path):
    first, _ = design(run_cli, tmp_path, name="a.h5")
    second, _ = design(run_cli, tmp_path, name="b.h5")
    third, _ = design(run_cli, tmp_path, name="c.h5", seed=12)
    for a, b in zip(first, second):
        assert np.array_equal(a.u, b.u)
    assert not np.array_equal(first[0].u, third[0].u)


@pytest.mark.parametrize("lines, odd", [("full", False), ("odd", True), ("random-full", False)])
def test_line_selection_types(run_cli, tmp_path, lines, odd):
    runs, summary = design(run_cli, tmp_path, multisine={"lines": lines, "group_size": 4})
    excited = runs[0].excited_bins
    candidates = np.arange(3 if odd else 2, 101, 2 if odd else 1)
    if lines == "random-full":
        # 99 candidates in groups of 4: 24 full groups and a remainder of 3, each losing one line.
        assert excited.size == 99 - 25
        assert np.all(np.isin(excited, candidates))
    else:
        assert np.array_equal(excited, candidates)
        assert summary["multisine"]["detection_bins"] == []
    assert np.all(excited % 2 == 1) == odd


def test_log_grid_is_quasi_logarithmic(run_cli, tmp_path):
    runs, _ = design(run_cli, tmp_path, multisine={"lines": "odd", "grid": "log", "log_ratio": 1.1,
                                                   "band": [10.0, 400.0]})
    bins = runs[0].excited_bins
    assert np.all(bins % 2 == 1) and bins[0] >= 10 and bins[-1] <= 400
    # Each target f_i = 11 * 1.1^i is rounded to the nearest odd bin: at most 1 bin away.
    targets = 11 * 1.1 ** np.arange(int(np.log(400 / 11) / np.log(1.1)) + 1)
    assert np.max(np.min(np.abs(bins[None, :] - targets[:, None]), axis=1)) <= 1.0
    ratios = bins[1:] / bins[:-1]
    assert np.all(ratios[bins[1:] > 100] < 1.1 + 2 / 100)


def test_schroeder_phases_and_crest_factor(run_cli, tmp_path):
    runs, summary = design(run_cli, tmp_path, multisine={"lines": "full", "phases": "schroeder", "realizations": 1,
                                                         "band": [1.0, 100.0]})
    # Schroeder multisine of a flat low band: crest factor about 1.65 (book digest 1.5, Ex 20).
    assert summary["multisine"]["crest_factors"][0] == pytest.approx(1.65, abs=0.15)
    assert crest_factor(runs[0].u) == pytest.approx(summary["multisine"]["crest_factors"][0], rel=1e-12)


def test_crest_factor_reduction_keeps_the_amplitude_spectrum():
    rng = np.random.default_rng(3)
    bins = band_bins(4096, 4096.0, (1.0, 500.0), odd_only=True)
    amplitudes = flat_amplitudes(bins.size, 1.0)
    start = random_phases(bins.size, rng)
    before = synthesize(4096, bins, amplitudes, start)
    after = synthesize(4096, bins, amplitudes, reduce_crest_factor(4096, bins, amplitudes, start, 100))
    spectrum = np.fft.rfft(after)
    np.testing.assert_allclose(2 * np.abs(spectrum[bins]) / 4096, amplitudes, rtol=1e-12)
    assert np.delete(np.abs(spectrum), bins).max() < 1e-10
    # A Gaussian-like random-phase multisine of 250 lines has a crest factor near 3.5; clipping
    # with spectrum restoration approaches Schroeder's 1.65 (book digest 1.5).
    assert crest_factor(before) > 3.0
    assert crest_factor(after) < 1.8


def test_crest_factor_option_in_config(run_cli, tmp_path):
    plain, s1 = design(run_cli, tmp_path, name="a.h5")
    reduced, s2 = design(run_cli, tmp_path, name="b.h5", multisine={"crest_factor_iterations": 60})
    assert max(s2["multisine"]["crest_factors"]) < min(s1["multisine"]["crest_factors"])
    for a, b in zip(plain, reduced):
        np.testing.assert_allclose(np.abs(one_period_spectrum(a)), np.abs(one_period_spectrum(b)), atol=1e-9)


def test_single_sine_grid_on_exact_bins(run_cli, tmp_path):
    sines = {"period": N, "frequency_steps": {"start": 5.0, "stop": 30.0, "step": 5.0},
             "amplitude_range": {"start": 0.1, "stop": 1.0, "count": 3}, "repeats": 2, "periods": 3,
             "transient_periods": 1}
    runs, summary = design(run_cli, tmp_path, multisine=None, sines=sines)
    assert len(runs) == 6 * 3 * 2
    np.testing.assert_allclose(summary["sines"]["amplitudes"], [0.1, np.sqrt(0.1), 1.0], rtol=1e-12)
    for run in runs:
        assert run.kind == "sine" and run.n_periods == 3
        k = int(round(run.frequency * N / FS))
        spectrum = one_period_spectrum(run)
        # u = a sin(2 pi k n / N) has U(k) = -j a N / 2 (book digest 1.1, Ex 19): magnitude and phase.
        assert spectrum[k] == pytest.approx(-0.5j * run.level * N, abs=1e-9 * N)
        assert np.delete(np.abs(spectrum), k).max() < 1e-10 * N
    assert sorted({r.frequency for r in runs}) == [5.0, 10.0, 15.0, 20.0, 25.0, 30.0]


def test_duration_in_summary(run_cli, tmp_path):
    _, summary = design(run_cli, tmp_path)
    # 2 levels x 3 realizations x (1 + 2) periods of 1 s each.
    assert summary["duration_s"] == pytest.approx(18.0)
    assert summary["runs"] == 6


def test_log_bins_never_leave_the_band():
    bins = log_bins(1000, 1000.0, (3.0, 47.0), 1.5, odd_only=False)
    assert bins.min() >= 3 and bins.max() <= 47 and np.all(np.diff(bins) > 0)


@pytest.mark.parametrize("key, line_text, value, bad", [
    ("fs", "fs: 1024.0", ".inf", ".inf"),
    ("multisine.band[1]", "  band: [0.5, 60.0]     # Hz", "[0.5, .nan]", ".nan"),
    ("multisine.rms_levels[1]", "  rms_levels: [1.0, 2.0, 4.0]", "[1.0, -.inf, 4.0]", "-.inf"),
    ("sines.amplitudes[0]", "  amplitudes: [1.0, 2.0, 4.0]", "[.nan, 2.0, 4.0]", ".nan"),
])
def test_a_non_finite_number_is_refused_at_its_key(run_cli, tmp_path, key, line_text, value, bad):
    from pathlib import Path

    lines = (Path(__file__).resolve().parents[2] / "configs" / "stage_design.yaml").read_text().splitlines()
    index = lines.index(line_text)
    lines[index] = f"{line_text.split(':')[0]}: {value}"
    config = tmp_path / "design.yaml"
    config.write_text("\n".join(lines) + "\n")
    result = run_cli("design", config, "-o", tmp_path / "exc.h5")
    assert result.exit_code == 2
    assert result.stderr.strip() == f"nlsid: error: {config}:{index + 1}: {key}: expected a finite number, got {bad}"
    assert not (tmp_path / "exc.h5").exists()
