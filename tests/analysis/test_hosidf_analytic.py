"""Analytic spectra and HOSIDFs (seed 002) against the paper's examples and against DFTs of time signals."""

from math import comb

import numpy as np
import pytest
from scipy.signal import lfilter

from nlsid.analysis.hosidf_analytic import (
    Branch,
    continuous_response,
    discrete_response,
    fhosidf,
    hosidf_from_fhosidf,
    lpl_hosidf,
    lpl_spectrum,
    omega_matrix,
    polynomial_spectrum,
)

N = 256  # samples per period
FS = 1000.0


def dft_harmonics(x_period: np.ndarray, bin0: int, harmonics: int) -> np.ndarray:
    """Single sided spectrum (phasors) of one period at bins k*bin0: independent of the library."""
    spectrum = np.fft.fft(x_period) / x_period.size
    out = 2 * spectrum[bin0 * np.arange(harmonics + 1)]
    out[0] /= 2
    return out


def tone(gamma: float, phi0: float, bin0: int, periods: int = 1) -> np.ndarray:
    n = np.arange(periods * N)
    return gamma * np.cos(2 * np.pi * bin0 * n / N + phi0)


# Exact arithmetic: every entry is an integer and the DFT of cos^p on 64+ samples is exact to
# ~1e-15 relative, so 1e-12 leaves a margin of 1000x for rounding.
@pytest.mark.parametrize("p", range(1, 9))
def test_omega_column_equals_dft_of_cos_power(p):
    x = np.cos(2 * np.pi * 3 * np.arange(N) / N) ** p
    measured = dft_harmonics(x, 3, p) * 2**p  # Omega[k, p] = Y_k / (gamma/2)^p with gamma = 1
    np.testing.assert_allclose(omega_matrix(p)[:, p - 1], measured.real, atol=1e-12 * 2**p)


