"""Measured HOSIDFs (seed 000 Eqs. 8-12, seed 002 Def. 2) and seed 003 Table I statistics."""

import numpy as np
import pytest
from scipy.signal import lfilter

from nlsid.analysis.hosidf import measured_hosidf, table_one
from nlsid.analysis.hosidf_analytic import Branch, discrete_response, lpl_hosidf
from nlsid.errors import InputError
from nlsid.io.run import Run

FS = 1000.0
N = 200
G1P = ([0.2, 0.1], [1.0, -0.7])
G2M = ([0.05, 0.05], [1.0, -0.9])
A1, A3, B1, B2 = 0.8, -0.4, 1.5, 0.6


def two_branch(u):
    """Seed 002 Fig. 2: (a1 q + a3 q^3 -> G1+) + (G2- -> b1 q + b2 q^2), built with lfilter."""
    q = lfilter(*G2M, u)
    return lfilter(*G1P, A1 * u + A3 * u**3) + B1 * q + B2 * q**2


def sine_run(run_id, line, amplitude, system, periods=2, transient=12, noise=0.0, rng=None, phase=0.0, **kw):
    """A single-sine run as `design` writes it: u = a sin(2 pi line n / N + phase), y = system(u) (+ noise)."""
    n = np.arange((transient + periods) * N)
    u = amplitude * np.sin(2 * np.pi * line * n / N + phase)
    y = system(u)
    if noise:
        y = y + noise * rng.standard_normal(y.size)
    return Run(run_id=run_id, fs=FS, kind="sine", u=u, y=y, period=N, transient_periods=transient,
               level=amplitude, frequency=line * FS / N, **kw)


def test_noise_free_two_branch_lpl_equals_analytic():
    """Issue acceptance: measured = Lemma 2 to 1e-9 relative (noise-free, steady state after 0.9^2400)."""
    lines, amplitudes = [1, 4, 9], [0.3, 1.0, 1.7]
    runs = [sine_run(f"r{l}_{a}_{r}", l, a, two_branch) for l in lines for a in amplitudes for r in range(2)]
    grid = measured_hosidf(runs, harmonics=3)
    branches = [Branch((A1, 0.0, A3), post=discrete_response(*G1P, FS)), Branch((B1, B2), pre=discrete_response(*G2M, FS))]
    np.testing.assert_allclose(grid.frequencies, np.array(lines) * FS / N)
    np.testing.assert_allclose(grid.levels, amplitudes)
    measured = grid.field("h")
    for fi, line in enumerate(lines):
        for ai, a in enumerate(amplitudes):
            analytic = lpl_hosidf(branches, 2 * np.pi * line * FS / N, a)
            np.testing.assert_allclose(measured[fi, ai], analytic, rtol=1e-9, atol=1e-9 * abs(analytic).max())
    # noise-free repeats and periods are identical: both variances vanish to rounding
    assert np.nanmax(grid.field("h_var_repeats")) < 1e-25
    assert np.nanmax(grid.field("h_var_periods")) < 1e-25


def test_cubic_seed_000_and_seed_002_forms():
    """y = u^3, u = a sin(w0 t): sin^3 x = (3 sin x - sin 3x)/4 gives both HOSIDF forms by hand.

    Y(w0) = 3a^3/4 e^{-i pi/2}, Y(3w0) = a^3/4 e^{+i pi/2}, U = a e^{-i pi/2}. Seed 000 Eqs. 8-9:
    |H1| = 3a^2/4, angle 0; |H3| = a^2/4, angle pi/2 + 3 pi/2 = 0 (mod 2 pi). Seed 002 Eq. 12:
    H1 = 3a^2/4, H3 = 1/4 (independent of a).
    """
    a = 1.6
    grid = measured_hosidf([sine_run(f"c{r}", 3, a, lambda u: u**3) for r in range(2)], harmonics=3)
    np.testing.assert_allclose(grid.field("h000")[0, 0], [0, 3 * a**2 / 4, 0, a**2 / 4], atol=1e-12)
    np.testing.assert_allclose(grid.field("h")[0, 0], [0, 3 * a**2 / 4, 0, 1 / 4], atol=1e-12)


