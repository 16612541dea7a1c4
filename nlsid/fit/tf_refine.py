"""Levenberg-Marquardt refinement of a transfer-function fit on its weighted cost.

From a start (:mod:`nlsid.fit.tf_starts`), :func:`scipy.optimize.least_squares` (``lm``) minimises
V(theta) on the residuals stacked as real and imaginary parts (:func:`nlsid.fit.tf_cost.residual`),
optionally kept inside the stable region.
"""

from __future__ import annotations

import numpy as np

from nlsid.fit.tf_basis import Basis
from nlsid.fit.tf_cost import residual as weighted_residual


EXTRA_EVALUATIONS = 60  # per parameter (+1): the budget of Levenberg-Marquardt from a further start


def refine(basis: Basis, theta0: np.ndarray, weight: np.ndarray, stable_only: bool = False,
           evaluations: int = 200):
    """Levenberg-Marquardt on V from theta0. ``stable_only``: a step to a parameter vector whose
    free factor is not strictly stable is refused (a huge residual, which LM treats as a failed
    step and answers with a shorter one), so the minimum found lies in the stable region."""
    from scipy.optimize import least_squares

    def residual(theta):
        if stable_only and not basis.stable(theta):
            return np.full(2 * weight.size, 1e150)
        out = weighted_residual(basis, theta, weight)
        return out if np.all(np.isfinite(out)) else np.full(out.size, 1e150)

    with np.errstate(over="ignore", invalid="ignore"):
        result = least_squares(residual, theta0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                               max_nfev=evaluations * (theta0.size + 1))
    if stable_only:  # the optimiser's Jacobian may hold the barrier's values: the plain one at the optimum
        result.jac = _jacobian(basis, result.x, weight)
    return result


def _jacobian(basis: Basis, theta: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of the stacked residual [Re e, Im e] at ``theta``."""
    J = np.empty((2 * weight.size, theta.size))
    for i in range(theta.size):
        h = 1e-6 * max(abs(theta[i]), 1e-3)
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        J[:, i] = (weighted_residual(basis, up, weight) - weighted_residual(basis, down, weight)) / (2 * h)
    return J
