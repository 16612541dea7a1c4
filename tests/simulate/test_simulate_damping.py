"""The ``quadratic_damping`` (F = c2 v|v|) and ``cubic_damping`` (F = c3 v^3) forces against a
reference computed here, independently of nlsid's simulator: classical Runge-Kutta on the held
input, 64 steps per sample (its own error, about (w h)^4 with w h < 0.01, is far below the
tolerances), checked by halving its step.

The law is stepped with the implicit midpoint rule (:mod:`nlsid.models.forces`), second order: 4x
finer sub-steps must divide the error by about 16 (asserted > 10, order above 1.66); a first-order
step would divide it by 4.
"""

from __future__ import annotations

import numpy as np
import pytest

from nlsid.errors import InputError
from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate.runs import simulate_run

FS = 100.0
M, C, K = 1.0, 0.5, 100.0  # 10 rad/s, lightly damped: the nonlinear damping dominates at the peaks


def rk4(force, u: np.ndarray, steps: int) -> np.ndarray:
    """Sampled position of m p'' + c p' + k p + force(p') = u, u held over each sample."""
    h = 1.0 / FS / steps
    x = np.zeros(2)
    out = np.empty(u.size)

    def rhs(z, f):
        return np.array([z[1], (f - C * z[1] - K * z[0] - force(z[1])) / M])

    for i, f in enumerate(u):
        out[i] = x[0]
        for _ in range(steps):
            k1 = rhs(x, f)
            k2 = rhs(x + 0.5 * h * k1, f)
            k3 = rhs(x + 0.5 * h * k2, f)
            k4 = rhs(x + h * k3, f)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


def excitation(n: int = 600) -> np.ndarray:
    t = np.arange(n) / FS
    return 40.0 * np.sin(2 * np.pi * 1.3 * t) + 25.0 * np.sin(2 * np.pi * 2.1 * t + 0.4)


def simulate(force: dict, u: np.ndarray, substeps: int) -> np.ndarray:
    cfg = mc.SimulateConfig.model_validate({"model": {"type": "mass_spring_damper", "mass": M, "damping": C,
                                                      "stiffness": K, "nonlinearities": [force]}})
    return simulate_run(from_config.model(cfg), None, Run("r", FS, "arbitrary", u), substeps).y


@pytest.mark.parametrize("force, law", [
    ({"type": "quadratic_damping", "c2": 2.0}, lambda v: 2.0 * v * np.abs(v)),
    ({"type": "cubic_damping", "c3": 1.5}, lambda v: 1.5 * v**3),
])
def test_damping_converges_at_second_order_to_runge_kutta(force, law):
    u = excitation()
    reference = rk4(law, u, 64)
    assert np.max(np.abs(reference - rk4(law, u, 32))) < 1e-9 * np.max(np.abs(reference))  # RK4 converged
    linear = rk4(lambda v: 0.0 * v, u, 8)
    effect = np.max(np.abs(reference - linear))
    assert effect > 0.2 * np.max(np.abs(reference))  # the force matters: a strong nonlinearity
    errors = [np.max(np.abs(simulate(force, u, s) - reference)) for s in (2, 8)]
    assert errors[0] < 1e-3 * effect  # measured 1.4e-4 (quadratic) and 1.0e-4 (cubic)
    assert errors[0] / errors[1] > 14.0  # second order: 16 for 4x finer sub-steps (measured 16.00)


def test_damping_needs_a_positive_coefficient():
    from nlsid.io.config import validate

    for force in ({"type": "quadratic_damping", "c2": -1.0}, {"type": "cubic_damping", "c3": 0.0}):
        data = {"model": {"type": "mass_spring_damper", "mass": 1.0, "nonlinearities": [force]}}
        with pytest.raises(InputError, match="nonlinearities"):
            validate(data, mc.SimulateConfig, "m.yaml", {})