def test_variances_and_table_one_match_white_noise_theory():
    """White output noise of variance s^2: each period's phasor at k >= 1 has E|dY|^2 = 4 s^2 / N.

    So with n pooled periods sigma^2(k) = 4 s^2/(N n), and Var(H_k mean) = 4 s^2/(N n |U|^{2k}).
    A variance estimated from n complex samples has relative sd 1/sqrt(n-1); averaged over the
    K = 6 harmonic lines and 3 cells (18 estimates, n = 40): relative sd 1/sqrt(39*18) = 0.038.
    The tolerance 0.15 is 4 sd. The repeat variance uses R = 4 repeats only (3 dof each), averaged
    over 18 values: relative sd 1/sqrt(3*18) = 0.14; tolerance 0.55 (4 sd).
    """
    rng = np.random.default_rng(7)
    s, periods, repeats, amplitude = 0.05, 10, 4, 1.0
    runs = [sine_run(f"n{l}_{r}", l, amplitude, two_branch, periods=periods, noise=s, rng=rng)
            for l in (2, 5, 11) for r in range(repeats)]
    grid = measured_hosidf(runs, harmonics=6)
    n = periods * repeats
    theory = 4 * s**2 / (N * n)
    sigma2 = grid.stat("var_mean")[:, 0, 1:]
    assert np.mean(sigma2) / theory == pytest.approx(1.0, abs=0.15)
    # DC line: E|dY0|^2 = s^2 / N per period (no factor 2 in the single sided DC value)
    assert np.mean(grid.stat("var_mean")[:, 0, 0]) / (s**2 / (N * n)) == pytest.approx(1.0, abs=0.5)
    k = np.arange(1, 7)
    h_theory = theory / amplitude ** (2 * k)
    assert np.mean(grid.field("h_var_periods")[:, 0, 1:] / h_theory) == pytest.approx(1.0, abs=0.15)
    assert np.mean(grid.field("h_var_repeats")[:, 0, 1:] / h_theory) == pytest.approx(1.0, abs=0.55)
    # Eq. 6: the fundamental and third harmonic (|Y3| = |a3|/4 |G1+(3w0)| ~ 0.05 >> sigma ~ 0.005)
    # are far above the bound; the bound is sigma(k) + 2 varsigma by construction of Table I.
    significant = grid.stat("significant")
    assert significant[:, 0, 1].all() and significant[:, 0, 3].all()


def test_table_one_by_hand():
    """Table I and Eq. 6 on three spectra of K = 2 lines, worked out by hand.

    Line 1: values 1, 2, 3 (mean 2, sum of squares 2, sigma^2 = 2/6 = 1/3).
    Line 2: values 1j, 1j, 4j (mean 2j, sum 1+1+4 = 6, sigma^2 = 1).
    sigma_bar^2 = (1/3 + 1)/2 = 2/3; varsigma^2 = (sqrt(1/3) - sqrt(2/3))^2 + (1 - sqrt(2/3))^2 (K-1 = 1).
    """
    spectra = np.array([[5, 1, 1j], [5, 2, 1j], [5, 3, 4j]], dtype=complex)
    stats = table_one(spectra)
    np.testing.assert_allclose(stats.mean, [5, 2, 2j])
    np.testing.assert_allclose(stats.var_mean, [0, 1 / 3, 1])
    assert stats.avg_var == pytest.approx(2 / 3)
    varsigma2 = (np.sqrt(1 / 3) - np.sqrt(2 / 3)) ** 2 + (1 - np.sqrt(2 / 3)) ** 2
    assert stats.var_var == pytest.approx(varsigma2)
    np.testing.assert_allclose(stats.bound, np.sqrt([0, 1 / 3, 1]) + 2 * np.sqrt(varsigma2))
    np.testing.assert_array_equal(stats.significant, [True, True, True])


def test_repeats_with_different_input_phase_pool_correctly():
    """Table I pools phase-aligned spectra: repeats at phases 0 and 1 rad give zero variance (noise-free)."""
    runs = [sine_run(f"p{i}", 3, 1.0, two_branch, phase=ph) for i, ph in enumerate((0.0, 1.0))]
    grid = measured_hosidf(runs, harmonics=3)
    assert grid.stat("var_mean").max() < 1e-28
    assert grid.field("h_var_repeats").max() < 1e-25


def test_bad_input_is_reported():
    good = sine_run("ok", 3, 1.0, two_branch)
    multisine = Run(run_id="ms", fs=FS, kind="multisine", u=good.u, y=good.y, period=N, transient_periods=12,
                    excited_bins=np.array([1, 3]))
    with pytest.raises(InputError, match="kind 'sine'"):
        measured_hosidf([good, multisine], harmonics=3, source="rec.h5")
    off_bin = sine_run("off", 3, 1.0, two_branch)
    off_bin.frequency = 3.3 * FS / N
    with pytest.raises(InputError, match=r"rec.h5:/runs/off.frequency: 16.5 Hz is not on a bin"):
        measured_hosidf([off_bin], harmonics=3, source="rec.h5")
    with pytest.raises(InputError, match="1 repeat; the variance over repeats"):
        measured_hosidf([good], harmonics=3, variance="repeats", source="rec.h5")
    measured_hosidf([good], harmonics=3, variance="periods")  # two periods suffice for this one
    no_level = sine_run("nolevel", 3, 1.0, two_branch)
    no_level.level = None
    with pytest.raises(InputError, match="missing attribute 'level'"):
        measured_hosidf([no_level], harmonics=3, variance="periods")
    with pytest.raises(InputError, match="Nyquist"):
        measured_hosidf([sine_run("hi", 40, 1.0, two_branch)] * 2, harmonics=3)
