"""A measured frequency response function (FRF) as the transfer-function fit sees it.

The BLA G_k at the excited bins k of one period of N samples (frequency k fs/N), with the variance
sigma_k^2 of each averaged value (noise plus stochastic nonlinear distortions, ``var_total``,
Schoukens, Pintelon and Rolain 2012, (6-3)): the fit weights line k by 1/sigma_k
(:func:`nlsid.fit.tf_cost.line_weights`). With variances estimated from M realizations the cost's
distribution depends on M (:mod:`nlsid.fit.cost_statistics`), so M travels with the data.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FRFData:
    """A measured FRF: excited bins of one period, values, variances of the values, rate, period."""

    bins: np.ndarray
    G: np.ndarray
    variance: np.ndarray
    fs: float
    period: int
    realizations: int | None = None   # M behind sample variances (None: variances taken as exact)
    shared_lags: int = 0              # lines this many apart or closer share samples (LPM windows); 0: independent

    @property
    def frequency(self) -> np.ndarray:
        return self.bins * self.fs / self.period

    @functools.cached_property
    def z(self) -> np.ndarray:
        """exp(j 2 pi k / N) at the bins (computed once: every model evaluation of a fit needs it)."""
        return np.exp(2j * np.pi * self.bins / self.period)

    def subset(self, index: np.ndarray) -> "FRFData":
        return FRFData(self.bins[index], self.G[index], self.variance[index], self.fs, self.period, self.realizations,
                       self.shared_lags)
