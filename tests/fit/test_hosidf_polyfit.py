"""Polynomial coefficients from measured HOSIDFs by weighted least squares, with covariance."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from nlsid.analysis.hosidf import measured_hosidf
from nlsid.analysis.hosidf_analytic import Branch, discrete_response
from nlsid.errors import InputError
from nlsid.fit.polynomial_from_hosidf import fit_coefficients, observations_from_grid

_spec = importlib.util.spec_from_file_location("hosidf_cases", Path(__file__).resolve().parents[1] / "analysis" / "test_hosidf.py")
cases = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cases)

TRUE = np.array([cases.A1, 0.0, cases.A3, cases.B1, cases.B2])
STRUCTURE = [Branch((0.0, 0.0, 0.0), post=discrete_response(*cases.G1P, cases.FS)),
             Branch((0.0, 0.0), pre=discrete_response(*cases.G2M, cases.FS))]


def noisy_grid(rng, noise=0.02):
    runs = [cases.sine_run(f"r{l}_{a}_{r}", l, a, cases.two_branch, periods=8, noise=noise, rng=rng)
            for l in (1, 4, 9) for a in (0.4, 1.0, 1.6) for r in range(3)]
    return measured_hosidf(runs, harmonics=4)


def test_noise_free_recovers_coefficients_exactly():
    """Noise-free data: the LS solution equals the true coefficients (to rounding, weights arbitrary)."""
    grid = measured_hosidf([cases.sine_run(f"r{l}_{a}", l, a, cases.two_branch) for l in (1, 4, 9)
                            for a in (0.4, 1.0, 1.6) for _ in range(2)], harmonics=4)
    observations = observations_from_grid(grid)
    observations = [type(o)(o.omega0, o.gamma, o.h, np.ones_like(o.variance)) for o in observations]
    fit = fit_coefficients(STRUCTURE, observations)
    np.testing.assert_allclose(fit.coefficients, TRUE, atol=1e-9)
    assert fit.branches[1].alpha == pytest.approx((cases.B1, cases.B2), abs=1e-9)


def test_noisy_recovery_within_reported_uncertainty():
    """One noisy data set: every coefficient within 4 reported standard deviations of the truth.

    With 5 Gaussian estimates the chance that any |z| > 4 is 5 * 6.3e-5 = 3e-4. The weighted
    residual is chi-square with dof = 9 cells * 9 real equations - 5 = 76 (sd of chi2/dof:
    sqrt(2/76) = 0.16); weights from variances with 21 degrees of freedom raise its mean to about
    21/19 = 1.1 and add scatter of the same order, so [0.4, 1.8] is about 3 sd either side.
    """
    fit = fit_coefficients(STRUCTURE, observations_from_grid(noisy_grid(np.random.default_rng(3))))
    z = (fit.coefficients - TRUE) / fit.std
    assert np.all(np.abs(z) < 4), z
    assert fit.dof == 76
    assert 0.4 < fit.chi2 / fit.dof < 1.8
    assert np.all(fit.std > 0) and np.all(fit.std < 0.05)  # the noise is small: a real test of accuracy


def test_reported_covariance_is_calibrated():
    """Over 25 independent data sets the normalised errors z have mean square 1.

    The mean of 125 values of z^2 (chi-square 1 each, sd sqrt(2)) has sd sqrt(2/125) = 0.13. The
    variances come from 3 x 7 = 21 degrees of freedom per value, which inflates E z^2 by about
    21/19 = 1.1. The tolerance [0.6, 1.6] is about 4 sd around 1.1.
    """
    rng = np.random.default_rng(11)
    z2 = []
    for _ in range(25):
        fit = fit_coefficients(STRUCTURE, observations_from_grid(noisy_grid(rng)))
        z2.append(((fit.coefficients - TRUE) / fit.std) ** 2)
    assert 0.6 < np.mean(z2) < 1.6


def test_unidentifiable_structure_is_reported():
    """A single amplitude at a single frequency cannot separate a1 from a3 (both only scale H1)."""
    grid = measured_hosidf([cases.sine_run(f"s{r}", 4, 1.0, cases.two_branch, noise=0.01,
                                           rng=np.random.default_rng(r)) for r in range(2)], harmonics=1 + 1)
    structure = [Branch((0.0, 0.0, 0.0), post=discrete_response(*cases.G1P, cases.FS))]
    with pytest.raises(InputError, match="not identifiable"):
        fit_coefficients(structure, observations_from_grid(grid))
