"""Static blocks per signal of a ``mimo_state_space`` model (``input_nonlinearity``,
``output_nonlinearity``) in :func:`nlsid.simulate.mimo.simulate_mimo`, against a simulation written
here: the exact zero-order hold from scipy's matrix exponential of [[A, B], [0, 0]] h, a plain loop,
and the blocks' laws written with numpy (np.clip, np.polyval, np.interp with its end segments)."""

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
A = np.array([[0.0, 1.0, 0.0], [-W**2, -2 * 0.2 * W, 0.0], [0.0, 0.0, -3.0]])
B = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]])
C = np.array([[10.0, 0.0, 0.0], [0.3, 0.01, 1.0]])
D = np.array([[0.0, 0.1], [0.0, 0.0]])

BLOCKS = {"input_nonlinearity": {"force": {"type": "polynomial", "coefficients": [0.1, 1.0, 0.0, -0.2]}},
          "output_nonlinearity": {"y": {"type": "deadzone", "lower": -0.05, "upper": 0.02},
                                  "accel": {"type": "saturation", "lower": -0.03, "upper": 0.025}}}


def _config(**changes):
    return {"type": "mimo_state_space", "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": D.tolist(),
            "inputs": ["u", "force"], "outputs": ["y", "accel"], **changes}


def _model(**changes):
    return build(validate_simulate_config({"model": _config(**changes)}, None, {}))


def _reference(U):
    """p = (u, 0.1 + f - 0.2 f^3), y = (deadzone(C_0 x + D_0 p), clip(C_1 x + D_1 p, -0.03, 0.025))."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A / FS, B / FS
    E = expm(M)
    Phi, Gamma = E[:n, :n], E[:n, n:]
    P = np.stack([U[0], np.polyval([-0.2, 0.0, 1.0, 0.1], U[1])])
    x = np.zeros(n)
    Y = np.zeros((2, U.shape[1]))
    for k in range(U.shape[1]):
        Y[:, k] = C @ x + D @ P[:, k]
        x = Phi @ x + Gamma @ P[:, k]
    dead = np.where(Y[0] > 0.02, Y[0] - 0.02, np.where(Y[0] < -0.05, Y[0] + 0.05, 0.0))
    return np.stack([dead, np.clip(Y[1], -0.03, 0.025)])


def test_blocks_on_inputs_and_outputs_equal_the_loop_written_here():
    rng = np.random.default_rng(14)
    U = 0.3 * rng.standard_normal((2, 400))
    run = Run("r", FS, "arbitrary", U[0], channels={"force": U[1]}, inputs=("u", "force"))
    Y = simulate_mimo(_model(**BLOCKS), run).output_matrix()
    truth = _reference(U)
    np.testing.assert_allclose(Y, truth, rtol=0, atol=1e-10)
    assert np.mean(truth[1] == 0.025) > 0.05 and np.mean(truth[0] == 0) > 0.05  # the blocks act on the data
    # a piecewise-linear block: np.interp inside, the end segments continued outside
    x, y = [-0.02, 0.0, 0.03], [-0.05, 0.0, 0.01]
    line = simulate_mimo(_model(output_nonlinearity={"accel": {"type": "piecewise_linear", "x": x, "y": y}}), run)
    linear = simulate_mimo(_model(), run).output_matrix()[1]
    slope_lo, slope_hi = (y[1] - y[0]) / (x[1] - x[0]), (y[2] - y[1]) / (x[2] - x[1])
    expected = np.where(linear < x[0], y[0] + slope_lo * (linear - x[0]),
                        np.where(linear > x[2], y[2] + slope_hi * (linear - x[2]), np.interp(linear, x, y)))
    np.testing.assert_allclose(line.output_matrix()[1], expected, rtol=0, atol=1e-12)
    assert np.any(linear < x[0]) and np.any(linear > x[2])


def test_config_round_trip_keeps_the_blocks():
    model = _model(**BLOCKS)
    again = build(validate_simulate_config({"model": model.config()}, None, {}))
    assert set(again.input_blocks) == {"force"} and set(again.output_blocks) == {"y", "accel"}
    for name, block in model.output_blocks.items():
        assert again.output_blocks[name].kind == block.kind
        np.testing.assert_array_equal(again.output_blocks[name].params, block.params)


@pytest.mark.parametrize("key, blocks, expected", [
    ("output_nonlinearity", {"y3": {"type": "saturation", "lower": -1, "upper": 1}},
     "model.output_nonlinearity: 'y3' is not an output of the model (its outputs: y, accel)"),
    ("input_nonlinearity", {"u2": {"type": "saturation", "lower": -1, "upper": 1}},
     "model.input_nonlinearity: 'u2' is not an input of the model (its inputs: u, force)"),
    ("input_nonlinearity", {"force": {"type": "backlash", "width": 0.1}},
     "model.input_nonlinearity: force: a backlash has memory"),
])
def test_unknown_names_and_blocks_with_memory_are_refused_at_their_key(key, blocks, expected):
    with pytest.raises(InputError) as error:
        validate_simulate_config({"model": _config(**{key: blocks})}, "m.yaml", {})
    assert expected in str(error.value)
