"""Transfer-function fits at the stability boundary: how far a pole lies inside it, integrators, stable fits.

A pole's distance inside the boundary (``1 - |p|`` in z, ``-Re p`` in s) has a standard deviation
from the fit's covariance (delta method, :func:`on_boundary`). The order selection
(:mod:`nlsid.fit.order`) considers only fits that are not unstable (:func:`fit_stable`): the free
fit, or integrators where unstable real poles lie within the uncertainty of z = 1 (s = 0), or a
fit refined inside the stable region.
"""

from __future__ import annotations

import math

import numpy as np

from nlsid.fit.frf_data import FRFData
from nlsid.fit.tf_basis import Basis
from nlsid.fit.tf_cost import line_weights
from nlsid.fit.tf_fit import TFFit, fit_order, fit_result
from nlsid.fit.tf_refine import EXTRA_EVALUATIONS, refine
from nlsid.fit.tf_starts import linear_start, spread_starts


BOUNDARY_STD = 3.0  # a real unstable pole within this many standard deviations of z = 1 (s = 0) is an integrator


def _boundary_distance(fit: TFFit, pole: complex) -> tuple[float, float]:
    """How far a simple pole of a fit without integrators lies inside the stability boundary, and
    the standard deviation of that distance: ``1 - |p|`` (z) or ``-Re p`` (s), by the delta method
    on the denominator coefficients (dp/dc_i = -p^(n-i) / P'(p) for P(x) = sum c_i x^(n-i),
    c_0 = 1; names a1..a_na in z, a0..a_{na-1} of s^0..s^{na-1} in s)."""
    P = np.asarray(fit.model.den, dtype=float)  # z: ascending in z^-1 = descending in z; s: descending in s
    na = fit.na
    if fit.model.domain == "z":
        grad = np.array([-(pole ** (na - i)) for i in range(1, na + 1)], dtype=complex)
    else:
        grad = np.array([-(pole ** i) for i in range(na)], dtype=complex)
    g = grad / np.polyval(np.polyder(P), pole)
    if fit.model.domain == "z":
        distance, row = 1 - abs(pole), -np.real(np.conj(pole) * g) / max(abs(pole), 1e-300)
    else:
        distance, row = -pole.real, -np.real(g)
    cov = fit.covariance[:na, :na]
    variance = float(row @ cov @ row) if np.all(np.isfinite(cov)) else math.nan
    return float(distance), math.sqrt(max(variance, 0.0)) if math.isfinite(variance) else math.nan


def on_boundary(fit: TFFit) -> bool:
    """A pole of the fit (integrators aside) within BOUNDARY_STD standard deviations of the
    stability boundary: the data do not tell it from a pole on or beyond it."""
    if fit.integrators:
        return False
    for pole in fit.model.poles():
        distance, std = _boundary_distance(fit, complex(pole))
        if not math.isfinite(std) or distance <= BOUNDARY_STD * std:
            return True
    return False


def fit_stable(data: FRFData, nb: int, na: int, domain: str = "z", delay: int = 0, thorough: bool = True) -> TFFit:
    """The fit of ``nb``/``na`` that ``--order auto`` may choose: never unstable.

    1. the free fit (:func:`fit_order`) when it is stable (or marginally: poles on the boundary);
    2. else, when every unstable pole is real and within BOUNDARY_STD standard deviations of z = 1
       (s = 0), the data ask for integrators (a free mass): those poles are fixed there and the rest
       refitted (``how = "integrator"``);
    3. else Levenberg-Marquardt inside the stable region (a step out of it is refused) from the
       free fit's poles reflected into it (z -> 1/conj z, s -> -conj s), from the reflected linear
       start and from poles spread over the band; the lowest cost of the fits that do not end within
       BOUNDARY_STD std of the boundary is kept (``how = "stabilised"``); its cost tells whether a
       stable model of this order can describe the data.

    ``thorough=False``: the free fit from the linear start only (no further starts, no
    stabilisation), for orders the scan no longer needs.
    """
    free = fit_order(data, nb, na, domain, delay, extra_starts=thorough)
    poles = free.model.poles()
    worst = math.nan if not poles.size else float(np.max(np.abs(poles))) if domain == "z" else float(np.max(poles.real))
    free.free_pole = worst
    if free.model.stability() != "unstable" or not thorough:
        return free
    bad = poles[(np.abs(poles) >= 1) if domain == "z" else (poles.real >= 0)]
    real = np.abs(bad.imag) <= 1e-9 * np.maximum(np.abs(bad), 1.0)
    if domain == "z":
        real &= bad.real > 0  # an integrator is a pole at z = +1; one near z = -1 is not
    distances = [(-d, sd) for d, sd in (_boundary_distance(free, complex(p.real)) for p in bad[real])]
    if bad.size and np.all(real) and all(d <= BOUNDARY_STD * sd for d, sd in distances):
        fit = fit_order(data, nb, na, domain, delay, integrators=bad.size)
        where = "z = 1" if domain == "z" else "s = 0"
        spread = ", ".join(f"{d:.2g} +- {sd:.2g}" for d, sd in distances)
        fit.note = (f"the free fit has {bad.size} real pole(s) just outside the stability boundary (distance {spread}, "
                    f"within {BOUNDARY_STD:g} std of {where}): fixed at {where} (integrator)")
        fit.how, fit.free_pole = "integrator", worst
        if fit.model.stability() != "unstable":
            return fit
    weight = line_weights(data)
    basis = Basis(domain, data, nb, na, delay)
    what = f"|z| = {worst:.3g}" if domain == "z" else f"Re s = {worst:.3g}"
    note = (f"the free fit is unstable (pole at {what}): refitted inside the stable region from its reflected "
            "poles, the reflected linear start and poles spread over the band; the best stable cost kept")
    starts = [basis.reflected(free.values / basis.values_scale()), basis.reflected(linear_start(basis, weight)),
              *spread_starts(basis, weight)]
    fits = []
    for theta in starts:
        if basis.stable(theta):
            fit = fit_result(basis, refine(basis, theta, weight, stable_only=True, evaluations=EXTRA_EVALUATIONS),
                          data, nb, na, 0, weight, note, "stabilised")
            fit.free_pole = worst
            fits.append(fit)
    if not fits:
        return free  # no stable start (cannot happen for na >= 1: the spread starts are stable)
    inside = [f for f in fits if not on_boundary(f)]
    return min(inside or fits, key=lambda f: f.cost)
