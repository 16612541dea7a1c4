"""The Local Polynomial Method for several inputs against data made here by scipy's ``lfilter``.

Every output is a sum of ``lfilter`` responses to independent white-noise inputs, started from rest
and cut after N samples: not periodic, so every line carries leakage (the transient term T). The
truth is ``freqz`` of the same filters; the transient's truth is what is left of the record's
spectrum once the truth G U is taken away, ``T(k) = Y(k) - G(k) U(k)`` (exact on noise-free data).

- Noise-free, a lightly resonant entry (pole radius 0.98): G is within the Taylor remainder of
  its local polynomial of degree R, ``|G^(R+1)| n^(R+1) / (R+1)!`` (the error of representing G
  by a quadratic over the window), and the error falls as N^-(R+1) when N grows: a factor 64 for
  4 N, asserted as at least 32 (the random input scales each line's error). T is recovered.
- With output noise correlated between the outputs: the 95 % circles of every entry cover the
  truth 95 % of the time (binomial band over lines one window apart, which share no data), and
  the residual covariance is unbiased for the noise's cross-spectrum ``Sigma / N``; averaged over
  B lines (the weights of a fit) it stays unbiased with a variance at most 1 / smoothed_dof.
- A Wiener system with a cubic: G is the Bussgang BLA within its circles, and the residual
  covariance holds the nonlinear distortion (it is no noise level).
- n_u = 1 gives the single-input LPM's numbers (:func:`nlsid.analysis.lpm.lpm`).
- Bad input is refused with an InputError naming the argument.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from generators.lpm_cases import binomial_band
from nlsid.analysis.lpm import lpm
from nlsid.analysis.lpm_mimo import degrees_of_freedom, lpm_mimo, narrowest_half_width
from nlsid.errors import InputError

RADIUS, ANGLE = 0.98, 0.6      # the resonance: pole radius and angle (rad/sample)
RESONANT = ([0.0, 1 - RADIUS], [1.0, -2 * RADIUS * math.cos(ANGLE), RADIUS ** 2])
FILTERS = {(0, 0): RESONANT, (0, 1): ([0.3], [1.0, -0.5]),
           (1, 0): ([0.0, 0.5, 0.2], [1.0, -0.2]), (1, 1): ([1.0, -0.4], [1.0, -0.7])}
SMOOTH = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (0, 1): ([0.3], [1.0, -0.5]),
          (1, 0): ([0.0, 0.5, 0.2], [1.0, -0.2]), (1, 1): ([1.0, -0.4], [1.0, -0.7])}


def respond(u: np.ndarray, filters: dict) -> np.ndarray:
    """Outputs (2, N) of the filters (output, input) -> (b, a) driven by the inputs u (n_u, N) from rest."""
    y = np.zeros((2, u.shape[-1]))
    for (i, a), (b, den) in filters.items():
        y[i] += signal.lfilter(b, den, u[a])
    return y


def truth(filters: dict, frequency: np.ndarray, fs: float = 1.0) -> np.ndarray:
    G = np.zeros((frequency.size, 2, 2), dtype=complex)
    for (i, a), (b, den) in filters.items():
        G[:, i, a] = signal.freqz(b, den, worN=frequency, fs=fs)[1]
    return G


def resonant_g(lines: np.ndarray, n_samples: int) -> np.ndarray:
    b, den = RESONANT
    return signal.freqz(b, den, worN=2 * np.pi * lines / n_samples)[1]


def noise_free(n_samples: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((2, n_samples))
    y = respond(u, FILTERS)
    return u, y, lpm_mimo(u, y, 1.0, half_width=5)


def test_noise_free_within_the_interpolation_error_falling_as_n_to_the_r_plus_1():
    errors = []
    for n_samples in (4096, 16384):
        u, y, result = noise_free(n_samples)
        G = truth(FILTERS, result.frequencies)
        offset = np.abs(2 * np.pi * result.frequencies - ANGLE)
        near, far = offset < 0.1, offset > 0.5                            # the resonance band, and away
        error = np.abs(result.G - G)
        # Taylor remainder of the quadratic over the window: |G'''| n^3 / 3!, G''' in lines by a
        # central difference of the truth (step h = 0.5 line)
        k, h = result.lines[near].astype(float), 0.5
        third = (resonant_g(k + 2 * h, n_samples) - 2 * resonant_g(k + h, n_samples)
                 + 2 * resonant_g(k - h, n_samples) - resonant_g(k - 2 * h, n_samples)) / (2 * h ** 3)
        remainder = np.abs(third) * result.half_width ** 3 / 6
        assert np.all(error[near][:, 0, 0] < remainder), np.max(error[near][:, 0, 0] / remainder)
        errors.append(math.sqrt(np.mean(error[near][:, 0, 0] ** 2)))

        # the transient: the record's spectrum beyond G U. The ratio Y/U would be off by the leakage
        # T/U; the LPM's G is off by less than a thousandth of it away from the resonance
        top = result.lines.size
        Y, U = (np.fft.rfft(x)[:, 1:top + 1] / n_samples for x in (y, u))
        T = Y.T - np.einsum("kia,ak->ki", G, U)
        leakage = np.abs(T[:, :, None] / U.T[:, None, :])
        assert np.median(error[far] / leakage[far]) < 1e-3
        assert rms(result.transient[0][far] - T[far]) < 1e-2 * rms(T[far])
    # the transient near the resonance, where a window spans a quarter of its half-power band
    assert rms(result.transient[0][near] - T[near]) < 0.1 * rms(T[near])
    assert errors[0] / errors[1] > 32, errors


def rms(x: np.ndarray) -> float:
    return math.sqrt(np.mean(np.abs(x) ** 2))


def test_bounds_cover_and_the_covariance_is_unbiased_under_correlated_noise():
    rng = np.random.default_rng(20261207)
    n_samples, trials, half_width = 2048, 24, 5
    mixing = np.array([[0.05, 0.0], [0.03, 0.04]])                 # v = mixing e: Sigma = mixing mixing^T
    sigma = mixing @ mixing.T
    hits, ratios, smoothed = [], [], []
    for _ in range(trials):
        u = rng.standard_normal((2, n_samples))
        y = respond(u, SMOOTH) + mixing @ rng.standard_normal((2, n_samples))
        result = lpm_mimo(u, y, 1.0, half_width=half_width)
        apart = np.arange(half_width, result.lines.size - half_width, 2 * half_width + 1)  # disjoint windows
        G = truth(SMOOTH, result.frequencies[apart])
        hits.append(np.abs(result.G[apart] - G) <= result.bounds(0.95).radius[apart])
        ratios.append(result.cov_v[apart] * n_samples / sigma)      # each entry: its mean is 1
        # the smoothed C_00 (cov_G_smoothed / cov_G = C_bar / C), on bands that share no line
        B = result.smoothing_lines
        far = np.arange(B // 2, result.lines.size - B // 2, B)
        smoothed.append((result.cov_G_smoothed[far, 0, 0] / result.cov_G[far, 0, 0]).real
                        * result.cov_v[far, 0, 0].real * n_samples / sigma[0, 0])
    hits, ratios, smoothed = np.concatenate(hits), np.concatenate(ratios), np.concatenate(smoothed)
    q = degrees_of_freedom(1, 2, half_width, 2)
    assert result.dof == q == 2
    # the four entries of a line share its residual: count lines, not entries, for the band
    assert abs(hits.mean() - 0.95) < binomial_band(0.95, hits.shape[0]), hits.mean(axis=0)
    # C_ii / Sigma_ii ~ chi2(2q)/(2q): variance 1/q; the cross term's real part scatters no more
    n_lines = ratios.shape[0]
    for i, j in ((0, 0), (1, 1), (0, 1)):
        assert abs(ratios[:, i, j].real.mean() - 1) < 4 / math.sqrt(q * n_lines) * (1.5 if i != j else 1), (i, j)
    # averaged over B = 101 lines: unbiased, with at least smoothed_dof = q B / 11 = 18.4 degrees of freedom
    assert result.smoothing_lines == 101 and result.smoothed_dof == pytest.approx(2 * 101 / 11)
    assert abs(smoothed.mean() - 1) < 4 / math.sqrt(result.smoothed_dof * smoothed.size), smoothed.mean()
    assert smoothed.var() < (1 / result.smoothed_dof) * (1 + 3 * math.sqrt(2 / smoothed.size)), smoothed.var()


def test_a_wiener_system_gives_the_bla_with_the_distortion_in_the_variance():
    """Output y2 through a cubic, y2 = x2 + alpha x2^3, x2 Gaussian (a sum of filtered white
    inputs): by Bussgang's theorem the BLA of row 2 is G_2a (1 + 3 alpha var(x2)), var(x2) the sum
    of the squared impulse responses. The stochastic distortion acts as noise under random
    excitation: the 95 % circles cover that BLA at 95 %, and C_22 holds it (here more than 100
    times the noise's sigma^2 / N), while C_11 of the linear output is the noise's alone."""
    rng = np.random.default_rng(3)
    alpha, sigma, n_samples, half_width = 0.1, 0.01, 4096, 5
    impulse = np.zeros(400)
    impulse[0] = 1.0
    var_x2 = sum(np.sum(signal.lfilter(*SMOOTH[(1, a)], impulse) ** 2) for a in range(2))
    hits, noise_only, with_distortion = [], [], []
    for _ in range(6):
        u = rng.standard_normal((2, n_samples))
        x = respond(u, SMOOTH)
        y = np.stack([x[0], x[1] + alpha * x[1] ** 3]) + sigma * rng.standard_normal((2, n_samples))
        result = lpm_mimo(u, y, 1.0, half_width=half_width)
        apart = np.arange(half_width, result.lines.size - half_width, 2 * half_width + 1)
        bla = truth(SMOOTH, result.frequencies[apart])
        bla[:, 1, :] *= 1 + 3 * alpha * var_x2
        hits.append(np.abs(result.G[apart] - bla) <= result.bounds(0.95).radius[apart])
        noise_only.append(result.cov_v[apart, 0, 0].real * n_samples / sigma ** 2)
        with_distortion.append(result.cov_v[apart, 1, 1].real * n_samples / sigma ** 2)
    hits, noise_only = np.concatenate(hits), np.concatenate(noise_only)
    assert abs(hits.mean() - 0.95) < binomial_band(0.95, hits.shape[0]), hits.mean(axis=0)
    assert abs(noise_only.mean() - 1) < 4 / math.sqrt(result.dof * noise_only.size), noise_only.mean()
    assert np.mean(with_distortion) > 100


def test_one_input_gives_the_single_input_lpm():
    """Three records of one input and two outputs: each output's G, its variance and the
    residual variance are the single-input LPM's, which computes the residual energy through its
    normal equations (hence 1e-9, not 1e-14, on the variances)."""
    rng = np.random.default_rng(5)
    u = rng.standard_normal((3, 1, 600))
    y = np.stack([signal.lfilter([1.0, 0.5], [1.0, -1.5, 0.8], u[:, 0]),
                  signal.lfilter([0.2], [1.0, -0.5], u[:, 0])], axis=1) + 0.1 * rng.standard_normal((3, 2, 600))
    both = lpm_mimo(u, y, 10.0)
    assert both.dof == degrees_of_freedom(3, 1, 3, 2) == 9
    for i in range(2):
        single = lpm(u[:, 0], y[:, i], 10.0)
        assert single.dof == both.dof
        np.testing.assert_allclose(both.G[:, i, 0], single.G, rtol=1e-12)
        np.testing.assert_allclose(both.var_G[:, i, 0], single.var_G, rtol=1e-9)
        np.testing.assert_allclose(both.cov_v[:, i, i].real, single.var_y, rtol=1e-9)
        bounds = single.bounds(0.9)
        np.testing.assert_allclose(both.bounds(0.9).radius[:, i, 0], bounds.radius, rtol=1e-9)
        assert both.smoothing_lines == single.smoothing_lines and both.smoothed_dof == single.smoothed_dof
        np.testing.assert_allclose(both.cov_G_smoothed[:, i, i].real, single.var_G_smoothed, rtol=1e-9)


@pytest.mark.parametrize("u, y, kwargs, where, fragment", [
    (np.ones((2, 300)) + np.eye(2, 300), np.zeros((2, 300)), {"half_width": 3}, "half_width",
     "leaves q = -2 degrees of freedom; at least half_width 5"),
    (np.full((2, 300), np.nan), np.zeros((2, 300)), {}, "u", "NaN or infinite"),
    (np.zeros((2, 300)), np.zeros((2, 299)), {}, "y", "records and samples of u"),
    (np.zeros((2, 20)), np.zeros((2, 20)), {}, "u", "20 samples give 9 lines, fewer than the window of 11"),
    (np.stack([np.arange(300.0) % 7, np.zeros(300)]), np.zeros((2, 300)), {}, "u", "input 1 is constant"),
    ("noise", np.zeros((2, 300)), {}, "u", "expected a numeric array"),
    (np.eye(2, 300), np.zeros((2, 300)), {"half_width": "5"}, "half_width", "expected an integer >= 1"),
    (np.eye(2, 300), np.zeros((2, 300)), {"degree": -1}, "degree", "expected an integer >= 0"),
    (np.eye(2, 300), np.zeros((2, 300)), {"fs": 0.0}, "fs", "expected a positive sample rate"),
])
def test_bad_input_is_refused_naming_the_argument(u, y, kwargs, where, fragment):
    with pytest.raises(InputError) as error:
        lpm_mimo(u, y, **{"fs": 1.0, "half_width": 5, **kwargs})
    assert error.value.where == where and fragment in error.value.what, str(error.value)


def test_collinear_inputs_are_refused():
    """u2 = -2 u1 (plus an offset, which the DFT lines do not see): no window separates them."""
    rng = np.random.default_rng(1)
    u1 = rng.standard_normal(400)
    u = np.stack([u1, 3.0 - 2 * u1])
    with pytest.raises(InputError) as error:
        lpm_mimo(u, respond(u, SMOOTH), 1.0, half_width=5)
    assert error.value.where == "u" and "collinear over the window at 199 line(s)" in error.value.what


def test_narrowest_half_width_leaves_a_degree_of_freedom():
    for records, inputs, degree in ((1, 1, 2), (1, 2, 2), (3, 2, 2), (1, 3, 1), (2, 4, 0)):
        n = narrowest_half_width(records, inputs, degree)
        assert degrees_of_freedom(records, inputs, n, degree) >= 1
        assert n == 1 or degrees_of_freedom(records, inputs, n - 1, degree) < 1
