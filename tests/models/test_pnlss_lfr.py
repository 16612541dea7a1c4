"""The nonlinear LFR form of the PNLSS model (nlsid.models.pnlss; Schoukens and Tiels 2017): the
monomials are those of z = Cz x + Dz u. Its simulation against a plain loop written here, its
exact sensitivities (Cz and Dz included) against central finite differences, and its config."""

from __future__ import annotations

import numpy as np
import pytest

import nlsid
from nlsid.errors import InputError
from nlsid.fit.pnlss import global_vector, with_vector
from nlsid.models.pnlss import Pnlss, from_linear, lfr_start_rows, to_config
from nlsid.models.lti import from_transfer_function
from nlsid.simulate.pnlss_runs import Record, jacobian_blocks, simulate_record


def _reference(A, B, C, D, E, F, Cz, Dz, u):
    """Two combinations z1, z2; the monomials of degrees 2 and 3 written out by hand in the
    documented order (combinations_with_replacement of z1, z2)."""
    def mono(z1, z2):
        return np.array([z1 * z1, z1 * z2, z2 * z2, z1 ** 3, z1 * z1 * z2, z1 * z2 * z2, z2 ** 3])
    x = np.zeros(A.shape[0])
    y = np.empty(len(u))
    for t, v in enumerate(u):
        m = mono(*(Cz @ x + Dz * v))
        y[t] = C @ x + D * v + F @ m
        x = A @ x + B * v + E @ m
    return y


def _random_lfr(rng, n=3, nz=2):
    A = np.diag(np.linspace(0.8, -0.3, n)) + 0.05 * rng.standard_normal((n, n))
    Cz, Dz = 0.5 * rng.standard_normal((nz, n)), 0.5 * rng.standard_normal(nz)
    E, F = 0.03 * rng.standard_normal((n, 7)), 0.1 * rng.standard_normal(7)
    return Pnlss(A, rng.standard_normal(n), rng.standard_normal(n), 0.3, E, F, 1.0, (2, 3), (2, 3), Cz=Cz, Dz=Dz)


def test_simulation_equals_a_plain_loop():
    rng = np.random.default_rng(0)
    model = _random_lfr(rng)
    u = 0.4 * rng.standard_normal(500)
    expected = _reference(model.A, model.B, model.C, model.D, model.E, model.F, model.Cz, model.Dz, u)
    np.testing.assert_allclose(model.simulate(u), expected, rtol=1e-12, atol=1e-12)
    assert model.monomials((2,)) == ["z1^2", "z1*z2", "z2^2"]
    assert model.n_parameters == 9 + 3 + 3 + 1 + 21 + 7 + 6 + 2


def _central_differences(f, theta, relative=1e-5):
    columns = []
    for p in range(theta.size):
        h = relative * max(1.0, abs(theta[p]))
        up, down = theta.copy(), theta.copy()
        up[p] += h
        down[p] -= h
        columns.append((f(up) - f(down)) / (2 * h))
    return np.column_stack(columns)


@pytest.mark.parametrize("nz", [1, 2])
def test_exact_jacobian_equals_central_differences(nz):
    """dy/d(x0, A, B, E, Cz, Dz, C, D, F) from the sensitivity recursion (chain rule through z)
    against central differences of the simulation, step 1e-5 relative: truncation ~h^2 |y'''| ~
    1e-10 and rounding ~1e-16 / 1e-5 = 1e-11 of each column, so 1e-6 leaves room without hiding a
    wrong term (a missing W x_k term in a Cz column is an O(1) relative error)."""
    rng = np.random.default_rng(1 + nz)
    model = _random_lfr(rng, 3, 2)
    if nz == 1:
        model = Pnlss(model.A, model.B, model.C, model.D, model.E[:, [0, 3]], model.F[[0, 3]], 1.0, (2, 3), (2, 3),
                      Cz=model.Cz[:1], Dz=model.Dz[:1])
    n = model.order
    u = 0.5 * rng.standard_normal(200)
    record = Record("r", u, np.zeros(u.size), None)
    x0 = 0.1 * rng.standard_normal(n)
    J = np.vstack([block for _, block in jacobian_blocks(model, record, x0, 1e6)])
    theta = np.concatenate([x0, global_vector(model)])
    assert J.shape[1] == theta.size
    fd = _central_differences(lambda th: simulate_record(with_vector(model, th[n:]), record, th[:n], 1e6), theta)
    relative = np.linalg.norm(J - fd, axis=0) / np.linalg.norm(fd, axis=0)
    assert relative.max() < 1e-6, relative.max()
    start = n + n * n + n + model.E.size
    mixing = slice(start, start + model.Cz.size + model.Dz.size)  # the Cz, Dz columns: not trivially zero
    assert np.all(np.linalg.norm(fd[:, mixing], axis=0) > 1e-3)


