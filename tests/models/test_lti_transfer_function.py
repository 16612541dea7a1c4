"""The transfer function of the config conventions as an LTI model (nlsid.models.lti.TransferFunction):
its state space, sampled response and stability, checked against scipy.signal's own discretisation
and frequency responses."""

import numpy as np
import pytest
from scipy import signal

from nlsid.errors import InputError
from nlsid.models.lti import TransferFunction, check_stable, sampled_response, stability

FS = 1000.0
N = 4096
BINS = np.array([1, 7, 40, 300, 1200, 2047])


def _freqz(num_desc_z, den_desc_z, bins, period):
    """scipy's response of B(z)/A(z) (descending powers of z) at z = e^{j 2 pi k / N}."""
    _, h = signal.freqz(num_desc_z, den_desc_z, worN=2 * np.pi * bins / period)
    return h


def test_a_continuous_model_responds_as_its_zoh_discretisation_by_scipy():
    """A lightly damped mode (40 Hz, zeta 0.05) with a zero, 3 samples dead time: the response at
    the sample instants is that of scipy.signal.cont2discrete(ZOH) times z^-3 (to rounding)."""
    w = 2 * np.pi * 40.0
    num, den = np.array([0.3 * w, w * w]), np.array([1.0, 2 * 0.05 * w, w * w])
    tf = TransferFunction("s", num, den, 3, FS)
    bd, ad, _ = signal.cont2discrete((num, den), 1.0 / FS, method="zoh")
    z = np.exp(2j * np.pi * BINS / N)
    expected = _freqz(np.ravel(bd), ad, BINS, N) * z ** -3
    np.testing.assert_allclose(tf.response(BINS, N), expected, rtol=1e-9, atol=1e-12)


def test_a_discrete_model_responds_as_scipy_freqz():
    """b0 + b1 z^-1 over 1 - 1.5 z^-1 + 0.7 z^-2 (ascending in z^-1, as the config writes it),
    1 sample dead time: scipy.signal.freqz of the same coefficients times z^-1."""
    num, den = np.array([0.2, 0.1]), np.array([1.0, -1.5, 0.7])
    tf = TransferFunction("z", num, den, 1, FS)
    z = np.exp(2j * np.pi * BINS / N)
    expected = _freqz(num, den, BINS, N) * z ** -1
    np.testing.assert_allclose(tf.response(BINS, N), expected, rtol=1e-12)


@pytest.mark.parametrize("domain", ["s", "z"])
def test_the_state_space_is_the_config_loaders_and_holds_the_same_model(domain):
    """to_state_space gives the model of the config block (same dead time in seconds, discrete
    for z); its sampled response is the transfer function's without the dead time."""
    if domain == "s":
        num, den = np.array([2.0, 50.0]), np.array([1.0, 12.0, 400.0])
    else:
        num, den = np.array([0.5, -0.2, 0.1]), np.array([1.0, -0.9])  # nb > na: a further pole at z = 0
    tf = TransferFunction(domain, num, den, 2, FS)
    ss = tf.to_state_space()
    assert ss.discrete == (domain == "z")
    assert ss.delay == pytest.approx(2 / FS)
    z = np.exp(2j * np.pi * BINS / N)
    np.testing.assert_allclose(sampled_response(ss, z, 1.0 / FS), tf.response(BINS, N) * z ** 2, rtol=1e-9)
    if domain == "s":  # the continuous response B(jw)/A(jw) of the state space itself
        s = 2j * np.pi * np.array([1.0, 20.0, 300.0])
        np.testing.assert_allclose(ss.frequency_response(s), np.polyval(num, s) / np.polyval(den, s), rtol=1e-12)


@pytest.mark.parametrize("domain, den, expected", [
    ("s", [1.0, 3.0, 2.0], "stable"),        # poles -1, -2
    ("s", [1.0, 1.0, 0.0], "marginal"),      # an integrator: poles 0, -1
    ("s", [1.0, -1.0, -2.0], "unstable"),    # poles 2, -1
    ("z", [1.0, -0.5], "stable"),            # pole 0.5
    ("z", [1.0, -1.0], "marginal"),          # pole 1
    ("z", [1.0, 0.0, -1.21], "unstable"),    # poles +-1.1
])
def test_stability_is_one_rule_for_the_fit_and_the_simulator(domain, den, expected):
    """The fitted transfer function's stability and the loader's check (check_stable refuses
    exactly the unstable ones) read the same poles the same way."""
    tf = TransferFunction(domain, np.array([1.0]), np.array(den), 0, FS)
    assert tf.stability() == expected
    assert stability(tf.to_state_space().poles(), domain == "z") == expected
    if expected == "unstable":
        with pytest.raises(InputError, match="unstable model"):
            check_stable(tf.to_state_space(), "model")
    else:
        check_stable(tf.to_state_space(), "model")
