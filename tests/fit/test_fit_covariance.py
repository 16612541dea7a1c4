"""The fit's standard errors account for correlated residuals (the sandwich of
nlsid.fit.uncertainty), checked by Monte Carlo on a case where the white-noise formula is far off.

A first-order discrete system y = b0 u + a y[k-1] (lfilter, here) with its gain b0 free, driven by
low-pass noise, and output noise coloured by an AR(1) filter with pole 0.95: the residual's
spectrum is strongest where the input's is, so the white-noise standard error sigma (J^T J)^-1/2
is several times too small. Over R = 150 independent records the spread of the estimates is the
truth; the mean sandwich standard error must match it within 4 standard errors of a standard
deviation estimated from R samples (sqrt(1 / (2 (R - 1))) = 5.8 % relative), while the white-noise
value must not.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from nlsid.fit.extension import fit_free_parameters
from nlsid.fit.free_parameters import FreeParameter
from nlsid.io.run import Run

B0, A1, N, R = 0.5, 0.8, 1500, 150
MODEL = {"model": {"type": "transfer_function", "domain": "discrete", "num": [B0], "den": [1.0, -A1]}}


def record(rng) -> Run:
    u = lfilter(*butter(2, 0.05), rng.standard_normal(N)) * 10
    y = lfilter([B0], [1.0, -A1], u) + lfilter([0.05], [1.0, -0.95], rng.standard_normal(N))
    return Run("r", 1.0, "arbitrary", u, y=y)


@pytest.fixture(scope="module")
def fits():
    rng = np.random.default_rng(42)
    out = []
    for _ in range(R):
        run = record(rng)
        fit = fit_free_parameters(MODEL, {"model.num[0]": FreeParameter(0.4, 0.0, 2.0)}, [run], [])
        out.append((fit.value("model.num[0]"), float(fit.std[0]), fit.estimation_rms, run))
    return out


def test_sandwich_standard_error_matches_the_spread(fits):
    estimates = np.array([f[0] for f in fits])
    spread = float(np.std(estimates, ddof=1))
    stated = float(np.mean([f[1] for f in fits]))
    assert abs(np.mean(estimates) - B0) < 4 * spread / math.sqrt(R)  # unbiased
    assert stated == pytest.approx(spread, rel=4 * math.sqrt(1 / (2 * (R - 1))))


def test_the_white_noise_formula_would_be_far_off(fits):
    """The check above can fail: sigma (J^T J)^-1/2, J = dy/db0 = u / (1 - a z^-1), is too small."""
    spread = float(np.std([f[0] for f in fits], ddof=1))
    white = []
    for _, _, rms, run in fits:
        J = lfilter([1.0], [1.0, -A1], run.u)
        white.append(rms / math.sqrt(float(J @ J)))
    assert float(np.mean(white)) < 0.5 * spread


def test_correlations_stay_within_one_when_the_jacobian_is_nearly_singular():
    """Two nearly interchangeable parameters (columns equal to 1e-9) and a coloured residual: the
    sandwich in factored form is positive semi-definite, so |correlation| <= 1 (Cauchy-Schwarz);
    before, roundoff in A^-1 B A^-1 gave correlations of 3 on such fits."""
    from scipy.signal import lfilter

    from nlsid.fit.uncertainty import sandwich_covariance

    rng = np.random.default_rng(5)
    base = rng.standard_normal((4000, 3))
    jac = np.column_stack([base, base[:, 0] * (1 + 1e-9) + 1e-9 * rng.standard_normal(4000)])
    residual = lfilter([1.0], [1.0, -0.95], rng.standard_normal(4000))
    names = ["a", "b", "c", "d"]
    _, corr, warnings = sandwich_covariance(jac, residual, np.ones(4), names, np.ones(4), np.full(4, -np.inf),
                                     np.full(4, np.inf), [4000])
    assert np.all(np.abs(corr) <= 1 + 1e-12), corr
    assert any("cannot tell these apart" in w for w in warnings)
