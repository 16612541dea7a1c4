"""The black-box term of a hybrid model (nlsid/fit/hybrid.py): its output equation started by
linear least squares along the state trajectory of a given state equation.

The data come from a direct numpy loop of the PNLSS equations written here (the monomials formed
with itertools in the documented order, docs/pnlss.md), not from nlsid's kernels: with the true
state equation kept, the output y = C x + D u + F eta(x, u) + c is linear in (C, D, F, c), so on
noise-free data the least squares must return them to rounding (1e-8 relative, the conditioning
of a few hundred rows of monomials of size 0.1-1)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from nlsid.fit.hybrid import fit_black_box, output_equation, residual_run
from nlsid.io.run import Run
from nlsid.models.pnlss import Pnlss

FS = 50.0
A = np.array([[0.6, 0.25], [-0.2, 0.5]])
B = np.array([1.0, -0.4])
C = np.array([0.7, -1.3])
D, OFFSET = 0.15, 0.42


def _monomials(v: np.ndarray, degrees) -> np.ndarray:
    """Products of the entries of v of each total degree, in itertools.combinations_with_replacement order."""
    return np.array([np.prod([v[i] for i in combo]) for d in degrees
                     for combo in itertools.combinations_with_replacement(range(v.size), d)])


def _loop(E, F, u, mix=None, degrees=(2, 3)):
    """x[t+1] = A x + B u + E zeta(v), y = C x + D u + F eta(v) + c; v = (x, u), or mix(x, u) (LFR)."""
    x, y = np.zeros(2), np.empty(u.size)
    for t, ut in enumerate(u):
        v = np.append(x, ut) if mix is None else mix[0] @ x + mix[1] * ut
        m = _monomials(v, degrees)
        y[t] = C @ x + D * ut + F @ m + OFFSET
        x = A @ x + B * ut + E @ m
    return y


def _runs(E, F, mix=None):
    rng = np.random.default_rng(3)
    period = 64
    u_period = 0.5 * rng.standard_normal(period)
    lead = 20  # periods from rest: the linear part (|eig| 0.56) decays by 1e-100, the record is in steady state
    y = _loop(E, F, np.tile(u_period, lead + 2), mix)[lead * period:]
    periodic = Run("p", FS, "multisine", np.tile(u_period, 2), y, period=period)
    u = 0.5 * rng.standard_normal(300)
    arbitrary = Run("a", FS, "noise", u, _loop(E, F, u, mix))
    return [periodic, arbitrary]


@pytest.mark.parametrize("form", ["full", "lfr"])
def test_least_squares_output_equation_recovers_c_d_f_exactly(form):
    rng = np.random.default_rng(11)
    if form == "full":
        mix, nv = None, 3
        start_kw = {}
    else:
        Cz, Dz = np.array([[0.8, -0.5]]), np.array([0.6])
        mix, nv = (Cz, Dz), 1
        start_kw = {"Cz": Cz, "Dz": Dz}
    terms = len(_monomials(np.ones(nv), (2, 3)))
    E = 0.03 * rng.standard_normal((2, terms))
    F = 0.5 * rng.standard_normal(terms)
    runs = _runs(E, F, mix)
    start = Pnlss(A, B, np.zeros(2), 0.0, E, np.zeros(terms), FS, **start_kw)  # the output equation unknown
    fitted, rms = output_equation(start, runs)
    np.testing.assert_allclose(fitted.C, C, rtol=1e-8)
    np.testing.assert_allclose(fitted.F, F, rtol=1e-8, atol=1e-10)
    assert fitted.D == pytest.approx(D, rel=1e-8) and fitted.output_offset == pytest.approx(OFFSET, rel=1e-8)
    np.testing.assert_array_equal(fitted.A, A)  # the state equation is kept
    np.testing.assert_array_equal(fitted.E, E)
    assert rms < 1e-9


def test_black_box_term_fitted_to_the_residual_of_a_physical_part():
    """y = a physical part's output (a known FIR filter here) + a PNLSS term: on the residual
    y - y_p, the term's start from its true state equation is exact and the fit keeps it there
    (its validation error at rounding level); given y itself instead, the least squares leave the
    physical part's share as error: the residual is what the term needs."""
    rng = np.random.default_rng(5)
    E = 0.03 * rng.standard_normal((2, 16))
    F = 0.5 * rng.standard_normal(16)
    runs = _runs(E, F)
    physical = [np.convolve(run.u, [0.0, 0.9, -0.3])[:run.n_samples] for run in runs]  # y_p, from rest
    measured = [residual_run(run, -yp) for run, yp in zip(runs, physical)]  # y = y_b + y_p
    residual = [residual_run(run, yp) for run, yp in zip(measured, physical)]
    np.testing.assert_allclose(residual[1].y, runs[1].y, rtol=1e-13, atol=1e-13)
    start = Pnlss(A, B, np.zeros(2), 0.0, E, np.zeros(16), FS)
    fit = fit_black_box(start, [residual[1]], [residual[0]], max_iterations=2, patience=2)
    assert fit.validation_rms < 1e-8 * np.std(runs[0].y)
    _, rms_on_y = output_equation(start, measured)
    assert rms_on_y > 0.1 * np.std(physical[1])


