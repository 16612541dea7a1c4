"""Excitation inference on records of known structure (nlsid.signals.inference).

Records are built here from explicit cosine sums (not with the library's synthesiser), with the
period, lines, lead-in and realization boundaries chosen by the test; the inference must recover
them exactly. Input noise is white Gaussian at the stated SNR.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from scipy import stats

from nlsid.signals.inference import (
    f_threshold, grid_of, infer_excitation, simplest_fraction, squared_differences)

FS = 1000.0


def multisine(period: int, bins: np.ndarray, rng: np.random.Generator, rms: float = 1.0) -> np.ndarray:
    """One period of sum_k A cos(2 pi k n / N + phi_k), equal amplitudes, uniform random phases."""
    n = np.arange(period)[:, None]
    amplitude = rms * math.sqrt(2.0 / bins.size)
    phases = rng.uniform(0, 2 * np.pi, bins.size)
    return amplitude * np.cos(2 * np.pi * bins[None, :] * n / period + phases).sum(axis=1)


def random_odd_grid(top: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Odd bins 1..top with one random line of every group of 3 left out: (excited, detection)."""
    odd = np.arange(1, top + 1, 2)
    dropped = [group[rng.integers(group.size)] for group in np.array_split(odd, math.ceil(odd.size / 3))]
    return np.setdiff1d(odd, dropped), np.sort(dropped)


def concatenated(period, bins, rng, realizations, periods, lead, noise):
    """``lead`` samples of low-level noise, then realizations of ``periods`` identical periods each."""
    parts = [rng.normal(0, 0.3, lead)]
    parts += [np.tile(multisine(period, bins, rng), periods) for _ in range(realizations)]
    x = np.concatenate(parts)
    return x + rng.normal(0, noise, x.size)


@pytest.mark.parametrize("seed", range(5))
def test_lead_in_noise_and_realizations_are_found_exactly(seed):
    # Input SNR 50 dB (noise std 3.2e-3 against rms 1). A one-sample error of the period phase needs
    # the squared change at every boundary to fall below a noise sample's: about
    # (0.64 / sqrt(SNR))^B = (2e-3)^4 for the B = 4 edges here (3 boundaries and the lead-in).
    rng = np.random.default_rng(seed)
    period, lead = 512, 701  # 1.37 periods of lead-in: a non-integer number of periods
    excited, detection = random_odd_grid(101, rng)
    x = concatenated(period, excited, rng, realizations=4, periods=3, lead=lead, noise=10 ** (-50 / 20))
    inf = infer_excitation(x, FS)
    assert inf.kind == "multisine" and inf.period == period
    steady_starts = [r.start + r.transient_periods * period for r in inf.realizations]
    assert steady_starts == [lead + m * 3 * period for m in range(4)]
    assert [r.periods for r in inf.realizations] == [3, 3, 3, 3]
    # the lead-in: 701 = 189 + 512, so 189 samples are dropped and one whole slot is a transient period
    assert inf.realizations[0].start == lead % period and inf.realizations[0].transient_periods == 1
    assert inf.measures["dropped_leading_samples"] == lead % period
    for r in inf.realizations:
        np.testing.assert_array_equal(r.excited_bins, excited)
    assert inf.grid == "random-odd"
    in_band = detection[(detection > excited[0]) & (detection < excited[-1])]
    np.testing.assert_array_equal(inf.measures["detection_bins"], in_band)
    # the measured input SNR is the 50 dB put in: the within-realization noise variance is estimated
    # from 4 x 2 x 512 = 4096 degrees of freedom, relative std sqrt(2/4096) = 0.022 = 0.1 dB
    assert inf.measures["input_snr_db"] == pytest.approx(50.0, abs=0.5)


def test_two_periods_per_realization_are_enough():
    # With P = 2 half of the lag-N differences cross a boundary; the repeat residual still finds N.
    rng = np.random.default_rng(11)
    period = 256
    bins = np.arange(1, 60)
    x = concatenated(period, bins, rng, realizations=5, periods=2, lead=0, noise=1e-3)[0:]
    inf = infer_excitation(x, FS)
    assert inf.period == period and inf.grid == "full"
    assert [r.start for r in inf.realizations] == [m * 2 * period for m in range(5)]
    assert all(r.transient_periods == 0 and r.periods == 2 for r in inf.realizations)


@pytest.mark.parametrize("grid, bins", [("full", np.arange(3, 40)), ("odd", np.arange(1, 80, 2))])
def test_grid_names_of_full_and_odd_multisines(grid, bins):
    rng = np.random.default_rng(5)
    x = np.tile(multisine(1024, bins, rng), 4) + rng.normal(0, 1e-3, 4096)
    inf = infer_excitation(x, FS)
    assert inf.period == 1024 and inf.grid == grid and inf.measures["detection_bins"] == []
    np.testing.assert_array_equal(inf.realizations[0].excited_bins, bins)


def test_noise_free_record_uses_the_numeric_floor():
    # Exactly repeating float data: the period noise is zero, lines are tested against the 100 dB floor.
    rng = np.random.default_rng(2)
    bins = np.array([2, 5, 7, 11, 13])
    x = np.tile(multisine(200, bins, rng), 5)
    inf = infer_excitation(x, FS)
    assert inf.period == 200 and inf.grid == "sparse"
    np.testing.assert_array_equal(inf.realizations[0].excited_bins, bins)


