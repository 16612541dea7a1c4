"""A linear model of several inputs and outputs on a run (:mod:`nlsid.simulate.mimo`), against a
simulation written here: the exact zero-order hold from scipy's matrix exponential of the augmented
matrix [[A, B], [0, 0]] h, then a plain loop."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from nlsid.errors import InputError
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.run import Run
from nlsid.models.from_config import model as build
from nlsid.simulate.mimo import simulate_mimo

FS = 100.0
W = 2 * np.pi * 2.0
A = np.array([[0.0, 1.0, 0.0], [-W**2, -2 * 0.2 * W, 0.0], [0.0, 0.0, -3.0]])  # slowest decay 2.5 /s
B = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]])
C = np.array([[10.0, 0.0, 0.0], [0.3, 0.01, 1.0]])
D = np.array([[0.0, 0.1], [0.0, 0.0]])


def _model(**changes):
    config = {"type": "mimo_state_space", "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": D.tolist(),
              "inputs": ["u", "force"], "outputs": ["y", "accel"], **changes}
    return build(validate_simulate_config({"model": config}, None, {}))


def _reference(U, x0=None, delay=0):
    """y[k] = C x[k] + D u[k - delay], x[k+1] = Phi x[k] + Gamma u[k - delay], Phi and Gamma from expm."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A / FS, B / FS
    E = expm(M)
    Phi, Gamma = E[:n, :n], E[:n, n:]
    x = np.zeros(n) if x0 is None else x0
    Y = np.zeros((C.shape[0], U.shape[1]))
    for k in range(U.shape[1]):
        p = U[:, k - delay] if k >= delay else np.zeros(m)
        Y[:, k] = C @ x + D @ p
        x = Phi @ x + Gamma @ p
    return Y


def test_2x2_continuous_model_equals_the_exact_zero_order_hold_loop():
    rng = np.random.default_rng(4)
    U = rng.standard_normal((2, 400))
    run = Run("r", FS, "arbitrary", U[0], channels={"force": U[1], "temperature": np.ones(400)},
              inputs=("u", "force"))
    out = simulate_mimo(_model(), run)
    np.testing.assert_allclose(out.output_matrix(), _reference(U), rtol=0, atol=1e-10)
    assert out.inputs == ("u", "force") and out.outputs == ("y", "accel")
    np.testing.assert_array_equal(out.input_matrix(), U)  # the inputs carried as recorded
    np.testing.assert_array_equal(out.channels["temperature"], np.ones(400))  # other channels kept
    delayed = simulate_mimo(_model(delay=0.03), run)
    np.testing.assert_allclose(delayed.output_matrix(), _reference(U, delay=3), rtol=0, atol=1e-10)


def test_periodic_steady_state_is_the_end_of_a_long_run_from_rest():
    """One period of 64 samples, repeated for 40 periods (25.6 s: the slowest mode decays by e^-64)
    in the reference loop: its last period is the steady state the model starts in."""
    rng = np.random.default_rng(5)
    period = 64
    U = rng.standard_normal((2, period))
    run = Run("p", FS, "multisine", np.tile(U[0], 2), period=period, excited_bins=np.arange(1, 20),
              channels={"force": np.tile(U[1], 2)}, inputs=("u", "force"))
    truth = _reference(np.tile(U, 40))[:, -period:]
    steady = simulate_mimo(_model(delay=0.02), run, steady=True).output_matrix()
    np.testing.assert_allclose(steady[:, :period], _reference(np.tile(U, 40), delay=2)[:, -period:], atol=1e-10)
    np.testing.assert_allclose(simulate_mimo(_model(), run, steady=True).output_matrix()[:, period:], truth, atol=1e-10)


def test_arbitrary_record_in_motion_starts_from_the_fitted_state():
    rng = np.random.default_rng(6)
    U = rng.standard_normal((2, 2400))  # the slowest mode decays to 1e-6 in 553 samples, within a quarter
    x0 = np.array([0.02, -0.3, 0.5])
    Y = _reference(U, x0)  # a record cut from a longer run: its start holds a free response
    run = Run("a", FS, "arbitrary", U[0], y=Y[0], channels={"force": U[1], "accel": Y[1]}, inputs=("u", "force"),
              outputs=("y", "accel"))
    np.testing.assert_allclose(simulate_mimo(_model(), run, steady=True).output_matrix(), Y, atol=1e-9)
    assert np.max(np.abs(simulate_mimo(_model(), run).output_matrix() - Y)) > 0.1  # from rest it misses it


@pytest.mark.parametrize("run, what", [
    (Run("s", FS, "arbitrary", np.ones(10)),
     "has no input 'force' (the model's inputs: u, force; the run's channels: none)"),
    (Run("s", FS, "arbitrary", np.ones(10), channels={"force": np.ones(10), "v": np.ones(10)}, inputs=("u", "force", "v")),
     "has input 'v', which the model does not take (its inputs: u, force): simulating it would drop that input"),
    (Run("s", FS, "arbitrary", np.ones(10), channels={"force": np.ones(10), "accel": np.ones(10)}),
     "has a channel 'accel' that is not one of its outputs (y): the model's output 'accel' would overwrite it"),
])
def test_a_run_the_model_cannot_take_whole_is_refused(run, what):
    with pytest.raises(InputError) as info:
        simulate_mimo(_model(), run)
    assert info.value.where == "s" and info.value.what == what


def test_noise_rows_first_as_for_one_input_and_output_the_others_independent():
    from nlsid.simulate.noise import NoiseLevels, draw, draw_channels

    levels = NoiseLevels(u=0.1, y=0.2, process=0.3)
    stream = np.random.SeedSequence(11).spawn(3)[2]
    one, rows = draw(levels, stream, 4000), draw_channels(levels, stream, 4000, 2, 3)
    for kind, count in (("u", 2), ("y", 3), ("process", 2)):
        matrix = getattr(rows, kind)
        assert matrix.shape == (count, 4000)
        np.testing.assert_array_equal(matrix[0], getattr(one, kind))
        # independent rows of the same std: |correlation| < 5 / sqrt(4000), variance within 5 sigma
        assert np.all(np.abs(np.corrcoef(matrix)[np.triu_indices(count, 1)]) < 5 / np.sqrt(4000))
        assert np.all(np.abs(matrix.var(axis=1) / getattr(levels, kind) ** 2 - 1) < 5 * np.sqrt(2 / 4000))
