"""The PNLSS model (nlsid.models.pnlss): its monomials, its simulation against a plain loop written
here, its linear start against scipy's discretisation, and its exact sensitivities against central
finite differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import solve_discrete_lyapunov

from nlsid.errors import InputError
from nlsid.fit.pnlss import global_vector, with_vector
from nlsid.simulate.pnlss_runs import Record, jacobian_blocks, simulate_record
from nlsid.models.lti import StateSpace, from_transfer_function
from nlsid.models.pnlss import Pnlss, balanced, check_degrees, exponents, from_linear, monomial_names


@pytest.mark.parametrize("n_vars, degree", [(3, 2), (3, 3), (7, 2), (7, 3), (4, 5)])
def test_monomial_count_is_the_multiset_number(n_vars, degree):
    """Monomials of total degree d in v variables: binom(v + d - 1, d), each of total degree d, all distinct."""
    table = exponents(n_vars - 1, (degree,), with_input=True)
    assert table.shape == (math.comb(n_vars + degree - 1, degree), n_vars)
    assert np.all(table.sum(axis=1) == degree)
    assert len({tuple(r) for r in table}) == table.shape[0]


def test_monomial_order_is_documented_order():
    assert monomial_names(2, (2,)) == ["x1^2", "x1*x2", "x1*u", "x2^2", "x2*u", "u^2"]
    assert monomial_names(2, (3,), with_input=False) == ["x1^3", "x1^2*x2", "x1*x2^2", "x2^3"]


@pytest.mark.parametrize("bad", [[1, 2], [2, 2], [2.5], ["a"]])
def test_bad_degrees_are_refused(bad):
    with pytest.raises(InputError, match="degree"):
        check_degrees(bad, "degrees")


def _reference(A, B, C, D, E, F, u):
    """Two states and the input; the monomials written out by hand in the documented order."""
    def mono(x1, x2, v):
        return np.array([x1 * x1, x1 * x2, x1 * v, x2 * x2, x2 * v, v * v,
                         x1 ** 3, x1 * x1 * x2, x1 * x1 * v, x1 * x2 * x2, x1 * x2 * v, x1 * v * v,
                         x2 ** 3, x2 * x2 * v, x2 * v * v, v ** 3])
    x = np.zeros(2)
    y = np.empty(len(u))
    for t, v in enumerate(u):
        m = mono(x[0], x[1], v)
        y[t] = C @ x + D * v + F @ m
        x = A @ x + B * v + E @ m
    return y


def test_simulation_equals_a_plain_loop():
    rng = np.random.default_rng(0)
    A = np.array([[0.7, 0.2], [-0.2, 0.6]])
    B, C = np.array([1.0, 0.5]), np.array([0.3, -1.0])
    E, F = 0.02 * rng.standard_normal((2, 16)), 0.1 * rng.standard_normal(16)
    model = Pnlss(A, B, C, 0.4, E, F, 100.0, (2, 3), (2, 3))
    u = 0.3 * rng.standard_normal(500)
    np.testing.assert_allclose(model.simulate(u), _reference(A, B, C, 0.4, E, F, u), rtol=1e-12, atol=1e-12)


def test_divergence_is_reported_not_returned():
    A = np.array([[0.5, 0.0], [0.0, 0.5]])
    model = Pnlss(A, np.ones(2), np.ones(2), 0.0, np.full((2, 16), 5.0), np.zeros(16), 1.0)
    y, t = model.try_simulate(np.full(100, 2.0), bound=1e6)
    assert 0 <= t < 100
    with pytest.raises(InputError, match="diverged"):
        model.simulate(np.full(100, 2.0), bound=1e6)


def test_start_keeps_the_zoh_frequency_response():
    """A continuous resonance with a dead time of 2 samples: the PNLSS start's linear part has the
    frequency response of scipy's ZOH discretisation times z^-2."""
    fs = 100.0
    w, zeta = 2 * np.pi * 8.0, 0.05
    num, den = [w * w], [1.0, 2 * zeta * w, w * w]
    ss = from_transfer_function(num, den, False, 2 / fs, "t")
    model, how = from_linear(ss, fs, (3,), (3,), with_input=False)
    assert how == "balanced realisation" and model.order == 4
    bd, ad, _ = signal.cont2discrete((num, den), 1 / fs, method="zoh")
    f = np.linspace(0.5, 40, 50)
    z = np.exp(2j * np.pi * f / fs)
    _, expected = signal.freqz(bd.ravel(), ad, worN=f, fs=fs)
    np.testing.assert_allclose(model.linear.frequency_response(z), expected * z ** -2, rtol=1e-8)
    assert not model.E.any() and not model.F.any()


def test_balanced_gramians_are_equal_and_diagonal():
    b, a = signal.cheby1(4, 1.0, 0.2)
    ss = from_transfer_function(list(b), list(a), True, 0.0, "t")
    bal, how = balanced(ss)
    Wc = solve_discrete_lyapunov(bal.A, np.outer(bal.B, bal.B))
    Wo = solve_discrete_lyapunov(bal.A.T, np.outer(bal.C, bal.C))
    scale = np.max(np.abs(Wc))
    np.testing.assert_allclose(Wc, Wo, atol=1e-9 * scale)
    np.testing.assert_allclose(Wc - np.diag(np.diag(Wc)), 0, atol=1e-9 * scale)


