"""Circular confidence regions of a complex FRF estimate (book Section 6.1.5, Exercise 92).

With ``G_hat - G`` circular complex normal of variance ``sigma^2`` and ``sigma_hat^2`` a sample
variance built from R independent observations, ``|G_hat - G|^2 / sigma_hat^2 ~ F(2, 2R-2)``
((6-88), (6-89)), so the most compact 100p% region is a circle of radius
``sigma_hat sqrt(F_{p; 2, 2R-2})`` around ``G_hat`` ((6-87) for known variance: the limit R -> inf,
radius ``sigma sqrt(-ln(1-p))``). R follows Table 6-1: R = M for the total variance of the robust
method, R = M P for its noise variance, R = P for the noise variance of the fast method and
R = 2 for its interpolated total variance (the conservative end of the book's R in (2, 3]).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def f_quantile_2(p: float, dof: float) -> float:
    """Quantile p of the F(2, dof) distribution, closed form ``(dof/2)((1-p)^(-2/dof) - 1)``.

    ``dof = inf`` gives the chi-square limit ``-ln(1 - p)`` ((6-87)). Example: p = 0.95, dof = 10
    (the detection test (6-50) with P = 6) gives 4.10.
    """
    if not 0 < p < 1:
        raise ValueError(f"probability must lie in (0, 1), got {p}")
    if np.isinf(dof):
        return float(-np.log1p(-p))
    if dof <= 0:
        return float("nan")
    return float(dof / 2 * ((1 - p) ** (-2 / dof) - 1))


@dataclass
class Bounds:
    """Confidence bounds per line: the circle radius, |G| interval and phase interval (rad).

    The phase interval is ``angle(G) -+ arcsin(radius/|G|)``; where the circle contains the origin
    the phase is not bounded and the interval is ``angle(G) -+ pi``. NaN variance gives NaN bounds.
    """

    radius: np.ndarray
    mag_lo: np.ndarray
    mag_hi: np.ndarray
    phase_lo: np.ndarray
    phase_hi: np.ndarray


def circle_bounds(G: np.ndarray, variance: np.ndarray, probability: float, observations: float) -> Bounds:
    """Bounds of the 100p% circle of radius ``sqrt(variance F_{p;2,2R-2})`` around ``G`` (Ex. 92)."""
    radius = np.sqrt(variance * f_quantile_2(probability, 2 * observations - 2))
    mag = np.abs(G)
    phase = np.angle(G)
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.where(radius < mag, np.arcsin(np.minimum(radius / mag, 1.0)), np.pi)
    half = np.where(np.isnan(radius), np.nan, half)
    return Bounds(radius, np.maximum(mag - radius, 0.0), mag + radius, phase - half, phase + half)
