"""Rational transfer functions fitted to a BLA in the frequency domain (book Sections 4.4, 4.7, ch. 7).

The model and its parameters: :mod:`nlsid.fit.tf_basis`; the data: :mod:`nlsid.fit.frf_data`; the
weighted cost V(theta): :mod:`nlsid.fit.tf_cost`, its expected value and acceptance bound:
:mod:`nlsid.fit.cost_statistics`. The dead time d is a whole number of samples (given, or the best
of 0..max_delay by cost).

Procedure (book 4.7 K; digest 3.3): the linear start (Levy, Sanathanan-Koerner:
:func:`nlsid.fit.tf_starts.linear_start`) leads into a Levenberg-Marquardt minimisation of V
itself (:func:`nlsid.fit.tf_refine.refine`). When the result is unstable or its cost lies above
its bound, further starts follow and the lowest cost is kept: for ``s`` the z fit mapped to s
(matched poles s = fs ln z), else poles spread over the band; for ``z`` the poles of the
frequency-domain subspace model and poles spread over the band (:mod:`nlsid.fit.tf_starts`).
Integrators (poles fixed at z = 1 / s = 0) and fits kept inside the stable region serve the order
selection (:func:`nlsid.fit.tf_stable.fit_stable`, :mod:`nlsid.fit.order`).

Uncertainty: with the residuals r(theta) = [Re e_k, Im e_k], e_k = (G_k - G(Omega_k, theta))/sigma_k,
each of variance 1/2, cov(theta) = (1/2) (J^T J)^{-1} at the optimum (Gauss-Newton form of the
Cramér-Rao bound). The model's frequency response has var(G(Omega_k)) = g_k^H cov g_k with
g_k = dG(Omega_k)/dtheta, reported as a standard deviation per line. As the book warns (Ex 97, 98),
with dominant nonlinear distortions this underestimates the true variability (3-8 dB in Ex 97).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.cost_statistics import cost_bound, expected_cost
from nlsid.fit.frf_data import FRFData
from nlsid.fit.tf_basis import Basis
from nlsid.fit.tf_cost import line_weights
from nlsid.fit.tf_refine import EXTRA_EVALUATIONS, refine
from nlsid.fit.tf_starts import linear_start, spread_starts, subspace_start, theta_from_poles
from nlsid.models.lti import TransferFunction


@dataclass
class TFFit:
    """A fitted model with its cost check and uncertainty."""

    model: TransferFunction
    nb: int
    na: int
    names: list[str]
    values: np.ndarray
    covariance: np.ndarray
    cost: float
    expected_cost: float
    cost_std: float
    lines: int
    response: np.ndarray          # model at the data's bins
    response_std: np.ndarray      # std of the model's response per line
    warnings: list[str] = field(default_factory=list)
    cost_bound: float = math.nan  # the acceptance bound of the cost (:func:`nlsid.fit.cost_statistics.cost_bound`)
    integrators: int = 0          # poles fixed at z = 1 (s = 0), part of na
    how: str = "free"             # free, integrator or stabilised (:func:`nlsid.fit.tf_stable.fit_stable`)
    note: str = ""                # why a stabilised or integrator fit was made
    free_pole: float = math.nan   # the free fit's largest |z| (z) or Re s (s), :func:`nlsid.fit.tf_stable.fit_stable`
    vector: object = None         # the vector fit behind a fit of many poles (:mod:`nlsid.fit.tf_vector`), else None

    @property
    def n_theta(self) -> int:
        return self.na - self.integrators + self.nb + 1

    @property
    def accepted(self) -> bool:
        """The cost lies within its statistical bound (:func:`nlsid.fit.cost_statistics.cost_bound`)."""
        return bool(self.cost <= self.cost_bound)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.abs(np.diag(self.covariance)))


def _s_starts(data: FRFData, nb: int, na: int, delay: int, integrators: int, basis: Basis,
              weight: np.ndarray) -> tuple[list[np.ndarray], str]:
    """Starts of an s fit besides Levy/SK: the z fit of the same denominator order mapped to s
    (matched poles s = fs ln z, which has a real-coefficient equivalent when no free pole lies on
    the negative real z axis), else poles spread over the band (:func:`spread_starts`)."""
    free = na - integrators
    if free == 0:
        return [], ""
    z_fit = fit_order(data, min(na, max(nb, 1)), na, "z", delay, integrators, z_start=False)
    z_poles = np.roots(z_fit.model.den)  # den ascending in z^-1 = descending in z
    z_poles = z_poles[np.argsort(np.abs(z_poles - 1))][integrators:] if integrators else z_poles
    bad = (np.abs(z_poles.imag) <= 1e-12 * np.abs(z_poles)) & (z_poles.real <= 0)
    if z_poles.size == free and not np.any(bad):
        theta = theta_from_poles(basis, data.fs * np.log(z_poles.astype(complex)), weight)
        if theta is not None:
            return [theta], "the z fit mapped to s (matched poles)"
    return spread_starts(basis, weight), "poles spread over the band (the z fit has poles without a real s equivalent)"


def fit_order(data: FRFData, nb: int, na: int, domain: str = "z", delay: int = 0, integrators: int = 0,
              z_start: bool = True, extra_starts: bool = True) -> TFFit:
    """Fit one model order ``nb``/``na`` with a given dead time (samples); see the module docstring.

    ``integrators`` of the ``na`` poles are fixed at z = 1 (s = 0). An s fit starts from Levy/SK
    and from the z fit mapped to s (:func:`_s_starts`); the start with the lowest cost after
    Levenberg-Marquardt wins.
    """
    if domain not in ("s", "z"):
        raise InputError("--domain", f"expected s or z, got {domain!r}")
    if na < 0 or nb < 0 or (domain == "s" and nb > na):
        raise InputError("--order", f"{nb}/{na}: orders must be >= 0 and a continuous model proper (nb <= na)")
    n_theta = na - integrators + nb + 1
    if 2 * data.bins.size <= n_theta:
        raise InputError("--order", f"{nb}/{na} has {n_theta} parameters; {data.bins.size} lines give only "
                                    f"{2 * data.bins.size} real equations")
    weight = line_weights(data)
    basis = Basis(domain, data, nb, na - integrators, delay, integrators)
    result = refine(basis, linear_start(basis, weight), weight)
    fit = fit_result(basis, result, data, nb, na, integrators, weight)
    if not extra_starts or (fit.accepted and fit.model.stability() != "unstable"):
        return fit  # a stable fit within its cost bound: no other start can be significantly better
    # the linear start led to an unstable model or a cost above its bound (a local minimum, or a
    # too-low order): other starts, the best cost kept
    if domain == "s" and z_start:
        s_starts, how = _s_starts(data, nb, na, delay, integrators, basis, weight)
        starts = [(theta, how) for theta in s_starts]
    else:
        starts = [(theta, "the subspace model's poles (McKelvey, Akçay and Ljung 1996)")
                  for theta in subspace_start(basis, weight)]
        starts += [(theta, "poles spread over the band") for theta in spread_starts(basis, weight)]
    best, best_how = result, ""
    for theta0, how in starts:
        other = refine(basis, theta0, weight, evaluations=EXTRA_EVALUATIONS)
        if math.isfinite(other.cost) and other.cost < best.cost * (1 - 1e-9):
            best, best_how = other, how
    if best is result:
        return fit
    return fit_result(basis, best, data, nb, na, integrators, weight,
                   f"start: {best_how} (the linear start gave cost {fit.cost:.4g}, {fit.model.stability()})")


def refit(fit: TFFit, data: FRFData) -> TFFit:
    """``fit``'s model class (order, delay, integrators, stabilisation) fitted to other data (the
    held-out check's training lines), starting from ``fit``'s parameters."""
    delay = fit.model.delay
    weight = line_weights(data)
    basis = Basis(fit.model.domain, data, fit.nb, fit.na - fit.integrators, delay, fit.integrators)
    theta0 = fit.values / basis.values_scale()
    result = refine(basis, theta0, weight, stable_only=fit.how == "stabilised")
    return fit_result(basis, result, data, fit.nb, fit.na, fit.integrators, weight, fit.note, fit.how)


def fit_result(basis: Basis, result, data: FRFData, nb: int, na: int, integrators: int, weight: np.ndarray,
               note: str = "", how: str = "free") -> TFFit:
    """The :class:`TFFit` of an optimiser result (covariance, response std, cost check, warnings)."""
    theta = result.x
    J = result.jac
    with np.errstate(over="ignore", invalid="ignore"):
        JTJ = J.T @ J
    cov_theta = 0.5 * np.linalg.pinv(JTJ) if np.all(np.isfinite(JTJ)) else np.full((theta.size, theta.size), np.nan)
    model, scale, names = basis.to_model(theta)
    F = data.bins.size
    n_theta = theta.size
    # dG/dtheta per line from the Jacobian rows [Re, Im] of -(G_model) * weight
    g_re, g_im = -J[:F] / weight[:, None], -J[F:] / weight[:, None]
    response_var = np.einsum("ki,ij,kj->k", g_re, cov_theta, g_re) + np.einsum("ki,ij,kj->k", g_im, cov_theta, g_im)
    cost = float(2 * result.cost)
    expected, spread = expected_cost(F, n_theta, data.realizations)
    warnings = []
    if model.stability() == "unstable":
        warnings.append(f"order {nb}/{na}: the fitted model is unstable (nlsid simulate refuses it in open loop)")
    if result.status <= 0:
        warnings.append(f"order {nb}/{na}: Levenberg-Marquardt did not converge ({result.message})")
    return TFFit(model, nb, na, names, theta * scale, cov_theta * np.outer(scale, scale), cost,
                 expected, spread, F, basis.model(theta), np.sqrt(np.maximum(response_var, 0.0)), warnings,
                 cost_bound(F, n_theta, data.realizations), integrators, how, note)


def fit_transfer_function(data: FRFData, nb: int, na: int, domain: str = "z", delay: int | None = 0,
                          max_delay: int = 10) -> TFFit:
    """Fit ``nb``/``na``; ``delay=None`` picks the dead time 0..max_delay samples with the lowest cost."""
    if delay is not None:
        if delay < 0:
            raise InputError("--delay", f"must be >= 0 samples, got {delay}")
        return fit_order(data, nb, na, domain, delay)
    fits = [fit_order(data, nb, na, domain, d) for d in range(max_delay + 1)]
    return min(fits, key=lambda f: f.cost)
