"""The Local Polynomial Method against data made here by an independent method: an exact zero-order-hold
discretisation of a continuous-time resonance (matrix exponential), the output sampled a fraction of a
sample late (converter skew), DC offsets on both channels, coloured output noise and a start from a
random state (a transient), under band-limited noise that is not periodic (leakage everywhere).

Truth: the FRF of that sampled system, in closed form. The LPM's claims checked by Monte Carlo:
its 95 % circles hold the truth about 95 % of the time on lines one window apart (independent), and
its residual variance is unbiased for the noise variance per line, within the statistics of its
degrees of freedom.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from generators.lpm_cases import (FS, band, binomial_band, closed_loop_record, measured_record,  # noqa: E402
                       noise_variance_per_line, true_frf)

from nlsid.analysis.lpm import degrees_of_freedom, hpd_inverse, lpm  # noqa: E402


def test_coverage_and_noise_variance_one_record():
    rng = np.random.default_rng(20261201)
    sigma = 0.02
    hits, ratios = [], []
    for _ in range(30):
        u, y = measured_record(rng, sigma)
        result = lpm(u, y, FS)
        sel = band(result)
        error = np.abs(result.G[sel] - true_frf(result.lines[sel]))
        hits.append(error <= result.bounds(0.95).radius[sel])
        ratios.append(result.var_y[sel] / noise_variance_per_line(result.lines[sel], sigma))
    hits, ratios = np.concatenate(hits), np.concatenate(ratios)
    assert result.dof == 1 == degrees_of_freedom(1, 3, 2)
    assert abs(hits.mean() - 0.95) < binomial_band(0.95, hits.size), hits.mean()
    # var_y / truth ~ chi2(2q)/(2q): mean 1, variance 1/q per line
    assert abs(ratios.mean() - 1) < 4 / math.sqrt(result.dof * ratios.size), ratios.mean()


def test_joint_records_share_the_frf_and_gain_degrees_of_freedom():
    """Four records, each with its own transient: q = 4*7 - 5*3 = 13; the variance estimate then
    scatters as chi2(26)/26, so its spread is checked as well as its mean."""
    rng = np.random.default_rng(7)
    sigma = 0.02
    hits, ratios = [], []
    for _ in range(12):
        records = [measured_record(rng, sigma) for _ in range(4)]
        result = lpm(np.array([r[0] for r in records]), np.array([r[1] for r in records]), FS)
        sel = band(result)
        hits.append(np.abs(result.G[sel] - true_frf(result.lines[sel])) <= result.bounds(0.95).radius[sel])
        ratios.append(result.var_y[sel] / noise_variance_per_line(result.lines[sel], sigma))
    hits, ratios = np.concatenate(hits), np.concatenate(ratios)
    assert result.dof == 13 and result.n_records == 4
    assert abs(hits.mean() - 0.95) < binomial_band(0.95, hits.size), hits.mean()
    assert abs(ratios.mean() - 1) < 4 / math.sqrt(13 * ratios.size), ratios.mean()
    assert abs(ratios.var() - 1 / 13) < 0.35 / 13, ratios.var()


def test_closed_loop_indirect_ratio_is_covered():
    """The indirect ratio through the reference (book (6-75)-(6-77)) with noise on both recorded
    signals: its first-order circles cover at high SNR."""
    rng = np.random.default_rng(99)
    hits = []
    for _ in range(30):
        r, y, u = closed_loop_record(rng, sigma_y=0.05, sigma_u=0.01)
        result = lpm(r, np.stack([y, u]), FS)
        sel = band(result)
        hits.append(np.abs(result.G[sel] - true_frf(result.lines[sel])) <= result.bounds(0.95).radius[sel])
    hits = np.concatenate(hits)
    assert result.G_yr is not None and result.var_u is not None
    assert abs(hits.mean() - 0.95) < binomial_band(0.95, hits.size), hits.mean()


def test_exact_for_a_polynomial_transient_and_frf_without_noise():
    """With no noise, an FRF and a transient that are quadratic in the line offset are fitted exactly."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal(512)
    X = np.fft.rfft(x) / 512
    k = np.arange(X.size)
    G = 1.0 + 0.01j * k - 2e-5 * k ** 2
    T = 0.3 - 0.002 * k + 1e-6j * k ** 2
    y = np.fft.irfft((G * X + T) * 512, n=512)
    result = lpm(x, y, 1.0)
    inner = slice(3, -3)   # irfft drops the imaginary part at DC; the polynomial holds elsewhere
    np.testing.assert_allclose(result.G[inner], G[1:result.lines.size + 1][inner], atol=1e-9)


def test_hpd_inverse_against_numpy():
    rng = np.random.default_rng(5)
    B = rng.standard_normal((40, 3, 3)) + 1j * rng.standard_normal((40, 3, 3))
    A = B @ np.conj(np.swapaxes(B, -1, -2)) + 0.1 * np.eye(3)
    got = np.moveaxis(hpd_inverse(np.moveaxis(A, 0, -1)), -1, 0)
    np.testing.assert_allclose(got, np.linalg.inv(A), rtol=1e-10, atol=1e-12)


def test_too_short_or_no_degrees_of_freedom():
    with pytest.raises(ValueError, match="fewer than the window"):
        lpm(np.ones(10), np.ones(10), 1.0)
    with pytest.raises(ValueError, match="degrees of freedom"):
        lpm(np.ones(100), np.ones(100), 1.0, half_width=2, degree=2)


def test_smoothed_variance_is_unbiased_with_at_least_its_stated_degrees_of_freedom():
    """The disturbance variance averaged over B lines (the fit's weight): its ratio to the true
    noise variance averaged over the same lines (computed here from the noise filter) has mean 1
    and a variance at most 1/smoothed_dof, smoothed_dof = q B / 7 (docs/lpm.md); lines B apart, so
    the averages are independent. Measured when written: variance 1/43 for the stated 1/19.9."""
    rng = np.random.default_rng(20261205)
    sigma = 0.02
    ratios = []
    for _ in range(30):
        u, y = measured_record(rng, sigma)
        result = lpm(u, y, FS)
        B = result.smoothing_lines
        lines = result.lines
        interior = np.arange(B, lines.size - B, B)
        truth = np.convolve(noise_variance_per_line(lines, sigma), np.ones(B) / B, mode="same")[interior]
        smoothed_c = (result.var_G_smoothed / result.var_G * result.var_y)[interior]
        ratios.append(smoothed_c / truth)
    ratios = np.concatenate(ratios)
    assert result.dof == 1 and B == 139 and result.smoothed_dof == pytest.approx(139 / 7)
    assert abs(ratios.mean() - 1) < 4 / math.sqrt(result.smoothed_dof * ratios.size), ratios.mean()
    # variance of a sample variance from ratios.size values: a 3-sigma allowance above 1/dof
    assert ratios.var() < (1 / result.smoothed_dof) * (1 + 3 * math.sqrt(2 / ratios.size)), ratios.var()


def test_no_smoothing_where_the_degrees_of_freedom_suffice():
    """Twenty records give q = 20*7 - 21*3 = 77 >= 20: the weight is the per-line variance."""
    rng = np.random.default_rng(3)
    records = [measured_record(rng, 0.02) for _ in range(20)]
    result = lpm(np.array([r[0] for r in records]), np.array([r[1] for r in records]), FS)
    assert result.dof == 77 and result.smoothing_lines == 1
    assert np.array_equal(result.var_G_smoothed, result.var_G, equal_nan=True)