def test_unstable_linear_part_is_kept_as_given():
    ss = StateSpace(np.array([[1.2]]), np.array([1.0]), np.array([1.0]), 0.0, discrete=True)
    bal, how = balanced(ss)
    assert "unstable" in how and bal.A[0, 0] == 1.2


def _central_differences(f, theta, relative=1e-5):
    columns = []
    for p in range(theta.size):
        h = relative * max(1.0, abs(theta[p]))
        up, down = theta.copy(), theta.copy()
        up[p] += h
        down[p] -= h
        columns.append((f(up) - f(down)) / (2 * h))
    return np.column_stack(columns)


def _random_model(rng, n, with_input=True):
    A = np.diag(np.linspace(0.8, -0.3, n)) + 0.05 * rng.standard_normal((n, n))
    nz = exponents(n, (2, 3), with_input).shape[0]
    return Pnlss(A, rng.standard_normal(n), rng.standard_normal(n), 0.3, 0.02 * rng.standard_normal((n, nz)),
                 0.05 * rng.standard_normal(nz), 1.0, (2, 3), (2, 3), with_input)


@pytest.mark.parametrize("with_input", [True, False])
def test_exact_jacobian_equals_central_differences_arbitrary_record(with_input):
    """dy/d(x0, A, B, E, C, D, F) from the sensitivity recursion against central differences of the
    simulation (step 1e-5 relative: truncation ~1e-10, rounding ~1e-11 of each column)."""
    rng = np.random.default_rng(1)
    n = 3
    model = _random_model(rng, n, with_input)
    u = 0.5 * rng.standard_normal(200)
    record = Record("r", u, np.zeros(u.size), None)
    x0 = 0.1 * rng.standard_normal(n)
    J = np.vstack([block for _, block in jacobian_blocks(model, record, x0, 1e6)])
    theta = np.concatenate([x0, global_vector(model)])
    fd = _central_differences(lambda th: simulate_record(with_vector(model, th[n:]), record, th[:n], 1e6), theta)
    relative = np.linalg.norm(J - fd, axis=0) / np.linalg.norm(fd, axis=0)
    assert relative.max() < 1e-6, relative.max()


def test_exact_jacobian_equals_central_differences_periodic_record():
    """A periodic record of three periods: the steady state moves with the parameters, and the rows
    are the total derivative through it (central differences of the steady-state output)."""
    rng = np.random.default_rng(2)
    model = _random_model(rng, 2)
    period = 64
    u = np.tile(0.5 * rng.standard_normal(period), 3)
    record = Record("p", u, np.zeros(u.size), period)
    J = np.vstack([block for _, block in jacobian_blocks(model, record, None, 1e6)])[:, 2:]
    theta = global_vector(model)
    fd = _central_differences(lambda th: simulate_record(with_vector(model, th), record, None, 1e6), theta)
    relative = np.linalg.norm(J - fd, axis=0) / np.linalg.norm(fd, axis=0)
    assert relative.max() < 1e-6, relative.max()


def _config_model():
    rng = np.random.default_rng(6)
    A = np.array([[0.7, 0.2], [-0.2, 0.6]])
    B, C = np.array([1.0, 0.5]), np.array([0.3, -1.0])
    E, F = 0.02 * rng.standard_normal((2, 16)), 0.1 * rng.standard_normal(16)
    config = {"model": {"type": "pnlss", "fs": 100.0, "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": 0.4,
                        "state_degrees": [2, 3], "output_degrees": [2, 3], "E": E.tolist(), "F": F.tolist(),
                        "output_offset": 0.25}}
    return config, (A, B, C, 0.4, E, F)


def test_config_model_simulates_as_the_plain_loop():
    import nlsid

    config, matrices = _config_model()
    u = 0.3 * np.random.default_rng(7).standard_normal(400)
    y = nlsid.Model.from_dict(config).simulate(u, fs=100.0)
    np.testing.assert_allclose(y, _reference(*matrices, u) + 0.25, rtol=1e-12, atol=1e-12)


def test_config_model_refuses_another_rate_and_wrong_sizes():
    import nlsid

    config, _ = _config_model()
    with pytest.raises(InputError, match="model.fs.*100 Hz.*200 Hz"):
        nlsid.Model.from_dict(config).simulate(np.zeros(10), fs=200.0)
    config["model"]["F"] = config["model"]["F"][:-1]
    with pytest.raises(InputError, match=r"model\.F.*16 coefficients"):
        nlsid.Model.from_dict(config).simulate(np.zeros(10), fs=100.0)
    config["model"]["state_degrees"] = [1, 3]
    with pytest.raises(InputError, match="state_degrees"):
        nlsid.Model.from_dict(config)
