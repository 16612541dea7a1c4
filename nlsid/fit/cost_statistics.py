"""The statistics of the weighted cost of a transfer-function fit: its expected value and acceptance bound.

The cost V(theta) = sum_{k=1}^{F} |G_k - G(Omega_k, theta)|^2 / sigma_k^2 (:mod:`nlsid.fit.tf_cost`)
has, at the minimum of a correct model, the expected value F - n_theta/2 (Schoukens, Pintelon and
Rolain 2012, 4.7 L; Ex 76, 99, 100); with variances estimated from M realizations the weights are
biased by E{1/sigma_hat^2} = (M-1)/(M-2) / sigma^2, so the expectation is (M-1)/(M-2) (F - n_theta/2).
With exact variances V is (1/2) chi^2 with 2F - n_theta degrees of freedom (standard deviation
sqrt(F - n_theta/2)); with variances from M realizations each term is F(2, 2M - 2) distributed
(:func:`expected_cost`), and the acceptance bound of the cost is a quantile of that distribution
(:func:`cost_bound`).
"""

from __future__ import annotations

import functools
import math

import numpy as np

def expected_cost(lines: int, n_theta: int, realizations: int | None) -> tuple[float, float]:
    """E{V} at the minimum of a correct model and its standard deviation (module docstring).

    Exact variances: V ~ (1/2) chi^2(2F - n_theta), mean and variance F - n_theta/2. Variances
    from M realizations: each term |e_k|^2 / sigma_hat_k^2 is F(2, 2M - 2) distributed (the mean
    over M realizations and their sample variance are independent), mean (M-1)/(M-2) and variance
    (M-1)^3 / ((M-2)^2 (M-3)); over the F - n_theta/2 degrees of freedom the mean and the variance
    add up. M <= 3 has no finite variance (and M = 2 no finite mean): returned as inf.
    """
    base = lines - n_theta / 2
    if realizations is None:
        return base, math.sqrt(max(base, 0.0))
    M = realizations
    if M <= 2:
        return math.inf, math.inf
    mean = (M - 1) / (M - 2)
    variance = (M - 1) ** 3 / ((M - 2) ** 2 * (M - 3)) if M > 3 else math.inf
    return mean * base, math.sqrt(max(base, 0.0) * variance)


ACCEPT_PROBABILITY = 0.99865  # one-sided, the probability of a normal variable below mean + 3 std
_TAIL_MASS = 1e-5             # probability mass of the cost distribution allowed beyond the grid (wraps around)


def cost_bound(lines: int, n_theta: int, realizations: int | None) -> float:
    """The cost a correct model stays below with probability ACCEPT_PROBABILITY (the cost check).

    Exact variances: the chi^2(2F - n_theta) quantile over 2. Variances from M >= 3 realizations:
    the quantile of a sum of F - n_theta/2 independent F(2, 2M - 2) terms (the distribution behind
    :func:`expected_cost`); its tail is heavy for small M (moments of order M - 1 and above are
    infinite), so no normal approximation: :func:`_sum_quantile` computes it. M = 2: the cost has
    no finite expected value and no cost check is possible (NaN: no order is accepted by cost).
    """
    from scipy.stats import chi2

    base = lines - n_theta / 2
    if base <= 0:
        return math.nan
    if realizations is None:
        return float(chi2.ppf(ACCEPT_PROBABILITY, 2 * base) / 2)
    if realizations <= 2:
        return math.nan
    return _sum_quantile(int(realizations), int(lines)) * base / lines


@functools.lru_cache(maxsize=64)
def _sum_quantile(realizations: int, terms: int) -> float:
    """ACCEPT_PROBABILITY quantile of a sum of ``terms`` independent F(2, d) variables, d = 2M - 2.

    The distribution of one term, P(X <= x) = 1 - (1 + 2x/d)^(-d/2), is put on a grid (midpoint
    rule, step about 0.05 of its unit mean) that reaches past the sum's mean by the single-term
    quantile at _TAIL_MASS / terms (a heavy-tailed sum exceeds its bulk by one large term); the
    ``terms``-fold convolution is a power of its discrete Fourier transform."""
    d = 2.0 * (realizations - 1)
    mean = d / (d - 2)
    tail = (d / 2) * ((terms / _TAIL_MASS) ** (2 / d) - 1)
    spread = math.sqrt(terms * d**2 * (d + 0) / ((d - 2) ** 2 * (d - 4))) if d > 4 else 0.0  # std of the sum
    top = terms * mean + tail + 10 * spread
    size = int(2 ** math.ceil(math.log2(min(max(top / 0.05, 2.0**16), 2.0**22))))
    h = top / size
    edges = (np.arange(size + 1) - 0.5) * h
    cdf = 1 - (1 + 2 * np.maximum(edges, 0.0) / d) ** (-d / 2)
    pmf = np.diff(cdf)
    total = np.fft.irfft(np.fft.rfft(pmf) ** terms, size)
    cumulative = np.cumsum(total)
    return float(np.searchsorted(cumulative, ACCEPT_PROBABILITY) * h)
