"""Robust method (book Section 6.1.1, Exercises 88.a-c) against theory.

Tolerances: a band mean of F per-line variance estimates, each a scaled chi-square with d degrees
of freedom, has relative standard deviation 1/sqrt(d F/2) (lines are independent for random-phase
multisines, book (5-69)); we allow 4 such standard deviations. Fractions of lines inside a 95%
region are binomial: 0.95 +- 4 sqrt(0.95 0.05 / F).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal, stats

from generators.bla_cases import multisine, odd_random_bins, runs_of_level, simulate  # noqa: E402

from nlsid.analysis.bla import RobustAccumulator  # noqa: E402
from nlsid.analysis.levels import analyse_runs  # noqa: E402
from nlsid.analysis.period_stats import period_stats  # noqa: E402
from nlsid.errors import InputError  # noqa: E402


def analyse(runs, method="auto"):
    levels, warnings = analyse_runs(((run, run.run_id) for run in runs), method)
    return levels


def inside_fraction(G_hat, G_true, radius):
    return float(np.mean(np.abs(G_hat - G_true) <= radius))


def binomial_tolerance(n, p=0.95):
    return 4 * np.sqrt(p * (1 - p) / n)


def complex_normal(rng, shape, variance):
    return np.sqrt(variance / 2) * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))


def test_variance_scaling_of_the_robust_method():
    """Digest 11.1, book (6-5): E sigma^2_tot = s2/M + n2/(MP), E sigma^2_n = n2/(MP), M(tot - n) -> s2.

    Synthetic one-period spectra G^[m,p] = G + G_S^[m] + N^[m,p] with circular normal G_S, N and
    U = 1 at F lines, turned into time-domain periods by an inverse DFT.
    """
    rng = np.random.default_rng(11)
    F, M, P, s2, n2, G = 3000, 5, 4, 0.3, 0.2, 2.0 - 1.0j
    N = 2 * F + 2
    bins = np.arange(1, F + 1)
    acc = RobustAccumulator(bins, "frf")
    for m in range(M):
        U = np.zeros((P, N // 2 + 1), complex)
        U[:, bins] = 1.0
        Y = np.zeros_like(U)
        Y[:, bins] = G + complex_normal(rng, F, s2) + complex_normal(rng, (P, F), n2)
        acc.add(period_stats(np.fft.irfft(U * N, n=N), np.fft.irfft(Y * N, n=N)))
    result = acc.result()
    # total variance: 2(M-1) dof per line; noise variance: 2M(P-1) dof per line (pooled over M).
    tot_tol = 4 / np.sqrt((M - 1) * F)
    noise_tol = 4 / np.sqrt(M * (P - 1) * F)
    assert np.mean(result.var_total) == pytest.approx(s2 / M + n2 / (M * P), rel=tot_tol)
    assert np.mean(result.var_noise) == pytest.approx(n2 / (M * P), rel=noise_tol)
    assert np.mean(result.var_noise_period) == pytest.approx(n2, rel=noise_tol)
    # var_nl = M (tot - n): its spread is dominated by the total variance term, M/(M-1)... of s2 + n2/P.
    assert np.mean(result.var_nl) == pytest.approx(s2, abs=tot_tol * (s2 + n2 / P))
    assert np.mean(result.G) == pytest.approx(G, abs=4 * np.sqrt((s2 / M + n2 / (M * P)) / F))


def test_linear_system_with_noise_frf_method():
    """A linear system: G_BLA = G(e^jw) inside the 95% circles at 95% of the lines, no significant
    nonlinear variance, and the noise variance equals the injected white noise sigma^2/N / |U|^2."""
    rng = np.random.default_rng(5)
    b, a = signal.cheby1(2, 3, 0.3)
    # M = 4 makes the finite-sample F(2, 6) quantile matter: the chi-square radius (6-87) would
    # cover only 1 - 2^-3 = 87.5% of the lines.
    N, M, P, sigma, rms = 1024, 4, 4, 0.02, 1.0
    bins = np.arange(1, 301)
    runs = runs_of_level(M, N, bins, rms, lambda u: signal.lfilter(b, a, u), P, rng, noise_y=sigma)
    level = analyse(runs, "frf")[0]
    robust = level.robust
    F = bins.size
    _, G_true = signal.freqz(b, a, worN=2 * np.pi * bins / N)
    frac = inside_fraction(robust.G, G_true, robust.bounds.radius)
    assert frac == pytest.approx(0.95, abs=binomial_tolerance(F))
    # |U(k)|^2 = (A/2)^2 with A = rms sqrt(2/F); white noise gives E|N(k)|^2 = sigma^2/N per period.
    U2 = (rms * np.sqrt(2 / F) / 2) ** 2
    noise_dof = 2 * M * (P - 1) * F
    assert np.mean(robust.var_noise_period) == pytest.approx(sigma**2 / N / U2, rel=4 * np.sqrt(2 / noise_dof))
    # No nonlinearity: total and noise variance estimate the same quantity; the band-mean ratio
    # has relative spread sqrt(1/((M-1) F) + 1/(M (P-1) F)) (2(M-1) and 2M(P-1) dof per line).
    ratio = np.mean(robust.var_total) / np.mean(robust.var_noise)
    assert ratio == pytest.approx(1.0, abs=4 * np.sqrt(1 / ((M - 1) * F) + 1 / (M * (P - 1) * F)))


def test_errors_in_variables_noise_variance():
    """Noisy input and output (io method, (6-19)-(6-20)): var(N_G) = (s_y^2 + |G|^2 s_u^2)/(N |U0|^2)."""
    rng = np.random.default_rng(6)
    b, a = [0.5, 0.2], [1.0, -0.4]
    N, M, P, su, sy, rms = 512, 6, 5, 0.01, 0.03, 1.0
    bins = np.arange(1, 151)
    runs = runs_of_level(M, N, bins, rms, lambda u: signal.lfilter(b, a, u), P, rng, noise_u=su, noise_y=sy)
    robust = analyse(runs, "io")[0].robust
    _, G = signal.freqz(b, a, worN=2 * np.pi * bins / N)
    U2 = (rms * np.sqrt(2 / bins.size) / 2) ** 2
    expected = (sy**2 + np.abs(G) ** 2 * su**2) / N / U2
    dof = 2 * M * (P - 1) * bins.size
    assert np.mean(robust.var_noise_period / expected) == pytest.approx(1.0, abs=4 * np.sqrt(2 / dof))
    frac = inside_fraction(robust.G, G, robust.bounds.radius)
    assert frac == pytest.approx(0.95, abs=binomial_tolerance(bins.size))


def test_correlated_input_and_output_noise():
    """One noise source n in both channels (u = u0 + n, y = G u0 + n): the covariance term of (6-49)
    matters, var(N_G) = |1 - G|^2 s^2 / (N |U0|^2)."""
    rng = np.random.default_rng(7)
    b, a = [0.5, 0.2], [1.0, -0.4]
    N, M, P, sn, rms = 512, 6, 5, 0.02, 1.0
    bins = np.arange(1, 151)
    runs = runs_of_level(M, N, bins, rms, lambda u: signal.lfilter(b, a, u), P, rng)
    for run in runs:
        n = sn * rng.standard_normal(run.u.size)
        run.u, run.y = run.u + n, run.y + n
    robust = analyse(runs, "io")[0].robust
    _, G = signal.freqz(b, a, worN=2 * np.pi * bins / N)
    U2 = (rms * np.sqrt(2 / bins.size) / 2) ** 2
    expected = np.abs(1 - G) ** 2 * sn**2 / N / U2
    dof = 2 * M * (P - 1) * bins.size
    assert np.mean(robust.var_noise_period / expected) == pytest.approx(1.0, abs=4 * np.sqrt(2 / dof))


def test_closed_loop_reference_method_recovers_the_plant():
    """Closed loop u = r - y, y = G u + v (process noise v): the reference method (6-26)-(6-34) gives
    the plant G (the ratio of the BLAs r -> y and r -> u) inside its 95% circles at 95% of lines."""
    rng = np.random.default_rng(8)
    b, a = np.array([0.0, 0.6]), np.array([1.0, -0.7])
    N, M, P, sv, rms = 512, 10, 4, 0.05, 1.0
    bins = np.arange(1, 121)
    a_cl = a + b

    def loop_run(m):
        r_period = multisine(N, bins, rms, rng)
        r = np.tile(r_period, P + 1)
        v = sv * rng.standard_normal(r.size)
        y = signal.lfilter(b, a_cl, r) + signal.lfilter(a, a_cl, v)
        run = simulate(f"r{m}", r_period, lambda x: x, P, rng, realization=m, bins=bins, reference=True)
        run.u, run.y = r - y, y
        return run

    level = analyse([loop_run(m) for m in range(M)])[0]
    assert level.robust.method == "reference"
    _, G = signal.freqz(b, a, worN=2 * np.pi * bins / N)
    frac = inside_fraction(level.robust.G, G, level.robust.bounds.radius)
    assert frac == pytest.approx(0.95, abs=binomial_tolerance(bins.size))
    assert not any("actuator" in w for w in level.warnings)


def standard_error_of_band_mean(runs):
    """Standard error of the band mean of Re G_BLA from the spread of the per-realization band means.

    The stochastic distortions of different lines of one realization are correlated (for a cubic
    the scatter over lines underestimates the error of the band mean about 2x), while realizations
    are independent: their band means give an honest standard error.
    """
    means = [np.mean(analyse([run])[0].robust.G.real) for run in runs]
    return np.std(means, ddof=1) / np.sqrt(len(means))


def t_tolerance(runs):
    """Half-width of a two-sided t-test at false-alarm rate 1e-3 on the band mean (M - 1 dof)."""
    return stats.t.ppf(1 - 5e-4, len(runs) - 1) * standard_error_of_band_mean(runs)


def test_bussgang_gain_of_a_cubic():
    """y = u^3, random-phase multisine of rms s with F equal lines: G_BLA = 3 s^2 (1 - 1/(2F)).

    [derived] The phase-coherent terms of u^3 at line k are the triples (k, l, -l): 6 orderings for
    l != k and 3 for l = k, so E{Y(k)/U(k)} = 3 s^2 - 3 A^2/4 = 3 s^2 (1 - 1/(2F)): Bussgang's
    3 s^2 (book (5-24), Gaussian) up to the O(1/F) term of (5-42). Tolerance: a t-test at
    false-alarm rate 1e-3 on the band mean over M = 16 independent realizations.
    """
    rng = np.random.default_rng(3)
    N, s, M = 2048, 0.7, 16
    bins = odd_random_bins(1, 301, 3, rng)
    F = bins.size
    runs = runs_of_level(M, N, bins, s, lambda u: u**3, 2, rng, noise_y=1e-4)
    robust = analyse(runs)[0].robust
    assert np.mean(robust.G.real) == pytest.approx(3 * s**2 * (1 - 1 / (2 * F)), abs=t_tolerance(runs))
    # The cubic adds stochastic distortion far above the noise: var(G_S) dominates var(N_G).
    assert np.mean(robust.var_nl) > 100 * np.mean(robust.var_noise_period)


def test_even_nonlinearity_leaves_the_bla_of_an_odd_multisine_alone():
    """y = u + a u^2 with an odd multisine: u^2 only reaches even lines, so G_BLA = 1 exactly (Ex 85)
    and the excited lines carry no nonlinear variance (total = noise within 4 sigma)."""
    rng = np.random.default_rng(4)
    N, M, P, sigma = 1024, 8, 3, 1e-3
    bins = odd_random_bins(1, 201, 3, rng)
    level = analyse(runs_of_level(M, N, bins, 1.0, lambda u: u + 0.3 * u**2, P, rng, noise_y=sigma))[0]
    robust, F = level.robust, bins.size
    assert inside_fraction(robust.G, 1.0, robust.bounds.radius) == pytest.approx(0.95, abs=binomial_tolerance(F))
    ratio = np.mean(robust.var_total) / np.mean(robust.var_noise)
    assert ratio == pytest.approx(1.0, abs=4 * np.sqrt(1 / ((M - 1) * F) + 1 / (M * (P - 1) * F)))


def test_one_realization_or_one_period_warns_instead_of_failing():
    rng = np.random.default_rng(9)
    bins = np.arange(3, 40, 2)
    one_m = analyse(runs_of_level(1, 256, bins, 1.0, lambda u: u, 3, rng, noise_y=0.01))[0]
    assert np.all(np.isnan(one_m.robust.var_total)) and np.all(np.isfinite(one_m.robust.var_noise))
    assert any("M = 1" in w for w in one_m.warnings)
    one_p = analyse(runs_of_level(3, 256, bins, 1.0, lambda u: u, 1, rng, noise_y=0.01))[0]
    assert np.all(np.isnan(one_p.robust.var_noise)) and np.all(np.isfinite(one_p.robust.var_total))
    assert any("P = 1" in w for w in one_p.warnings)


@pytest.mark.parametrize("change, message", [
    ("period", "one level needs one period"),
    ("bins", "must excite the same lines"),
    ("periods", "the same P"),
    ("realization", "new realization"),
])
def test_runs_of_one_level_must_agree(change, message):
    rng = np.random.default_rng(10)
    bins = np.arange(3, 40, 2)
    runs = runs_of_level(2, 256, bins, 1.0, lambda u: u, 3, rng, level=1.0)
    other = runs[1]
    if change == "period":
        runs[1] = simulate("x", multisine(512, bins, 1.0, rng), lambda u: u, 3, rng, level=1.0, bins=bins)
    elif change == "bins":
        other.excited_bins = bins + 2
    elif change == "periods":
        runs[1] = simulate("x", multisine(256, bins, 1.0, rng), lambda u: u, 4, rng, level=1.0, bins=bins)
    else:
        other.realization = runs[0].realization
    with pytest.raises(InputError, match=message):
        analyse(runs)


def test_levels_are_grouped_and_sorted():
    """Interleaved runs of two levels give the same results as each level analysed alone, sorted by
    level; the cubic term makes the BLA grow with the level (Bussgang: 1 + 0.3 s^2, (5-24))."""
    rng = np.random.default_rng(12)
    bins = np.arange(3, 80, 2)
    runs = {}
    for s in (2.0, 0.5):
        runs[s] = runs_of_level(4, 512, bins, s, lambda u: u + 0.1 * u**3, 2, rng, level=s)
        for i, run in enumerate(runs[s]):
            run.run_id = f"s{s:g}_{i}"
    mixed = [run for pair in zip(runs[2.0], runs[0.5]) for run in pair]
    levels = analyse(mixed)
    assert [lvl.level for lvl in levels] == [0.5, 2.0]
    assert [lvl.n_realizations for lvl in levels] == [4, 4]
    for lvl in levels:
        alone = analyse(runs[lvl.level])[0]
        np.testing.assert_array_equal(lvl.robust.G, alone.robust.G)
        np.testing.assert_array_equal(lvl.robust.var_total, alone.robust.var_total)
    # Expected 0.3 (2^2 - 0.5^2) = 1.125 apart; the band mean at s = 2 with M = 4 scatters by about
    # 0.08 (spread of per-realization band means, see standard_error_of_band_mean), so 0.5 is safe.
    assert np.mean(levels[1].robust.G.real) - np.mean(levels[0].robust.G.real) > 0.5


def test_excited_bin_without_input_is_an_input_error():
    rng = np.random.default_rng(13)
    bins = np.arange(3, 40, 2)
    runs = runs_of_level(2, 256, bins, 1.0, lambda u: u, 2, rng)
    for run in runs:
        run.excited_bins = np.append(bins, 41)
    with pytest.raises(InputError, match="excited bin 41 carries no input"):
        analyse(runs)


def test_frf_method_with_a_recorded_reference_warns():
    """--method frf ignores r: the level says the noise variance is then under-estimated."""
    rng = np.random.default_rng(3)
    bins = odd_random_bins(1, 60, 3, rng)
    runs = runs_of_level(3, 256, bins, 1.0, lambda u: 0.5 * u, 2, rng, noise_y=0.01, reference=True)
    with_r = analyse(runs, "frf")[0]
    assert any("--method frf while the runs carry the reference r" in w for w in with_r.warnings)
    without = analyse(runs_of_level(3, 256, bins, 1.0, lambda u: 0.5 * u, 2, rng, noise_y=0.01), "frf")[0]
    assert not any("reference r" in w for w in without.warnings)


def test_plant_distortion_fed_back_is_not_called_an_actuator_nonlinearity():
    """Closed loop u = r - y around a plant with a cubic term and a linear actuator: the plant's
    distortion reaches u through the controller, so u varies over realizations far beyond its
    noise (book (6-40)-(6-43)). The warning states what was measured, distortion at the plant input,
    and that in closed loop the plant's own distortion fed back explains it as well as an actuator."""
    rng = np.random.default_rng(21)
    N, M, P, rms = 512, 8, 3, 0.6
    bins = np.arange(1, 121)

    def loop(r):  # y[k+1] = 0.7 y[k] + 0.5 u[k] - 0.3 y[k]^3, u[k] = r[k] - y[k] (noise on y)
        y, u = np.zeros(r.size), np.zeros(r.size)
        for k in range(r.size - 1):
            u[k] = r[k] - y[k]
            y[k + 1] = 0.7 * y[k] + 0.5 * u[k] - 0.3 * y[k] ** 3
        u[-1] = r[-1] - y[-1]
        return u, y

    runs = []
    for m in range(M):
        r_period = multisine(N, bins, rms, rng)
        run = simulate(f"r{m}", r_period, lambda x: x, P, rng, realization=m, bins=bins, reference=True)
        u, y = loop(run.r)
        run.u, run.y = u, y + 1e-3 * rng.standard_normal(y.size)
        runs.append(run)
    warnings = analyse(runs)[0].warnings
    text = " ".join(warnings)
    assert "reaches the plant input" in text and "fed back by the controller" in text, warnings
    assert "the actuator is nonlinear" not in text


