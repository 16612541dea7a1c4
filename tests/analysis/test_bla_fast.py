"""Fast method, line classes and detection tests (book Section 6.1.2, Exercises 89.c, 89.e, 91).

Tolerances: a detection line without signal passes the F(2, 2P-2) test (6-50) with probability
0.95 exactly (circular normal noise), so the fraction of significant lines among n such lines is
0.05 +- 4 sqrt(0.05 0.95 / n) (4 binomial standard deviations).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal, stats

from generators.bla_cases import full_random_bins, multisine, odd_random_bins, runs_of_level, simulate  # noqa: E402

from nlsid.analysis.confidence import circle_bounds, f_quantile_2  # noqa: E402
from nlsid.analysis.levels import analyse_runs  # noqa: E402
from nlsid.analysis.lines import EVEN, EXCITED, NONHARMONIC, ODD, classify_lines, spectra  # noqa: E402


def analyse(runs, method="auto"):
    return analyse_runs(((run, run.run_id) for run in runs), method)[0][0]


def null_tolerance(n):
    return 4 * np.sqrt(0.05 * 0.95 / n)


def test_dft_scaling_of_a_cosine_and_of_white_noise():
    """(2-2) with S = 1/N: a cosine of amplitude A gives |X(k)| = A/2; white noise E|X|^2 = s^2/N."""
    N, k, A = 64, 5, 3.0
    n = np.arange(N)
    X = spectra(A * np.cos(2 * np.pi * k * n / N + 0.4)[None, :])[0]
    assert abs(X[k]) == pytest.approx(A / 2, rel=1e-12)
    assert np.angle(X[k]) == pytest.approx(0.4, abs=1e-12)
    noise = np.random.default_rng(0).standard_normal((4000, N)) * 2.0
    power = np.mean(np.abs(spectra(noise)[:, 1:N // 2]) ** 2)
    # 4000 x 31 exponential variables: relative standard deviation 1/sqrt(124000).
    assert power == pytest.approx(4.0 / N, rel=4 / np.sqrt(4000 * 31))


def test_line_classes_of_an_odd_grid():
    lines = classify_lines(40, 40.0, np.array([3, 5, 9, 11]))
    assert lines.base == 1 and lines.odd_grid
    assert lines.kind[[3, 5, 9, 11]].tolist() == [EXCITED] * 4
    assert lines.kind[[1, 7, 13]].tolist() == [ODD] * 3
    assert lines.kind[[2, 4, 6, 12]].tolist() == [EVEN] * 4
    assert lines.kind[0] == -1 and lines.kind[20] == -1  # DC and Nyquist
    assert lines.detection(ODD).tolist() == [7]  # in band: 3..11
    assert lines.detection(EVEN).tolist() == [4, 6, 8, 10]
    assert lines.grid_factor == pytest.approx(5 / 4)  # odd candidates 3, 5, 7, 9, 11 over 4 excited
    # A grid on multiples of 2: odd bins are not harmonics of the excitation.
    shifted = classify_lines(40, 40.0, np.array([2, 6, 10]))
    assert shifted.base == 2 and shifted.kind[3] == NONHARMONIC and shifted.kind[4] == EVEN
    assert not classify_lines(40, 40.0, np.array([3, 4, 5])).odd_grid


def test_detection_lines_of_several_classes_are_their_sorted_union_and_read_only():
    """A tuple of classes gives the union of their bins in increasing order (what np.union1d gave,
    without loading numpy.ma); the bins are kept for the level's next run and cannot be changed."""
    lines = classify_lines(40, 40.0, np.array([3, 4, 9, 11]))  # a full grid: every harmonic a candidate
    for in_band in (True, False, None):
        union = np.union1d(lines.detection(ODD, in_band), lines.detection(EVEN, in_band))
        assert np.array_equal(lines.detection((ODD, EVEN), in_band), union)
    assert lines.bla_detection().tolist() == [5, 6, 7, 8, 10]
    assert lines.detection((ODD, EVEN, NONHARMONIC)).tolist() == [5, 6, 7, 8, 10]  # base 1: no nonharmonic
    assert lines.detection(ODD) is lines.detection(ODD)
    with pytest.raises(ValueError):
        lines.detection(ODD)[0] = 1


