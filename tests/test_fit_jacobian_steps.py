"""The fit engine forms its finite-difference Jacobian itself (its columns simulated together), so
its steps must be scipy's forward-difference rule: the Jacobian (f(x + h_i e_i) - f(x)) / h_i with
:func:`nlsid.fit.extension.forward_steps` is compared with scipy's own
``approx_derivative(method="2-point", rel_step=...)`` (the Jacobian ``least_squares`` forms with
``diff_step``), bit for bit, at points inside, near and on the bounds, at zero and at negative
values. The function is analytic, so a wrong step (size, sign or bound rule) changes the numbers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from nlsid.fit.extension import forward_steps


def f(x: np.ndarray) -> np.ndarray:
    return np.array([np.sin(3 * x[0]) + x[1] ** 3, np.exp(0.5 * x[1]) * x[2], x[0] * x[2] ** 2 + np.cos(x[1])])


CASES = [
    (np.array([0.7, -1.3, 2.0]), np.full(3, -np.inf), np.full(3, np.inf)),         # no bounds
    (np.array([0.0, -1e-12, 1e5]), np.full(3, -np.inf), np.full(3, np.inf)),       # zero, tiny, large
    (np.array([0.9999, -1.3, 2.0]), np.array([-1.0, -5.0, 0.0]), np.array([1.0, 5.0, 2.0])),  # at and near upper bounds
    (np.array([0.001, -1.3, 0.0015]), np.array([0.0, -1.3005, 0.0]), np.array([0.0015, 0.0, 0.0016])),  # narrow boxes
]


@pytest.mark.parametrize("x, lower, upper", CASES)
@pytest.mark.parametrize("rel_step", [1e-3, 1e-6])
def test_the_steps_give_scipys_forward_difference_jacobian(x, lower, upper, rel_step):
    h = forward_steps(x, rel_step, lower, upper)
    f0 = f(x)
    ours = np.empty((3, 3))
    for i in range(3):
        shifted = x + np.where(np.arange(3) == i, h, 0.0)
        assert lower[i] <= shifted[i] <= upper[i]
        ours[:, i] = (f(shifted) - f0) / (shifted[i] - x[i])
    theirs = approx_derivative(f, x, method="2-point", rel_step=rel_step, f0=f0, bounds=(lower, upper))
    np.testing.assert_array_equal(ours, theirs)