def test_sine_on_a_bin():
    # 3 cycles per 1024 samples: the smallest period is 1024 (3 and 1024 are coprime).
    rng = np.random.default_rng(4)
    n = np.arange(8 * 1024)
    sigma = 1e-3
    x = 0.7 * np.sin(2 * np.pi * 3 * n / 1024 + 0.3) + rng.normal(0, sigma, n.size)
    inf = infer_excitation(x, FS)
    assert inf.kind == "sine" and inf.period == 1024
    np.testing.assert_array_equal(inf.realizations[0].excited_bins, [3])
    assert inf.frequency == 3 * FS / 1024
    # amplitude of the line: averaged over 8 periods, its std is sigma sqrt(2 / L) = 1.6e-5; allow 5 std
    assert inf.level == pytest.approx(0.7, abs=5 * sigma * math.sqrt(2 / n.size))
    assert inf.measures["sine_on_bin"] is True


def test_sine_between_bins_is_arbitrary_with_its_frequency():
    rng = np.random.default_rng(6)
    L, sigma, amplitude = 8192, 1e-3, 0.5
    f = 3.1 * FS / 1024
    n = np.arange(L)
    x = amplitude * np.cos(2 * np.pi * f / FS * n) + rng.normal(0, sigma, L)
    inf = infer_excitation(x, FS)
    assert inf.kind == "arbitrary" and inf.period is None
    assert "not on a bin" in inf.notes[0]
    # Cramer-Rao bound of a real sine's frequency (Kay 1993, Eq. 3.41), in Hz, computed here
    crb = FS / (2 * np.pi) * math.sqrt(24 * sigma**2 / (amplitude**2 * L * (L**2 - 1)))
    assert abs(inf.frequency - f) < 5 * crb
    assert inf.measures["sine_frequency_std"] == pytest.approx(crb, rel=0.05)  # noise variance from 8188 dof


def test_white_noise_is_arbitrary_with_a_note():
    x = np.random.default_rng(8).normal(size=20000)
    inf = infer_excitation(x, FS)
    assert inf.kind == "arbitrary" and inf.period is None and inf.realizations == []
    assert inf.notes and "not periodic" in inf.notes[0]


def test_given_period_that_does_not_fit_is_not_periodic():
    rng = np.random.default_rng(9)
    x = np.tile(multisine(500, np.arange(1, 50), rng), 4)
    assert infer_excitation(x, FS, period=500).period == 500
    wrong = infer_excitation(x, FS, period=499)
    assert wrong.kind == "arbitrary" and "given period of 499" in wrong.notes[0]


def test_realizations_kept_whole_become_arbitrary():
    rng = np.random.default_rng(10)
    x = concatenated(256, np.arange(1, 40), rng, realizations=2, periods=3, lead=0, noise=1e-3)
    inf = infer_excitation(x, FS, split=False)
    assert inf.kind == "arbitrary" and "2 segments" in inf.notes[0] and "2 realizations" not in inf.notes[0]


def test_squared_differences_match_the_definition():
    x = np.random.default_rng(1).normal(size=300)
    direct = np.array([np.sum((x[tau:] - x[: x.size - tau]) ** 2) for tau in range(x.size)])
    np.testing.assert_allclose(squared_differences(x), direct, rtol=1e-9, atol=1e-9)


def test_simplest_fraction_against_brute_force():
    for lo, hi in [(0.33, 0.34), (3.1415, 3.1416), (0.0029296, 0.0029297), (0.5, 0.5), (0.7071, 0.70711)]:
        got = simplest_fraction(Fraction(lo), Fraction(hi))
        denominator = next(q for q in range(1, 10**6) if math.ceil(lo * q) <= math.floor(hi * q))
        assert got.denominator == denominator and lo <= got <= hi


def test_f_threshold_is_the_f_quantile():
    for alpha, nu in [(1e-3, 10), (1e-6, 34), (1e-8, 400)]:
        assert f_threshold(alpha, nu) == pytest.approx(stats.f.isf(alpha, 2, nu), rel=1e-6)


def test_grid_names():
    assert grid_of(np.array([1, 3, 5, 7]))[0] == "odd"
    name, missing = grid_of(np.array([1, 3, 7, 9, 13]))
    assert name == "random-odd" and missing.tolist() == [5, 11]
    name, missing = grid_of(np.array([2, 3, 5, 6]))
    assert name == "random-full" and missing.tolist() == [4]
    assert grid_of(np.array([1, 2, 4, 8, 16, 32]))[0] == "sparse"


def test_a_record_repeating_every_two_samples_is_no_excitation():
    x = np.tile([1.0, -1.0], 200)  # a Nyquist tone: period 2 has no line between DC and Nyquist
    result = infer_excitation(x, FS)
    assert result.kind == "arbitrary" and result.period is None
    assert "too short a period for any line" in result.notes[-1]


def test_noise_free_periods_after_a_lead_in():
    """Exact repeats give a zero period-to-period variance: the SNR and the phase margin are infinite."""
    rng = np.random.default_rng(20)
    bins = np.arange(1, 30, 2)
    x = np.concatenate([rng.normal(0, 0.3, 37), np.tile(multisine(128, bins, rng), 4)])
    result = infer_excitation(x, FS)
    assert (result.kind, result.period) == ("multisine", 128)
    np.testing.assert_array_equal(result.realizations[0].excited_bins, bins)
    assert result.measures["input_snr_db"] == math.inf and result.measures["phase_margin_db"] == math.inf
