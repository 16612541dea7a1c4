"""A free parameter without any effect on the simulated output is undetermined: the fit says so and
its standard error is infinite, not zero (an unknown is never reported as a reassuring value).

The data: a second-order plant stepped exactly for a held input (Van Loan's block exponential,
tests/generators/exact_zoh.py, not nlsid's simulator) with white sensor noise; the model is that plant
behind an input saturation whose upper limit lies far beyond the input (|u| < 4, limit 100), so
moving the limit changes no simulated sample: the Jacobian column is exactly zero. The plant's
own gain is free beside it and must stay determined (finite, at the truth within 5 standard
errors)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from generators.exact_zoh import zoh  # noqa: E402
from nlsid.fit.extension import fit_free_parameters  # noqa: E402
from nlsid.fit.free_parameters import FreeParameter  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

FS, N, NOISE = 1000.0, 4000, 1e-3
GAIN = 1e4  # y = GAIN / (s^2 + 20 s + 4e4) u


def test_a_limit_beyond_the_signal_has_an_infinite_standard_error():
    rng = np.random.default_rng(4)
    u = np.repeat(rng.uniform(-4.0, 4.0, N // 10), 10)
    phi, gamma = zoh(np.array([[0.0, 1.0], [-4e4, -20.0]]), np.array([0.0, 1.0]), 1 / FS)
    x, y = np.zeros(2), np.empty(N)
    for k in range(N):
        y[k] = GAIN * x[0]
        x = phi @ x + gamma * u[k]
    y += NOISE * rng.standard_normal(N)
    model = {"model": {"type": "transfer_function", "num": [0.9 * GAIN], "den": [1.0, 20.0, 4e4],
                       "input_nonlinearity": {"type": "saturation", "lower": -100.0, "upper": 100.0}}}
    free = {"model.input_nonlinearity.upper": FreeParameter(100.0, 50.0, 200.0),
            "model.num[0]": FreeParameter(0.9 * GAIN, 1.0, 1e6)}
    fit = fit_free_parameters(model, free, [Run("r", FS, "arbitrary", u, y=y)], [])
    upper, gain = fit.names.index("model.input_nonlinearity.upper"), fit.names.index("model.num[0]")
    assert math.isinf(fit.std[upper])
    assert any("has no effect" in w for w in fit.warnings), fit.warnings
    assert math.isfinite(fit.std[gain]) and abs(fit.values[gain] - GAIN) < 5 * fit.std[gain]
