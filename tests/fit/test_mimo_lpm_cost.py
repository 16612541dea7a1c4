"""The cost check of a MIMO fit to an FRM by the Local Polynomial Method (frm_lpm_levels).

The records are made here with scipy.signal.lfilter (from rest, so each record carries the
transient the LPM removes, and an offset on every output): a discrete 2x2 system of order 2, two
real poles with rank-one residues c_k b_k^T, y = sum_k c_k b_k^T u / (z - p_k) + offset + white
noise of known std. nlsid's LPM gives the FRM and its covariance cov_G = [A^-1]_00 kron C (q
degrees of freedom), and the fit of the true order is compared with docs/mimo.md, "Cost of an LPM
FRM": E{V} = q/(q - n_y) (F m - kappa n_theta/2), the n_u columns' Hotelling terms sharing C,
lines up to 2n apart correlated (kappa, kappa_2 from the residuals)."""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.stats import chi2

from nlsid.analysis.lpm_mimo import lpm_mimo
from nlsid.fit.mimo_fit import fit_frm
from nlsid.stages.frm_fit import lpm_data

POLES = (0.85, 0.5)
C_RES = np.array([[1.0, 0.5], [-0.3, 1.0]])      # c_k, one per column
B_RES = np.array([[0.8, -0.4], [0.5, 0.9]])      # b_k, one per row
RECORDS, SAMPLES, SIGMA, HALF_WIDTH, DRAWS = 4, 256, 0.1, 3, 20


def entry(i: int, a: int) -> tuple[list[float], list[float]]:
    """Numerator and denominator in z^-1 of G_ia = sum_k c_ki b_ka / (z - p_k)."""
    (p1, p2), r1, r2 = POLES, C_RES[i, 0] * B_RES[0, a], C_RES[i, 1] * B_RES[1, a]
    return [0.0, r1 + r2, -(r1 * p2 + r2 * p1)], [1.0, -(p1 + p2), p1 * p2]


def records(rng) -> tuple[np.ndarray, np.ndarray]:
    u = rng.standard_normal((RECORDS, 2, SAMPLES))
    y = np.zeros_like(u) + np.array([0.3, -0.2])[None, :, None]
    for i in range(2):
        for a in range(2):
            y[:, i] += signal.lfilter(*entry(i, a), u[:, a], axis=-1)
    return u, y + SIGMA * rng.standard_normal(y.shape)


def level(result) -> dict:
    """The frm_lpm_levels group as read_bla gives it (what the fit stage reads)."""
    keep = result.frequencies > 0
    return {"name": "level_00", "attrs": {"dof": result.dof, "fs": 1.0, "half_width": HALF_WIDTH},
            "frequency": result.frequencies[keep], "G": result.G[keep], "cov_G": result.cov_G[keep],
            "var_G": result.var_G[keep]}


def test_mean_cost_of_an_lpm_frm_fit_is_its_expected_value():
    rng = np.random.default_rng(1)
    costs, expected, spread = [], [], []
    for _ in range(DRAWS):
        data, notes = lpm_data(level(lpm_mimo(*records(rng), 1.0, half_width=HALF_WIDTH)), "test")
        fit = fit_frm(data, 2, "z").fit
        q, F = data.dof, data.lines
        # q = M (2n+1) - (R+1)(n_u + M) = 4 * 7 - 3 * 6; n_theta = 2 (2 + 2) + 4
        assert q == 10 and fit.parameters == 12 and not notes
        assert np.isclose(fit.expected_cost, q / (q - 2) * (F * 4 - fit.line_correlation * 12 / 2))
        costs.append(fit.cost), expected.append(fit.expected_cost), spread.append(fit.cost_std)
    costs = np.array(costs)
    error = costs.std(ddof=1) / np.sqrt(DRAWS)
    # the mean of 20 draws within 3 standard errors of the expected value (normal by the central
    # limit theorem: fails with probability 0.003); the full-covariance Hotelling value of dimension
    # m = 4, q/(q - 4) (F m - n_theta/2), is some 20 standard errors above
    assert abs(costs.mean() - np.mean(expected)) < 3 * error, (costs.mean(), np.mean(expected), error)
    assert costs.mean() + 10 * error < q / (q - 4) * (F * 4 - 6)
    # the spread: the draws' variance over the stated one within the chi^2(19)/19 quantiles at
    # 0.0005 and 0.9995 (the terms are F distributed, not normal: a wide interval)
    ratio = costs.var(ddof=1) / np.mean(np.square(spread))
    assert chi2.ppf(0.0005, DRAWS - 1) / (DRAWS - 1) < ratio < chi2.ppf(0.9995, DRAWS - 1) / (DRAWS - 1), ratio
