"""The linear model of several inputs and outputs (:class:`nlsid.models.lti.MimoStateSpace`):
its frequency response matrix against scipy's transfer functions of each input, evaluated apart."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from nlsid.errors import InputError
from nlsid.io.model_config import validate_simulate_config
from nlsid.models.from_config import model as build

# A 2-input 2-output plant of 3 states: a mode at 2 Hz with 5 % damping and a real pole at 3 rad/s
W = 2 * np.pi * 2.0
A = [[0.0, 1.0, 0.0], [-W**2, -2 * 0.05 * W, 0.0], [0.0, 0.0, -3.0]]
B = [[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]]
C = [[1.0, 0.0, 0.0], [0.3, 0.01, 1.0]]
D = [[0.0, 0.1], [0.0, 0.0]]


def _model(**changes):
    config = {"type": "mimo_state_space", "A": A, "B": B, "C": C, "D": D, **changes}
    return build(validate_simulate_config({"model": config}, None, {}))


def _scipy_response(a, b, c, d, freqs, fs=None):
    """(F, n_y, n_u) from ss2tf of each input, evaluated by freqs (s = j w) or freqz (z = e^{j w / fs})."""
    out = np.empty((len(freqs), len(c), len(b[0])), complex)
    for i in range(len(b[0])):
        num, den = signal.ss2tf(np.array(a), np.array(b), np.array(c), np.array(d), input=i)
        for o in range(len(c)):
            if fs is None:
                out[:, o, i] = signal.freqs(num[o], den, worN=2 * np.pi * freqs)[1]
            else:  # num and den of equal length in descending powers of z: the same in ascending z^-1
                out[:, o, i] = signal.freqz(num[o], den, worN=freqs, fs=fs)[1]
    return out


def test_continuous_response_matrix_equals_the_transfer_functions_of_each_input():
    freqs = np.array([0.0, 0.5, 1.9, 2.0, 2.1, 10.0, 100.0])
    G = _model().frequency_response(freqs)
    truth = _scipy_response(A, B, C, D, freqs)
    assert G.shape == (7, 2, 2)
    np.testing.assert_allclose(G, truth, rtol=1e-9, atol=1e-12)
    assert abs(G[0, 0, 0] - 1 / W**2) < 1e-12  # the DC gain of the mode, -C A^-1 B + D by hand


def test_discrete_response_and_a_dead_time():
    a = [[0.9, 0.2], [-0.2, 0.7]]
    b, c, d = [[1.0, 0.0], [0.5, 1.0]], [[1.0, 0.0], [0.0, 1.0]], [[0.0, 0.0], [0.2, 0.0]]
    freqs = np.linspace(0.0, 49.0, 9)
    model = _model(A=a, B=b, C=c, D=d, domain="discrete", fs=100.0)
    np.testing.assert_allclose(model.frequency_response(freqs), _scipy_response(a, b, c, d, freqs, fs=100.0),
                               rtol=1e-10, atol=1e-12)
    delayed = _model(A=a, B=b, C=c, D=d, domain="discrete", fs=100.0, delay=0.03)
    shift = np.exp(-2j * np.pi * freqs * 0.03)[:, None, None]  # three samples: z^-3
    np.testing.assert_allclose(delayed.frequency_response(freqs), model.frequency_response(freqs) * shift, atol=1e-12)
    unrated = _model(A=a, B=b, C=c, D=d, domain="discrete")
    with pytest.raises(InputError, match="states no sample rate"):
        unrated.frequency_response(freqs)
    np.testing.assert_allclose(unrated.frequency_response(freqs, fs=100.0), model.frequency_response(freqs))


def test_unstable_model_refused_and_config_round_trip():
    with pytest.raises(InputError, match="unstable model: pole with real part 1"):
        _model(A=[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -2.0]])
    model = _model(inputs=["u", "force"], outputs=["y", "accel"])
    again = build(validate_simulate_config({"model": model.config()}, None, {}))
    assert again.inputs == ("u", "force") and again.outputs == ("y", "accel")
    for name in "ABCD":
        np.testing.assert_array_equal(getattr(again, name), getattr(model, name))


@pytest.mark.parametrize("extra, where, what", [
    ({"closed_loop": {"controller": {"type": "pid", "kp": 1.0}}}, "closed_loop", "not a mimo_state_space model"),
    ({"simulation": {"substeps": 4}}, "simulation.substeps", "one step per sample; remove substeps"),
])
def test_a_closed_loop_and_substeps_are_refused(extra, where, what):
    config = {"type": "mimo_state_space", "A": A, "B": B, "C": C}
    with pytest.raises(InputError) as info:
        build(validate_simulate_config({"model": config, **extra}, None, {}))
    assert info.value.where == where and what in info.value.what