@pytest.mark.parametrize("form", ["full", "lfr"])
def test_minus_linear_simulates_the_difference(form):
    """The black-box term's start beside a linear model (minus_linear): its output is the PNLSS
    model's (the numpy loop above) minus the linear model's (scipy.signal.lfilter of its transfer
    function D + C (z - a)^-1 B = (D + (C B - a D) z^-1) / (1 - a z^-1)), to rounding."""
    from scipy import signal

    from nlsid.fit.hybrid import minus_linear
    from nlsid.models.lti import StateSpace

    rng = np.random.default_rng(2)
    mix = None if form == "full" else (np.array([[0.8, -0.5]]), np.array([0.6]))
    terms = 16 if form == "full" else 2
    E, F = 0.03 * rng.standard_normal((2, terms)), 0.5 * rng.standard_normal(terms)
    extra = {} if mix is None else {"Cz": mix[0], "Dz": mix[1]}
    model = Pnlss(A, B, C, D, E, F, FS, output_offset=OFFSET, **extra)
    a, b, c, d = 0.7, 1.0, 0.4, 0.1
    linear = StateSpace(np.array([[a]]), np.array([b]), np.array([c]), d, discrete=True)
    u = 0.5 * rng.standard_normal(200)
    wide = minus_linear(model, linear)
    expected = _loop(E, F, u, mix) - signal.lfilter([d, c * b - a * d], [1.0, -a], u)
    np.testing.assert_allclose(wide.simulate(u), expected, rtol=1e-12, atol=1e-12)
    assert wide.order == 3 and wide.lfr and wide.E.shape[1] == terms  # the same monomials, in the LFR form


def test_difference_of_two_pnlss_models_simulates_the_difference():
    """The start from both models (difference): a full-form model (the loop above) minus an LFR
    one of one combination, z = cz x + dz u, whose loop is written here; the difference's output is
    theirs to rounding, and each model's coefficients are its own monomials' (the mixed ones zero)."""
    from nlsid.fit.hybrid import difference

    rng = np.random.default_rng(8)
    E, F = 0.03 * rng.standard_normal((2, 16)), 0.5 * rng.standard_normal(16)
    a2, b2, c2, d2 = np.array([[0.7, 0.1], [0.0, 0.4]]), np.array([0.5, 1.0]), np.array([1.0, 0.3]), -0.2
    cz, dz = np.array([0.6, -0.4]), 0.3
    e2, f2 = np.array([[0.05, -0.02], [0.01, 0.03]]), np.array([0.2, -0.1])  # z^2, z^3
    first = Pnlss(A, B, C, D, E, F, FS, output_offset=OFFSET)
    second = Pnlss(a2, b2, c2, d2, e2, f2, FS, output_offset=0.1, Cz=cz[None, :], Dz=np.array([dz]))
    u = 0.5 * rng.standard_normal(200)
    x, y2 = np.zeros(2), np.empty(u.size)
    for t, ut in enumerate(u):
        z = cz @ x + dz * ut
        y2[t] = c2 @ x + d2 * ut + f2 @ [z ** 2, z ** 3] + 0.1
        x = a2 @ x + b2 * ut + e2 @ [z ** 2, z ** 3]
    both = difference(first, second)
    np.testing.assert_allclose(both.simulate(u), _loop(E, F, u) - y2, rtol=1e-12, atol=1e-12)
    assert both.order == 4 and both.lfr_inputs == 3 + 1
    assert np.count_nonzero(both.E) == E.size + e2.size and np.count_nonzero(both.F) == F.size + f2.size