def test_f_quantile_matches_the_book_and_scipy():
    """(6-50): F_{0.95; 2, 10} = 4.10 for P = 6 (book); closed form against scipy.stats."""
    assert f_quantile_2(0.95, 10) == pytest.approx(4.10, abs=0.005)
    for p, dof in ((0.95, 2), (0.9, 7), (0.99, 40)):
        assert f_quantile_2(p, dof) == pytest.approx(stats.f.ppf(p, 2, dof), rel=1e-10)
    assert f_quantile_2(0.95, np.inf) == pytest.approx(-np.log(0.05))  # (6-87): radius 1.731 sigma
    assert np.sqrt(f_quantile_2(0.95, np.inf)) == pytest.approx(1.731, abs=5e-4)


def test_circle_bounds_on_magnitude_and_phase():
    b = circle_bounds(np.array([2j]), np.array([1.0 / f_quantile_2(0.95, 8)]), 0.95, 5)
    assert b.radius[0] == pytest.approx(1.0)
    assert (b.mag_lo[0], b.mag_hi[0]) == pytest.approx((1.0, 3.0))
    assert (b.phase_lo[0], b.phase_hi[0]) == pytest.approx((np.pi / 2 - np.pi / 6, np.pi / 2 + np.pi / 6))


def wh_89c(u):
    """Book (6-57)/(6-58): G1 = 1/(1 - 0.2 z^-1 + 0.9 z^-2), z = x + 0.1 x^2 + 0.001 x^3,
    G2 = (1 + 0.5 z^-1)/(1 - 0.5 z^-1 + 0.9 z^-2)."""
    x = signal.lfilter([1.0], [1.0, -0.2, 0.9], u)
    return signal.lfilter([1.0, 0.5], [1.0, -0.5, 0.9], x + 0.1 * x**2 + 0.001 * x**3)


FS_89C, N_89C, P_89C = 4e9, 8000, 6  # f0 = 0.5 MHz; band [700, 1100] MHz = bins 1400..2200


def run_89c(bins, rng, run_id="a", realization=None):
    return simulate(run_id, multisine(N_89C, bins, 1.0, rng), wh_89c, P_89C, rng, fs=FS_89C, noise_u=0.1,
                    noise_y=0.2, bins=bins, realization=realization)