def test_exact_jacobian_periodic_record():
    """A periodic record: the lead-in's sensitivities (Cz, Dz included) carry into the steady rows."""
    rng = np.random.default_rng(4)
    model = _random_lfr(rng, 2, 2)
    period = 64
    u = np.tile(0.5 * rng.standard_normal(period), 3)
    record = Record("p", u, np.zeros(u.size), period)
    J = np.vstack([block for _, block in jacobian_blocks(model, record, None, 1e6)])[:, 2:]
    fd = _central_differences(lambda th: simulate_record(with_vector(model, th), record, None, 1e6),
                              global_vector(model))
    relative = np.linalg.norm(J - fd, axis=0) / np.linalg.norm(fd, axis=0)
    assert relative.max() < 1e-6, relative.max()


def test_start_rows_and_config_round_trip():
    """from_linear's LFR start: z1 = C x + D u (the linear output), z2 = u; E = F = 0, so the
    model is the linear one. Its config runs as the model, and bad LFR keys are refused by name."""
    ss = from_transfer_function([0.2, 0.1], [1.0, -1.2, 0.5], True, 0.0, "t")
    model, _ = from_linear(ss, 10.0, (2, 3), (3,), lfr_inputs=2)
    np.testing.assert_allclose(model.Cz[0], model.C)
    assert model.Dz.tolist() == [model.D, 1.0] and not model.Cz[1].any()
    assert model.E.shape == (2, 7) and model.F.shape == (4,)  # 3 + 4 and 4 monomials of (z1, z2)
    rng = np.random.default_rng(5)
    model = model.replace(E=0.01 * rng.standard_normal(model.E.shape), F=0.1 * rng.standard_normal(4))
    config = {"model": to_config(model)}
    assert config["model"]["nonlinearity"]["form"] == "lfr"
    u = 0.5 * rng.standard_normal(300)
    np.testing.assert_allclose(nlsid.Model.from_dict(config).simulate(u, fs=10.0), model.simulate(u), rtol=1e-12)
    # inputs alone: Cz, Dz from lfr_start_rows
    short = {"model": {**config["model"], "nonlinearity": {"form": "lfr", "inputs": 2}}}
    Cz, Dz = lfr_start_rows(model.C, model.D, 2)
    np.testing.assert_allclose(nlsid.Model.from_dict(short).simulate(u, fs=10.0),
                               model.replace(Cz=Cz, Dz=Dz).simulate(u))
    bad = {"model": {**config["model"], "nonlinearity": {"form": "lfr", "Cz": [[1.0, 2.0, 3.0]]}}}
    with pytest.raises(InputError, match=r"nonlinearity\.Cz.*2 coefficients"):
        nlsid.Model.from_dict(bad).simulate(u, fs=10.0)
    wrong_e = {"model": {**config["model"], "E": [[0.0] * 16] * 2}}
    with pytest.raises(InputError, match=r"model\.E.*7 coefficients.*z1\^2, z1\*z2"):
        nlsid.Model.from_dict(wrong_e).simulate(u, fs=10.0)
    for section, match in (({"form": "lfr"}, "inputs"), ({"form": "full", "inputs": 1}, "lfr"),
                           ({"form": "lfr", "inputs": 9}, "1 to 3")):
        with pytest.raises(InputError, match=match):
            nlsid.Model.from_dict({"model": {**config["model"], "nonlinearity": section}}).simulate(u, fs=10.0)
