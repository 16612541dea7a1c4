"""Starts of a transfer-function fit (Schoukens, Pintelon and Rolain 2012, 4.7 K).

A linear least-squares start (Levy) on w_k (A(Omega_k) G_k - B(Omega_k)), refined by
Sanathanan-Koerner iterations (each divides the equation by |A_prev(Omega_k)|, so the linear cost
approaches V): :func:`linear_start`. For ``s`` the linear start uses G_k e^{+j omega_k h / 2} (the
hold's half-sample delay removed), the band-limited approximation of the ZOH response. Further
starts, each a denominator with its least-squares numerator: the poles of the frequency-domain
subspace model (McKelvey, Akçay and Ljung 1996, :mod:`nlsid.fit.subspace`: non-iterative, so free
of the local minima the linear start can lead into when the order is high and the weights are
rough; :func:`subspace_start`), poles spread over the band (:func:`spread_starts`), or given poles
(:func:`theta_from_poles`).
"""

from __future__ import annotations

import math

import numpy as np

from nlsid.fit.tf_basis import Basis, zoh_response
from nlsid.fit.tf_cost import weighted_cost

SK_ITERATIONS = 20


def linear_start(basis: Basis, weight: np.ndarray) -> np.ndarray:
    """Levy, then Sanathanan-Koerner iterations; the candidate with the lowest cost V."""
    theta = basis.linear_fit(weight)
    best, best_cost = theta, weighted_cost(basis, theta, weight)
    for _ in range(SK_ITERATIONS):
        den = np.abs(basis.denominator(theta))
        if not np.all(np.isfinite(den)) or np.any(den == 0):
            break
        new = basis.linear_fit(weight / den)
        cost = weighted_cost(basis, new, weight)
        if cost < best_cost:
            best, best_cost = new, cost
        converged = np.linalg.norm(new - theta) <= 1e-10 * max(np.linalg.norm(new), 1e-300)
        theta = new
        if converged:
            break
    return best



def _numerator_for(basis: Basis, a: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """The numerator minimising V for a fixed free denominator factor ``a`` (V is linear in B then:
    column i is the response of Omega^i / (I A), through the ZOH for s); None if not finite."""
    z = basis.data.z
    full = basis.full_denominator(a)
    columns = []
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # None below, not warnings
        denominator = basis.powers[:, : full.size] @ full if basis.domain == "z" else None
        for i in range(basis.nb + 1):
            if basis.domain == "z":
                column = basis.powers[:, i] / denominator
            else:
                unit = np.zeros(basis.nb + 1)
                unit[i] = 1.0
                column = zoh_response(unit, full, basis.h * basis.scale, z)
            columns.append(column * z ** (-basis.delay))
        K = np.stack(columns, axis=1) * weight[:, None]
    rhs = basis.data.G * weight
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(rhs))):
        return None
    b, *_ = np.linalg.lstsq(np.vstack([K.real, K.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)
    return b


def theta_from_poles(basis: Basis, poles: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """A start whose free factor has the continuous-time poles ``poles`` (rad/s; in z through
    z = e^{s h}) and the best numerator for it."""
    if basis.domain == "z":
        a = np.real(np.poly(np.exp(poles / basis.data.fs))) if poles.size else np.ones(1)  # ascending in z^-1
    else:
        a = np.real(np.poly(poles / basis.scale))[::-1] if poles.size else np.ones(1)  # ascending in Omega, monic
    return _theta_from_denominator(basis, a, weight)


def _theta_from_denominator(basis: Basis, a: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """theta of the free factor with ascending coefficients ``a`` and the best numerator for it."""
    b = _numerator_for(basis, a, weight)
    if b is None:
        return None
    return np.concatenate([a[basis.free_a], b])


def subspace_start(basis: Basis, weight: np.ndarray) -> list[np.ndarray]:
    """A z fit's start whose free poles are those of the frequency-domain subspace model
    (:mod:`nlsid.fit.subspace`) of the data without delay and integrators, with the best numerator
    for them; none for s (its fit starts from the z fit mapped to s) or when the data cannot give
    it."""
    if basis.domain != "z" or basis.na == 0:
        return []
    from nlsid.fit.subspace import subspace_poles

    poles = subspace_poles(basis.linear_target(), basis.data.z, weight, basis.na)
    if poles is None:
        return []
    theta = _theta_from_denominator(basis, np.real(np.poly(poles)), weight)  # descending in z = ascending in z^-1
    return [] if theta is None else [theta]


START_DAMPING = (0.1, 0.5)  # damping ratios of the spread-pole starts


def spread_starts(basis: Basis, weight: np.ndarray) -> list[np.ndarray]:
    """Starts with the free poles spread over the band on a log scale, as pairs of damping ratio
    zeta (one start per START_DAMPING; a real pole at the lowest line for an odd count)."""
    free = basis.na
    if free == 0:
        return []
    data = basis.data
    w_lo, w_hi = 2 * np.pi * float(np.min(data.frequency)), 2 * np.pi * float(np.max(data.frequency))
    starts = []
    for zeta in START_DAMPING:
        wn = np.geomspace(w_lo, w_hi, (free + 1) // 2 + 2)[1:-1]
        poles = []
        for w in wn:
            poles += [complex(-zeta * w, w * math.sqrt(1 - zeta**2)), complex(-zeta * w, -w * math.sqrt(1 - zeta**2))]
        poles = np.array(poles[:free]) if free % 2 == 0 else np.array(poles[: free - 1] + [complex(-w_lo, 0.0)])
        theta = theta_from_poles(basis, poles, weight)
        if theta is not None:
            starts.append(theta)
    return starts