@pytest.mark.parametrize("p", [4, 6, 8])
def test_printed_dc_row_of_omega_disagrees_with_dft(p):
    """The printed DC row C(p, p/2) p/2 is p/2 times the DFT value for every even p >= 4."""
    x = np.cos(2 * np.pi * 3 * np.arange(N) / N) ** p
    dc = dft_harmonics(x, 3, 0)[0].real * 2**p
    printed = comb(p, p // 2) * p / 2
    assert printed == pytest.approx(dc * p / 2, rel=1e-12)
    assert abs(printed - dc) > 1.0


def test_example_1_matrices_and_spectrum():
    """Seed 002 Example 1: P = 3, the printed Omega and the spectrum Y = Phi Omega Gamma alpha."""
    printed_omega = np.array([[0, 2, 0], [2, 0, 6], [0, 2, 0], [0, 0, 2]], dtype=float)
    np.testing.assert_array_equal(omega_matrix(3), printed_omega)
    alpha, gamma, phi0 = np.array([0.7, -1.3, 2.1]), 1.7, 0.4
    expected = (
        np.diag(np.exp(1j * phi0 * np.arange(4))) @ printed_omega @ np.diag((gamma / 2) ** np.arange(1, 4)) @ alpha
    )
    np.testing.assert_allclose(polynomial_spectrum(alpha, gamma, phi0), expected, rtol=1e-14)
    # and the DFT of the sampled polynomial output (exact trigonometric identity, rounding only)
    u = tone(gamma, phi0, 5)
    y = alpha[0] * u + alpha[1] * u**2 + alpha[2] * u**3
    np.testing.assert_allclose(polynomial_spectrum(alpha, gamma, phi0), dft_harmonics(y, 5, 3), atol=1e-12)


def test_static_polynomial_degree_7_against_dft():
    """Up to degree 7: the corrected DC row is needed here (alpha_4 and alpha_6 contribute to Y(0))."""
    alpha = np.array([1.0, 0.5, -0.3, 0.2, 0.1, -0.05, 0.02])
    gamma, phi0 = 1.3, -0.8
    u = tone(gamma, phi0, 7)
    y = sum(a * u ** (p + 1) for p, a in enumerate(alpha))
    np.testing.assert_allclose(polynomial_spectrum(alpha, gamma, phi0), dft_harmonics(y, 7, 7), atol=1e-12)


def example_2_system():
    """The two-branch LPL system of seed 002 Fig. 2 with discrete-time G1+ and G2-."""
    a1, a3, b1, b2 = 0.8, -0.4, 1.5, 0.6
    g1p = ([0.2, 0.1], [1.0, -0.7])         # G1+: after a1 q + a3 q^3 (G1- = 1)
    g2m = ([0.05, 0.05], [1.0, -0.9])       # G2-: before b1 q + b2 q^2 (G2+ = 1)
    branches = [
        Branch((a1, 0.0, a3), post=discrete_response(*g1p, FS)),
        Branch((b1, b2), pre=discrete_response(*g2m, FS)),
    ]
    return (a1, a3, b1, b2), g1p, g2m, branches


def test_example_2_closed_forms():
    """Seed 002 Example 2: the printed spectrum Y and HOSIDFs H, entry by entry."""
    (a1, a3, b1, b2), g1p, g2m, branches = example_2_system()
    gamma, phi0, bin0 = 0.9, 0.7, 4
    w0 = 2 * np.pi * bin0 * FS / N
    G1p = discrete_response(*g1p, FS)
    G2m = discrete_response(*g2m, FS)(w0)
    e = np.exp(1j * phi0)
    printed_y = np.array([
        b2 * gamma**2 / 2 * abs(G2m) ** 2,
        gamma * ((a1 + 0.75 * a3 * gamma**2) * G1p(w0) + b1 * G2m) * e,
        b2 * gamma**2 / 2 * G2m**2 * e**2,
        a3 * gamma**3 / 4 * G1p(3 * w0) * e**3,
    ])
    printed_h = np.array([
        b2 * gamma**2 / 2 * abs(G2m) ** 2,
        (a1 + 0.75 * a3 * gamma**2) * G1p(w0) + b1 * G2m,
        b2 / 2 * G2m**2,
        a3 / 4 * G1p(3 * w0),
    ])
    np.testing.assert_allclose(lpl_spectrum(branches, w0, gamma, phi0), printed_y, rtol=1e-13)
    np.testing.assert_allclose(lpl_hosidf(branches, w0, gamma), printed_h, rtol=1e-13)


def test_lpl_spectrum_against_lfilter_simulation():
    """Lemma 1 against a time-domain simulation: lfilter, numpy polynomial, lfilter, last period.

    Poles at 0.7 and 0.9 decay as 0.9^(19*256) ~ 1e-200 before the analysed period, so the only
    error is rounding (~1e-15 relative); 1e-9 is the acceptance level of the issue.
    """
    (a1, a3, b1, b2), g1p, g2m, branches = example_2_system()
    gamma, phi0, bin0, periods = 1.1, -0.3, 6, 20
    u = tone(gamma, phi0, bin0, periods)
    y = lfilter(*g1p, np.polynomial.polynomial.polyval(u, [0, a1, 0, a3]))
    y = y + np.polynomial.polynomial.polyval(lfilter(*g2m, u), [0, b1, b2])
    measured = dft_harmonics(y[-N:], bin0, 3)
    w0 = 2 * np.pi * bin0 * FS / N
    analytic = lpl_spectrum(branches, w0, gamma, phi0)
    np.testing.assert_allclose(analytic, measured, rtol=1e-9, atol=1e-9 * abs(measured).max())


def test_lpl_with_dynamics_on_both_sides_and_dc_gain():
    """A branch with G- and G+ both dynamic and a quartic term: exercises the DC row and G+(0)."""
    g_minus = ([0.3], [1.0, -0.7])
    g_plus = ([0.5, 0.2], [1.0, -0.3])
    alpha = (0.4, 0.9, 0.0, -0.6)
    branch = Branch(alpha, pre=discrete_response(*g_minus, FS), post=discrete_response(*g_plus, FS))
    gamma, phi0, bin0 = 0.8, 1.1, 3
    u = tone(gamma, phi0, bin0, 20)
    y = lfilter(*g_plus, np.polynomial.polynomial.polyval(lfilter(*g_minus, u), (0,) + alpha))
    measured = dft_harmonics(y[-N:], bin0, 4)
    analytic = lpl_spectrum([branch], 2 * np.pi * bin0 * FS / N, gamma, phi0)
    np.testing.assert_allclose(analytic, measured, rtol=1e-9, atol=1e-12)


def test_fhosidf_of_parallel_hammerstein():
    """Definition 3: F_p = sum_n G_n^+ alpha_p^[n], and the HOSIDFs rebuilt from them (Lemma 2)."""
    g1 = continuous_response([1.0], [1e-3, 1.0])
    g2 = continuous_response([2.0, 0.0], [1.0, 50.0])
    branches = [Branch((1.0, 0.0, 0.5), post=g1), Branch((0.2, -0.3), post=g2)]
    w0, gamma = 2 * np.pi * 7.0, 0.6
    np.testing.assert_allclose(fhosidf(branches, w0), [g1(w0) + 0.2 * g2(w0), -0.3 * g2(w0), 0.5 * g1(w0)], rtol=1e-14)
    np.testing.assert_allclose(
        hosidf_from_fhosidf(lambda w: fhosidf(branches, w), w0, gamma), lpl_hosidf(branches, w0, gamma), rtol=1e-12
    )
    with pytest.raises(ValueError):
        fhosidf([Branch((1.0,), pre=g1)], w0)


def test_hosidf_does_not_depend_on_input_phase():
    """Remark after Lemma 2: Y(k w0)/U(w0)^k is the same for every phi0 (checked by DFT)."""
    _, g1p, g2m, branches = example_2_system()
    gamma, bin0 = 0.7, 2
    for phi0 in (0.0, 1.0, -2.5):
        u = tone(gamma, phi0, bin0, 20)
        (a1, a3, b1, b2) = (0.8, -0.4, 1.5, 0.6)
        y = lfilter(*g1p, a1 * u + a3 * u**3) + b1 * lfilter(*g2m, u) + b2 * lfilter(*g2m, u) ** 2
        y_h = dft_harmonics(y[-N:], bin0, 3)
        u_1 = dft_harmonics(u[-N:], bin0, 1)[1]
        np.testing.assert_allclose(y_h / u_1 ** np.arange(4), lpl_hosidf(branches, 2 * np.pi * bin0 * FS / N, gamma),
                                   rtol=1e-9)
