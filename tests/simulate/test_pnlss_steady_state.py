"""The periodic steady state of a PNLSS model on a periodic record (nlsid.simulate.pnlss_runs:
shooting, the Jacobian the total derivative through it), on a lightly damped model whose transient
outlasts the 20-period lead-in it replaces: pole radius 0.995 at a 64-sample period decays by
0.995^1280 = 1.6e-3 over 20 periods, and by 0.995^(64 * 150) = 1e-21 over the 150 periods the truth
is simulated here (a direct loop of the model's equations, written in the test)."""

from __future__ import annotations

import numpy as np

from nlsid.models.pnlss import Pnlss, exponents
from nlsid.simulate.pnlss_runs import Record, jacobian_blocks, periodic_state, simulate_record

PERIOD = 64


def lightly_damped() -> Pnlss:
    """Two states, a resonance at pole radius 0.995, small quadratic and cubic terms in x and u."""
    r, w = 0.995, 0.5
    A = r * np.array([[np.cos(w), -np.sin(w)], [np.sin(w), np.cos(w)]])
    ex = exponents(2, (2, 3), True)
    rng = np.random.default_rng(3)
    E, F = 1e-3 * rng.standard_normal((2, ex.shape[0])), 1e-3 * rng.standard_normal(ex.shape[0])
    return Pnlss(A, np.array([0.05, 0.0]), np.array([0.0, 1.0]), 0.0, E, F, 1.0)


def direct(model: Pnlss, u: np.ndarray, periods: int) -> np.ndarray:
    """x[t+1] = A x + B u + E zeta(x, u), y = C x + D u + F eta(x, u), from rest over ``periods``
    repetitions of u; the last period's output."""
    ex = exponents(2, (2, 3), True)
    x, y = np.zeros(2), np.empty(u.size)
    for p in range(periods):
        for t, ut in enumerate(u):
            v = np.array([x[0], x[1], ut])
            mono = np.prod(v ** ex, axis=1)
            if p == periods - 1:
                y[t] = model.C @ x + model.D * ut + model.F @ mono
            x = model.A @ x + model.B * ut + model.E @ mono
    return y


def test_the_steady_state_is_the_state_after_the_transient_has_died():
    model = lightly_damped()
    u = np.random.default_rng(4).standard_normal(PERIOD)
    record = Record("p", u, np.zeros(PERIOD), PERIOD)
    truth = direct(model, u, 150)
    steady = periodic_state(model, record, 1e6)
    assert steady is not None
    assert np.max(np.abs(np.linalg.eigvals(steady[1]))) < 1  # an attracting orbit
    y = simulate_record(model, record, None, 1e6)
    assert np.max(np.abs(y - truth)) < 1e-9 * np.max(np.abs(truth)), np.max(np.abs(y - truth))
    # what 20 periods from rest leave: the lead-in this replaces was 1.6e-3 off here
    assert np.max(np.abs(direct(model, u, 20) - truth)) > 1e-4 * np.max(np.abs(truth))


def test_the_jacobian_is_the_derivative_of_the_steady_state_output():
    """Columns of A, B and E (row-major in the kernel's layout) against central differences of the
    directly simulated steady state (step 1e-6: truncation of order 1e-12, rounding 1e-10 of a
    column)."""
    model = lightly_damped()
    u = np.random.default_rng(5).standard_normal(PERIOD)
    record = Record("p", u, np.zeros(PERIOD), PERIOD)
    (_, J), = list(jacobian_blocks(model, record, None, 1e6))
    n = 2
    nz = model.E.shape[1]
    cases = {"A[0,1]": (n + 1, lambda m, h: m.replace(A=m.A + h * _unit(m.A.shape, 0, 1))),
             "B[0]": (n + n * n, lambda m, h: m.replace(B=m.B + h * np.array([1.0, 0.0]))),
             "E[1,2]": (n + n * n + n + nz + 2, lambda m, h: m.replace(E=m.E + h * _unit(m.E.shape, 1, 2)))}
    for name, (column, moved) in cases.items():
        h = 1e-6
        fd = (direct(moved(model, h), u, 120) - direct(moved(model, -h), u, 120)) / (2 * h)  # 0.995^7680 = 2e-17
        error = np.linalg.norm(J[:, column] - fd) / np.linalg.norm(fd)
        assert error < 1e-5, (name, error)


def _unit(shape, i, j):
    out = np.zeros(shape)
    out[i, j] = 1.0
    return out