def test_exercise_89c_detection_lines():
    """Ex 89.c: odd-random grid (F_group = 3) in [700, 1100] MHz, P = 6, noise 0.1 on u, 0.2 on y.

    - input detection lines hold noise only: 95% pass (6-50) (book: 95.0%);
    - second-order products of the band fall in [0, 400] and [1400, 2200] MHz (even lines) and
      third-order ones in [300, 1500] MHz and their alias (odd lines): so even lines in
      (400, 1400) MHz, in band included, and odd lines below 300 MHz hold noise only, while the
      in-band odd lines and the even lines below 400 MHz carry distortion (book: in-band distortion
      odd only, even out of band in [0, 400] MHz).
    """
    rng = np.random.default_rng(89)
    level = analyse([run_89c(odd_random_bins(1400, 2200, 3, rng), rng)])
    lines, fast = level.lines, level.fast
    f = lines.frequency(np.arange(lines.period // 2 + 1))
    detection = np.flatnonzero(lines.kind > 0)
    assert np.mean(fast.fraction_significant_u[detection]) == pytest.approx(0.05, abs=null_tolerance(detection.size))
    even = np.flatnonzero((lines.kind == EVEN) & (f > 400e6) & (f < 1400e6))
    odd_low = np.flatnonzero((lines.kind == ODD) & (f < 300e6))
    for quiet in (even, odd_low):
        assert np.mean(fast.fraction_significant_y[quiet]) == pytest.approx(0.05, abs=null_tolerance(quiet.size))
    odd_in = lines.detection(ODD)
    even_low = np.flatnonzero((lines.kind == EVEN) & (f < 400e6))
    for loud in (odd_in, even_low):
        assert np.mean(fast.fraction_significant_y[loud]) > 0.05 + null_tolerance(loud.size) + 0.4
    summary = level.summary()["spectrum"]
    assert summary["odd_above_noise_db"] > 10 and abs(summary["even_above_noise_db"]) < 1.0


def test_exercise_89c_full_random_grid_has_3_db_more_noise():
    """(6-102): same period, F_group and rms, the full-random BLA has twice the noise variance of the
    odd-random one (half the power per line). The full grid's noise variance is interpolated to the
    odd grid's lines. Each band mean has relative spread 1/sqrt(5 n_eff) (10 dof per line), where
    n_eff = (sum w)^2 / sum w^2 counts the lines that matter (w: the per-line variances, dominated
    by the resonance, where |G|^2 amplifies the input noise); the ratio is 2 within
    4 sqrt(2/(5 n_eff))."""
    rng = np.random.default_rng(102)
    odd = analyse([run_89c(odd_random_bins(1400, 2200, 3, rng), rng)])
    full = analyse([run_89c(full_random_bins(1400, 2200, 3, rng), rng)])
    f_odd = odd.lines.frequency(odd.lines.excited)
    f_full = full.lines.frequency(full.lines.excited)
    ratio = np.mean(np.interp(f_odd, f_full, full.fast.var_noise)) / np.mean(odd.fast.var_noise)
    w = odd.fast.var_noise
    n_eff = np.sum(w) ** 2 / np.sum(w**2)
    assert ratio == pytest.approx(2.0, rel=4 * np.sqrt(2 / (5 * n_eff)))


def test_robust_and_fast_agree_on_the_nonlinear_variance():
    """Ex 91: on the same runs (M = 20, P = 6, as in the book) the rms-averaged fast estimate of
    var(G_S) equals the robust one. The band means are dominated by the few lines near the
    resonance, so their spread is larger than a count of all lines suggests: over 16 seeds at
    M = 10 the difference was +0.18 dB on average (linear interpolation of the detection-line power
    over the convex resonance peak) with a standard deviation of 0.22 dB, i.e. about 0.16 dB at
    M = 20; 1 dB is more than 5 standard deviations."""
    rng = np.random.default_rng(91)
    bins = odd_random_bins(1400, 2200, 3, rng)
    level = analyse([run_89c(bins, rng, f"r{m}", m) for m in range(20)])
    robust = np.mean(level.robust.var_nl)
    fast = np.mean(level.fast.var_nl)
    assert 10 * np.log10(fast / robust) == pytest.approx(0.0, abs=1.0)


def test_static_nonlinearities_odd_and_even_lines():
    """y = u^3 puts energy on odd detection lines only; y = u + a u^2 on even lines only (book (5-4),
    Section 5.1): the other class passes the detection test at the 95% rate."""
    rng = np.random.default_rng(54)
    bins = odd_random_bins(1, 301, 3, rng)
    for system, loud, quiet in ((lambda u: u**3, ODD, EVEN), (lambda u: u + 0.2 * u**2, EVEN, ODD)):
        level = analyse(runs_of_level(4, 4096, bins, 1.0, system, 3, rng, noise_y=1e-3))
        fast = level.fast
        quiet_lines = level.lines.detection(quiet, None)
        loud_lines = level.lines.detection(loud)
        n = quiet_lines.size * fast.n_runs
        assert np.mean(fast.fraction_significant_y[quiet_lines]) == pytest.approx(0.05, abs=null_tolerance(n))
        assert np.mean(fast.fraction_significant_y[loud_lines]) > 0.99


def test_exercise_89e_even_distorted_input_biases_the_even_level():
    """Ex 89.e, (6-71)/(6-72): with beta x^3 and no even nonlinearity, even input lines at -20 dB
    (constant amplitude, random phase) make the even output lines carry 3 beta (o^2 - mean o^2) e
    (o, e: odd and even parts of the input), which the impurity correction does not remove: the
    measured even level is at least the power of that term at the even lines (computed here
    directly from the signals), and the (6-72) check warns. With a pure input the even lines hold
    noise only. The measured level exceeds the mixing term by the incoherent |G_S(l)|^2 |E(l)|^2 of
    the single-run BLA that the correction (6-52) interpolates: var(G_S) |E|^2 is about 10% of the
    mixing term here (+0.45 dB, spread 0.06 dB over 12 seeds); we accept 0 to 1 dB."""
    rng = np.random.default_rng(895)
    N, P, M, beta = 4096, 2, 6, 0.05
    bins = odd_random_bins(9, 801, 2, rng)
    even_in = np.arange(10, 801, 2)
    A = np.sqrt(2 / bins.size)  # excited amplitude at rms 1

    def system(x):
        return x + beta * x**3

    pure = analyse(runs_of_level(M, N, bins, 1.0, system, P, rng, noise_u=1e-4, noise_y=1e-4))
    assert not any("even distortion level" in w for w in pure.warnings)
    even = pure.lines.detection(EVEN)
    n = even.size * M
    assert np.mean(pure.fast.fraction_significant_y[even]) == pytest.approx(0.05, abs=null_tolerance(n))

    runs, predicted = [], []
    for m in range(M):
        odd_part = multisine(N, bins, 1.0, rng)
        even_part = multisine(N, even_in, 0.1 * A * np.sqrt(even_in.size / 2), rng)  # amplitude A/10: -20 dB
        runs.append(simulate(f"r{m}", odd_part + even_part, system, P, rng, noise_u=1e-4, noise_y=1e-4,
                             realization=m, bins=bins))
        bias = 3 * beta * (odd_part**2 - np.mean(odd_part**2)) * even_part
        predicted.append(np.abs(spectra(bias[None, :])[0]) ** 2)
    distorted = analyse(runs)
    assert any("even distortion level may be overestimated" in w for w in distorted.warnings)
    measured = np.mean(distorted.fast.Yc_power[even] - distorted.fast.Yc_noise[even])
    expected = np.mean(np.mean(predicted, axis=0)[even])
    assert 0.0 < 10 * np.log10(measured / expected) < 1.0
    assert np.mean(distorted.fast.fraction_significant_y[even]) > 0.9


def test_fast_method_on_a_linear_system_with_input_and_output_noise():
    """A linear system: the corrected detection lines (6-52)/(6-53) hold noise only, so the
    extrapolated total variance (6-55) equals the noise variance (6-49) and var(G_S) (6-56) is not
    significant; the noise variance of the mean of M fast runs is (s_y^2 + |G|^2 s_u^2)/(N |U0|^2 P M).
    Band means of the ratios to that value: the noise variance has 2(P-1) dof per line and run; the
    detection-line powers are exponential (2 dof) per line and run, n_det of them per run."""
    rng = np.random.default_rng(31)
    b, a = signal.butter(2, 0.2)
    N, M, P, su, sy = 2048, 6, 4, 0.02, 0.01
    bins = odd_random_bins(1, 401, 3, rng)
    level = analyse(runs_of_level(M, N, bins, 1.0, lambda u: signal.lfilter(b, a, u), P, rng, noise_u=su,
                                  noise_y=sy))
    fast, F = level.fast, bins.size
    _, G = signal.freqz(b, a, worN=2 * np.pi * bins / N)
    U2 = (np.sqrt(2 / F) / 2) ** 2
    expected = (sy**2 + np.abs(G) ** 2 * su**2) / (N * U2 * P * M)
    assert np.mean(fast.var_noise / expected) == pytest.approx(1.0, abs=4 / np.sqrt((P - 1) * M * F))
    n_det = level.lines.bla_detection().size
    assert np.mean(fast.var_total / expected) == pytest.approx(1.0, abs=4 / np.sqrt(M * n_det))
    # var(G_S) of one realization is (total - noise) of one run, M times the variances of the mean:
    # zero within the same spread.
    assert abs(np.mean(fast.var_nl / (M * expected))) < 4 / np.sqrt(M * n_det)
