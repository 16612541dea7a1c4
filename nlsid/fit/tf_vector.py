"""Transfer-function fits of many poles by vector fitting, in the form of :class:`nlsid.fit.tf_fit.TFFit`.

A model of N poles with nb = na = N (n_theta = 2N + 1, the class of the polynomial fit N/N) is
fitted in pole-residue form (:func:`nlsid.fit.vector_fitting.vector_fit`: relaxed vector fitting,
then Levenberg-Marquardt on the same weighted cost V as the polynomial fit), always as a ``z``
model at the BLA's rate; a ``s`` model is the continuous system whose zero-order-hold equivalent it
is (:mod:`nlsid.fit.modal_model`), so both domains compare the same response with the BLA.

Measured against the polynomial fit from its linear and further starts (:func:`nlsid.fit.tf_fit.fit_order`,
one BLAS thread): on the BLA of a Wiener-Hammerstein system (18 000 lines, six poles) 6/6 reached
cost 17 916 (a local minimum; 0.99 s), vector fitting 17 724 (0.82 s); 8/8 came out unstable
(2.9 s) where vector fitting is stable (2.4 s); on 10 modes (1600 lines, bound about 1 660) 20/20
ended at 693 055, vector fitting at 1 575 (0.3 s each).

The model written: the transfer function with polynomial coefficients when its own response
reproduces the fit (cost within POLYNOMIAL_TOLERANCE of the pole-residue form's and the same
stability), else the modal state space (:class:`nlsid.fit.modal_model.ModalModel`). The
parameters reported are those of the form written: the polynomial coefficients with the
covariance carried over from the pole-residue form by the delta method (cov_c = T cov_theta T^T,
T = dc/dtheta by central differences), or the poles, residues and d themselves.

How the fit is described (``how``): ``free`` when the Levenberg-Marquardt refinement was kept (a
minimum of V over poles and residues that happens to lie inside the stable region), else
``stabilised`` (stability asked: the relocation's poles reflected into the stable region, its best
cost kept).
"""

from __future__ import annotations

import math

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.cost_statistics import cost_bound, expected_cost
from nlsid.fit.frf_data import FRFData
from nlsid.fit.modal_model import ModalModel
from nlsid.fit.tf_fit import TFFit
from nlsid.fit.vector_fitting import VectorFit, vector_fit
from nlsid.models.lti import TransferFunction

POLYNOMIAL_TOLERANCE = 1e-3  # the polynomial form may raise the cost by this many times its noise std, at most
BOUNDARY_STD = 3.0           # a stabilised pole within this many std of the boundary lies on it (tf_stable's rule)
HOLDOUT_RELOCATIONS = 0      # relocation steps of the held-out refit: its start is the full fit's poles
HOLDOUT_EVALUATIONS = 20     # and its Levenberg-Marquardt Jacobians


def _cost(data: FRFData, response: np.ndarray) -> float:
    value = float(np.sum(np.abs(data.G - response) ** 2 / data.variance))
    return value if math.isfinite(value) else math.inf


def _parameter_names(fit: VectorFit) -> list[str]:
    """Names of :attr:`VectorFit.parameters`: p1, r1 per real pole; p1.re, p1.im, r1.re, r1.im per
    pair; d."""
    names = []
    for i, p in enumerate(fit.poles, start=1):
        names += ([f"p{i}.re", f"p{i}.im", f"r{i}.re", f"r{i}.im"] if p.imag > 0 else [f"p{i}", f"r{i}"])
    return names + ["d"]


def _coefficients(fit: VectorFit, domain: str) -> tuple[np.ndarray, list[str]]:
    """The polynomial fit's parameter vector (:class:`nlsid.fit.tf_basis.Basis` order, config
    values): z: a1..aN, b0..bN; s: a0..a(N-1) (of s^0..s^(N-1)), b0..bN (of s^0..s^N)."""
    model = ModalModel(fit, domain)
    num, den = np.asarray(model.num, float), np.asarray(model.den, float)
    N = den.size - 1
    num = np.pad(num, (N + 1 - num.size, 0)) if domain == "s" else np.pad(num, (0, N + 1 - num.size))
    if domain == "z":
        return np.concatenate([den[1:], num]), [f"a{i}" for i in range(1, N + 1)] + [f"b{i}" for i in range(N + 1)]
    return (np.concatenate([den[::-1][:N], num[::-1]]),
            [f"a{i}" for i in range(N)] + [f"b{i}" for i in range(N + 1)])


def _delta_covariance(fit: VectorFit, domain: str) -> np.ndarray:
    """cov of the polynomial coefficients: T cov_theta T^T, T by central differences of the map
    from the pole-residue parameters to the coefficients (NaN without a covariance)."""
    values, _ = _coefficients(fit, domain)
    if fit.covariance is None:
        return np.full((values.size, values.size), np.nan)
    theta = fit.parameters
    T = np.empty((values.size, theta.size))
    std = np.sqrt(np.abs(np.diag(fit.covariance)))
    for i in range(theta.size):
        h = max(1e-6 * std[i], 1e-9 * max(abs(theta[i]), 1e-12))
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        T[:, i] = (_coefficients(fit.with_parameters(up), domain)[0]
                   - _coefficients(fit.with_parameters(down), domain)[0]) / (2 * h)
    return T @ fit.covariance @ T.T


