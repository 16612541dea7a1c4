"""The FRM of orthogonal multisines from the references, for a 2x2 plant in a closed loop.

The data are ``generators.mimo_periodic_loop``: the plant of ``generators.mimo_loop`` (truth
C (zI - A)^-1 B) under its diagonal controller, driven by orthogonal multisine references, run
sample by sample into the periodic steady state, coloured output noise fed back, offsets added.

With E = n_u experiments the estimate from the references equals Y U^-1 identically
(``W = R^-1 (U R^-1)^-1 = U^-1``). With E = 2 n_u the least-squares ``Y U^+`` correlates the output
noise with the input noise the loop feeds back: a bias of order sigma^2 / (P |U|^2) that the
realizations do not average out, which ``Y R^+ (U R^+)^-1`` does not have.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from generators.mimo_loop import truth
from generators.mimo_periodic_loop import BINS, N, closed_loop, periods, references
from nlsid.analysis.frm import frm, frm_reference
from nlsid.errors import InputError


def test_noise_free_equals_the_truth():
    """Both designs, E = n_u and E = 2 n_u: the truth to 1e-10 (the transient is below 1e-30)."""
    rng = np.random.default_rng(1)
    G0 = truth(BINS / N)
    for designs in (1, 2):
        r = references(rng, (2,), designs)
        u, y = closed_loop(r, 0.0, rng)
        result = frm_reference(periods(r), u, y, BINS, fs=N)
        assert result.method == "frm_reference" and result.n_experiments == 2 * designs
        assert np.max(np.abs(result.G - G0) / np.abs(G0)) < 1e-10
        assert np.allclose(result.frequency, BINS)


def test_square_design_is_the_direct_estimate():
    """E = n_u: ``R^-1 (U R^-1)^-1 = U^-1``, so G and both covariances are frm's to rounding."""
    rng = np.random.default_rng(2)
    r = references(rng, (6,), 1)
    u, y = closed_loop(r, 1.0, rng)
    direct, indirect = frm(u, y, BINS), frm_reference(periods(r), u, y, BINS)
    assert np.max(np.abs(indirect.G - direct.G) / np.abs(direct.G)) < 1e-12
    for name in ("cov_noise", "cov_total"):
        a, b = getattr(indirect, name), getattr(direct, name)
        assert np.max(np.abs(a - b)) < 1e-12 * np.max(np.abs(b))
    assert direct.method == "frm"


@pytest.fixture(scope="module")
def monte_carlo():
    """T = 40 trials of M = 8 realizations of E = 4 experiments (two orthogonal pairs), noise std 1
    against references of rms 1 (|R| = 1 / sqrt(62) per line, the noise 0.8 / sqrt(64 (1 - 0.25)) per
    line and period: about 11 dB per line and period)."""
    rng = np.random.default_rng(3)
    trials, realizations = 40, 8
    r = references(rng, (trials, realizations), 2)
    u, y = closed_loop(r, 1.0, rng)
    direct = [frm(u[t], y[t], BINS) for t in range(trials)]
    indirect = [frm_reference(periods(r[t]), u[t], y[t], BINS) for t in range(trials)]
    return direct, indirect, truth(BINS / N)


def bias_statistic(results, G0) -> tuple[float, int]:
    """sum over lines and entries of |mean error|^2 / var(mean error) over the trials, and its
    chi-square degrees of freedom (2 per complex entry) when the estimate is unbiased."""
    errors = np.array([result.G - G0 for result in results])              # (T, F, 2, 2)
    variance = np.mean([result.std_total ** 2 for result in results], axis=0) / len(results)
    return float(np.sum(2 * np.abs(errors.mean(axis=0)) ** 2 / variance)), 2 * errors[0].size


def test_direct_least_squares_is_biased_and_the_reference_estimate_is_not(monte_carlo):
    """Unbiased, the statistic is chi-square with 248 degrees of freedom (the std_total estimates over
    40 x 7 degrees of freedom make it slightly wider, 5 % allowed): its 1e-4 upper quantile is about
    340. The direct least squares exceeds it many times over (about 6100 over three seeds, the
    references' 260-280); the estimate from the references stays below."""
    direct, indirect, G0 = monte_carlo
    biased, dof = bias_statistic(direct, G0)
    unbiased, _ = bias_statistic(indirect, G0)
    limit = stats.chi2.ppf(1 - 1e-4, dof) * 1.05
    assert unbiased < limit
    assert biased > 5 * limit
    # its 95 % circles miss the truth far more often than 5 % (binomial std over the 1240 lines 0.0062)
    inside = np.mean([np.abs(result.G - G0) <= result.bounds.radius for result in direct])
    assert inside < 0.95 - 8 * np.sqrt(0.95 * 0.05 / 1240)


def test_reference_bounds_cover_the_truth_at_their_probability(monte_carlo):
    """The 95 % circles on the total variance (F(2, 2M - 2)) hold the truth in 95 % of 40 x 31 lines x
    4 entries; the four entries of a line share the noise, so the binomial std is taken over the
    1240 lines alone (0.0062), and 4 of it bound the share."""
    _, indirect, G0 = monte_carlo
    inside = np.array([np.abs(result.G - G0) <= result.bounds.radius for result in indirect])
    share = inside.mean()
    assert abs(share - 0.95) < 4 * np.sqrt(0.95 * 0.05 / (inside.shape[0] * inside.shape[1]))


def test_bad_references_are_refused_naming_r():
    rng = np.random.default_rng(4)
    r = references(rng, (1,), 1)
    u, y = closed_loop(r, 0.0, rng)
    with pytest.raises(InputError) as error:
        frm_reference(periods(r)[:, :, :1], u, y, BINS)
    assert error.value.where == "r" and "one reference per input" in error.value.what
    dependent = periods(np.stack([r[:, 0], r[:, 0]], axis=1))               # both experiments alike
    with pytest.raises(InputError) as error:
        frm_reference(dependent, u, y, BINS)
    assert error.value.where == "r" and "linearly dependent" in error.value.what
    with pytest.raises(InputError) as error:
        frm_reference(np.full(u.shape, np.nan), u, y, BINS)
    assert error.value.where == "r"