@pytest.mark.parametrize("block_bytes", [1 << 21, 3 * 16 * 257])
def test_period_stats_batched_transforms_change_no_bit(monkeypatch, block_bytes):
    """u and y deviations (and the means of u, y, r) are transformed in one rfft each: the result
    is bit for bit that of one rfft per signal, with one block of periods or several (3 rows)."""
    import nlsid.analysis.period_stats as ps
    from nlsid.analysis.lines import spectra

    monkeypatch.setattr(ps, "_BLOCK_BYTES", block_bytes)
    rng = np.random.default_rng(3)
    u, y, r = (rng.standard_normal((7, 512)) for _ in range(3))
    got = ps.period_stats(u, y, r)
    means = [x.mean(axis=0) for x in (u, y, r)]
    var_u, var_y, cov_yu = np.zeros(257), np.zeros(257), np.zeros(257, complex)
    rows = max(1, block_bytes // (16 * 257))
    for start in range(0, 7, rows):
        dU = np.fft.rfft(u[start:start + rows] - means[0], axis=-1)
        dY = np.fft.rfft(y[start:start + rows] - means[1], axis=-1)
        var_u += ps._real_products(dU, dU)
        var_y += ps._real_products(dY, dY)
        cov_yu += ps._cross_products(dY, dU)
    scale = 1.0 / (7 * 6 * 512 * 512)
    for field, expected in [("U", spectra(means[0])), ("Y", spectra(means[1])), ("R", spectra(means[2])),
                            ("var_u", var_u * scale), ("var_y", var_y * scale), ("cov_yu", cov_yu * scale)]:
        assert np.array_equal(getattr(got, field), expected), field