def from_vector_fit(fit: VectorFit, data: FRFData, domain: str, stable: bool) -> TFFit:
    """The :class:`TFFit` of a ``z`` vector fit of ``data`` (module docstring), as a ``domain`` model."""
    N = fit.order
    modal = ModalModel(fit, domain)
    modal.to_state_space()  # an s model needs every pole to have a continuous equivalent: InputError if not
    response = modal.response(data.bins, data.period)
    modal_cost = _cost(data, response)
    F = data.bins.size
    expected, spread = expected_cost(F, fit.n_parameters, data.realizations)
    tolerance = POLYNOMIAL_TOLERANCE * math.sqrt(max(F - fit.n_parameters / 2, 1.0))
    poly = TransferFunction(domain, modal.num, modal.den, fit.delay, fit.fs)
    try:
        with np.errstate(all="ignore"):
            poly_response = poly.response(data.bins, data.period)
        poly_cost = _cost(data, poly_response)
        poly_ok = poly_cost <= modal_cost + tolerance and poly.stability() == modal.stability()
    except (InputError, np.linalg.LinAlgError, ValueError):
        poly_ok = False
    if poly_ok:
        model, cost, response = poly, poly_cost, poly_response
        values, names = _coefficients(fit, domain)
        covariance = _delta_covariance(fit, domain)
    else:
        model, cost = modal, modal_cost
        values, names, covariance = fit.parameters, _parameter_names(fit), fit.covariance
        if covariance is None:
            covariance = np.full((values.size, values.size), np.nan)
    how = "free" if fit.refined or not stable else "stabilised"
    form = ("transfer function" if poly_ok else
            "modal state space (the polynomial coefficients do not reproduce the fit in floating point)")
    text = (f"vector fitting (Gustavsen and Semlyen 1999) of {N} poles, {fit.iterations} relocation steps, "
            + ("refined by Levenberg-Marquardt" if fit.refined else
               "the relocation's poles kept (the refinement left the stable region or did not lower the cost)")
            + f"; written as a {form}")
    warnings = []
    if model.stability() == "unstable":
        warnings.append(f"order {N}/{N}: the fitted model is unstable (nlsid simulate refuses it in open loop)")
    result = TFFit(model, N, N, names, np.asarray(values, float), np.asarray(covariance, float), cost, expected,
                   spread, F, response, fit.response_std(data.frequency), warnings,
                   cost_bound(F, fit.n_parameters, data.realizations), 0, how, text,
                   float(np.max(np.abs(fit.all_poles()))) if domain == "z" else
                   float(np.max(modal.poles().real)), fit)
    return result


def fit_vector(data: FRFData, poles: int, domain: str = "z", delay: int = 0, stable: bool = True) -> TFFit:
    """A model of ``poles`` poles (nb = na = poles) fitted by vector fitting (module docstring)."""
    fit = vector_fit(data.frequency, data.G, data.variance, poles, "z", data.fs, stable=stable, delay=delay)
    return from_vector_fit(fit, data, domain, stable)


def refit_vector(fit: TFFit, data: FRFData) -> TFFit:
    """``fit``'s model class (a vector fit) fitted to other data (the held-out check's training
    lines) from ``fit``'s poles: a few relocation steps and the refinement."""
    vector = fit.vector
    stable = fit.how == "stabilised" or vector.stable()
    new = vector_fit(data.frequency, data.G, data.variance, vector.order, "z", data.fs, stable=stable,
                     delay=vector.delay, poles=vector.poles, iterations=HOLDOUT_RELOCATIONS,
                     refine_evaluations=HOLDOUT_EVALUATIONS)
    return from_vector_fit(new, data, fit.model.domain, stable)


def holdout_error(data: FRFData, fit: TFFit) -> float:
    """The mean weighted squared error on the odd-indexed lines of ``fit``'s class fitted again
    (:func:`refit_vector`) on the even-indexed ones, as :func:`nlsid.fit.order.holdout_error`."""
    index = np.arange(data.bins.size)
    train, test = data.subset(index % 2 == 0), data.subset(index % 2 == 1)
    vector = refit_vector(fit, train).vector
    error = test.G - vector.frequency_response(test.frequency)
    return float(np.mean(np.abs(error) ** 2 / test.variance))


def on_boundary(fit: TFFit) -> bool:
    """A pole of a vector fit within BOUNDARY_STD standard deviations of the stability boundary of
    z (1 - |p|, its std by the delta method on (Re p, Im p): d|p| = (Re p dRe p + Im p dIm p)/|p|);
    poles whose covariance is unknown (a singular Jacobian) are not judged."""
    vector = fit.vector
    if vector.covariance is None:
        return False
    index = 0
    for p in vector.poles:
        width = 2 if p.imag > 0 else 1
        if width == 2:
            cov = vector.covariance[index:index + 2, index:index + 2]
            grad = np.array([p.real, p.imag]) / abs(p)
        else:
            cov = vector.covariance[index:index + 1, index:index + 1]
            grad = np.array([np.sign(p.real) or 1.0])
        std = math.sqrt(max(float(grad @ cov @ grad), 0.0))
        if 1 - abs(p) <= BOUNDARY_STD * std:
            return True
        index += 2 * width
    return False
