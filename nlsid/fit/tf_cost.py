"""The weighted cost of a transfer-function fit (Schoukens, Pintelon and Rolain 2012, Sections 4.4, 4.7, ch. 7).

Treating the input as exact, the sample maximum likelihood cost (4-32)/(4-33) becomes, in FRF form
(Chapter 7: "the variance on the averaged data should be used as frequency weighting"),

    V(theta) = sum_{k=1}^{F} |G_k - G(Omega_k, theta)|^2 / sigma_k^2,

with the residual e_k = (G_k - G(Omega_k, theta)) / sigma_k stacked as real and imaginary parts
for the optimiser (:func:`residual`). Its expected value and bound: :mod:`nlsid.fit.cost_statistics`.
"""

from __future__ import annotations

import math

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.frf_data import FRFData
from nlsid.fit.tf_basis import Basis


def line_weights(data: FRFData) -> np.ndarray:
    """1/sigma_k per line: the weights of the residual (an InputError where a variance is not finite and > 0)."""
    if not np.all(np.isfinite(data.variance)) or np.any(data.variance <= 0):
        raise InputError("BLA", "the variances weighting the fit must be finite and > 0 at every line")
    return 1.0 / np.sqrt(data.variance)


def weighted_cost(basis: Basis, theta: np.ndarray, weight: np.ndarray) -> float:
    """V(theta) (inf where it is not finite)."""
    e = (basis.data.G - basis.model(theta)) * weight
    value = float(np.sum(e.real ** 2 + e.imag ** 2))
    return value if math.isfinite(value) else math.inf


def residual(basis: Basis, theta: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The weighted residual [Re e, Im e], e_k = (G_k - G(Omega_k, theta)) w_k, whose squares sum to V."""
    e = (basis.data.G - basis.model(theta)) * weight
    return np.concatenate([e.real, e.imag])
