"""Nonlinear blocks (values from their definitions) and block structures (seed 002, Lemma 1).

The structure tests use discrete-time LTI blocks, for which the output spectrum of a parallel
Wiener-Hammerstein (LPL) system under a sine is given exactly by seed 002 Theorem 1 / Lemma 1 with
G(e^{j w Ts}) (no aliasing: every harmonic stays below Nyquist). The expected spectra are computed
here from the paper's matrices Phi, Omega, Gamma (Eq. 8), independently of the simulator, so the
agreement is to rounding: 1e-9 relative to the fundamental leaves a wide margin over the ~1e-13
rounding and the transient left after the transient periods (pole radius <= 0.8: 0.8^1024 ~ 1e-99).
"""

import numpy as np
import pytest
from scipy.special import comb

from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.models.blocks import static_block
from nlsid.simulate.engine import apply_static
from nlsid.simulate.runs import simulate_run

N = 1024
K0 = 5          # the sine sits on line 5; harmonics up to 3 * 5 = 15 << N / 2
GAMMA, PHI = 0.8, 0.4


def block(**kw):
    encoded = static_block(mc.SimulateConfig.model_validate({"model": {"type": "wiener", "linear": {
        "type": "transfer_function", "num": [1.0], "den": [1.0], "domain": "discrete"}, "nonlinear": kw}}).model.nonlinear)
    return lambda x: apply_static(encoded, x)


def test_polynomial_block_evaluates_ascending_coefficients():
    x = np.array([-2.0, -0.5, 0.0, 1.5])
    f = block(type="polynomial", coefficients=[0.5, -1.0, 2.0, 0.25])
    np.testing.assert_allclose(f(x), 0.5 - x + 2 * x**2 + 0.25 * x**3, rtol=1e-15)


def test_saturation_deadzone_and_piecewise_linear_values():
    x = np.array([-3.0, -1.0, -0.2, 0.0, 0.5, 2.0, 4.0])
    np.testing.assert_array_equal(block(type="saturation", lower=-1.0, upper=2.0)(x), [-1, -1, -0.2, 0, 0.5, 2, 2])
    np.testing.assert_allclose(block(type="deadzone", lower=-0.5, upper=1.0)(x), [-2.5, -0.5, 0, 0, 0, 1, 3])
    # Points (-1, -2), (0, 0), (1, 1): slopes 2 then 1, extended beyond the ends.
    pwl = block(type="piecewise_linear", x=[-1.0, 0.0, 1.0], y=[-2.0, 0.0, 1.0])
    np.testing.assert_allclose(pwl(x), [-6, -2, -0.4, 0, 0.5, 2, 4])


def test_backlash_play_operator_by_hand():
    # Half width 0.5, output starts at 0: it moves only when the input is more than 0.5 away.
    x = np.array([0.0, 1.0, 2.0, 1.0, 0.0, -1.0, 0.3])
    np.testing.assert_allclose(block(type="backlash", width=1.0)(x), [0.0, 0.5, 1.5, 1.5, 0.5, -0.5, -0.2])


def theorem1(alpha: np.ndarray, gamma: float, phi: float) -> np.ndarray:
    """Y = Phi(phi) Omega Gamma(gamma) alpha (seed 002, Eq. 8): single-sided lines 0..P."""
    P = alpha.size
    omega = np.zeros((P + 1, P))
    for p in range(1, P + 1):
        if p % 2 == 0:
            # DC: the mean of cos^p is C(p, p/2) / 2^p, so Omega_{1,p} = C(p, p/2). The printed Eq. 6 /
            # Theorem 1 carry an extra factor p/2, equal to 1 for p = 2 (Example 1's matrix) but
            # wrong for p = 4 (it would give 3/4 instead of the mean 3/8 of cos^4).
            omega[0, p - 1] = comb(p, p // 2)
        for k in range(1, p + 1):
            if (p - k) % 2 == 0:
                omega[k, p - 1] = 2 * comb(p, (p - k) // 2)
    gains = (gamma / 2) ** np.arange(1, P + 1)
    return np.exp(1j * np.arange(P + 1) * phi) * (omega @ (gains * alpha))


def dtf(b, a):
    def response(k):
        zinv = np.exp(-2j * np.pi * np.asarray(k) / N)
        return np.polyval(b[::-1], zinv) / np.polyval(a[::-1], zinv)

    return response


def spectrum_of(y_period: np.ndarray, lines: int) -> np.ndarray:
    """Single-sided spectrum: Y_0 = mean, Y_k = 2 X[k] / N (so y = sum |Y_k| cos(k w t + angle))."""
    X = np.fft.fft(y_period)
    out = 2 * X[: lines * K0 + 1: K0] / N
    out[0] /= 2
    return out


def sine_run() -> Run:
    n = np.arange(3 * N)
    u = GAMMA * np.cos(2 * np.pi * K0 * n / N + PHI)
    return Run("s", 1.0 * N, "sine", u, period=N, transient_periods=2, frequency=float(K0))


G_A = ([0.3, 0.2], [1.0, -0.6, 0.25])     # discrete blocks in ascending powers of z^-1
G_B = ([0.5], [1.0, -0.8])


def lti_cfg(b, a):
    return {"type": "transfer_function", "domain": "discrete", "num": list(b), "den": list(a)}


def simulate_cfg(model: dict) -> np.ndarray:
    config = mc.SimulateConfig.model_validate({"model": model})
    out = simulate_run(from_config.model(config), None, sine_run(), None)
    return out.periods("y")[-1]


def test_two_branch_lpl_matches_seed_002_example_2():
    # Example 2 / Fig. 2: branch 1 = (a1 q + a3 q^3) -> G1+, branch 2 = G2- -> (b1 q + b2 q^2).
    a1, a3, b1, b2 = 1.0, 0.5, 0.7, 0.3
    model = {"type": "lpl", "branches": [
        {"nonlinear": {"type": "polynomial", "coefficients": [0.0, a1, 0.0, a3]}, "after": lti_cfg(*G_A)},
        {"before": lti_cfg(*G_B), "nonlinear": {"type": "polynomial", "coefficients": [0.0, b1, b2]}},
    ]}
    Y = spectrum_of(simulate_cfg(model), 3)
    g1, g2 = dtf(*G_A), dtf(*G_B)
    w = np.exp(1j * PHI)
    expected = np.array([
        b2 * GAMMA**2 / 2 * abs(g2(K0)) ** 2 + a1 * 0,  # branch 1 is odd: no DC
        GAMMA * ((a1 + 0.75 * a3 * GAMMA**2) * g1(K0) + b1 * g2(K0)) * w,
        b2 * GAMMA**2 / 2 * g2(K0) ** 2 * w**2,
        a3 * GAMMA**3 / 4 * g1(3 * K0) * w**3,
    ])
    np.testing.assert_allclose(Y, expected, rtol=0, atol=1e-9 * abs(expected[1]))


def test_wiener_hammerstein_matches_lemma_1():
    # One branch G- -> rho -> G+ (Lemma 1 with N = 1): R = Theorem 1 at amplitude gamma |G-(w0)|
    # and phase phi + angle G-(w0), then each line k scaled by G+(k w0).
    alpha = np.array([1.0, -0.4, 0.6, 0.2])
    model = {"type": "wiener_hammerstein", "first": lti_cfg(*G_B),
             "nonlinear": {"type": "polynomial", "coefficients": [0.0, *alpha]}, "second": lti_cfg(*G_A)}
    Y = spectrum_of(simulate_cfg(model), 4)
    gm, gp = dtf(*G_B)(K0), dtf(*G_A)
    expected = gp(K0 * np.arange(5)) * theorem1(alpha, GAMMA * abs(gm), PHI + np.angle(gm))
    np.testing.assert_allclose(Y, expected, rtol=0, atol=1e-9 * abs(expected[1]))


@pytest.mark.parametrize("kind", ["wiener", "hammerstein"])
def test_wiener_and_hammerstein_are_lemma_1_special_cases(kind):
    alpha = np.array([0.9, 0.3, -0.5])
    nonlinear = {"type": "polynomial", "coefficients": [0.0, *alpha]}
    model = {"type": kind, "linear": lti_cfg(*G_A), "nonlinear": nonlinear}
    Y = spectrum_of(simulate_cfg(model), 3)
    g = dtf(*G_A)
    lines = K0 * np.arange(4)
    if kind == "wiener":   # G- = G, G+ = 1
        expected = theorem1(alpha, GAMMA * abs(g(K0)), PHI + np.angle(g(K0)))
    else:                  # G- = 1, G+ = G
        expected = g(lines) * theorem1(alpha, GAMMA, PHI)
    np.testing.assert_allclose(Y, expected, rtol=0, atol=1e-9 * abs(expected[1]))


def test_hammerstein_output_does_not_depend_on_substeps():
    # A static map of a held input is held too, so the ZOH-exact LTI block gives the same samples
    # whatever the sub-step: equal to rounding.
    config = mc.SimulateConfig.model_validate({"model": {
        "type": "hammerstein", "nonlinear": {"type": "saturation", "lower": -0.5, "upper": 0.6},
        "linear": {"type": "transfer_function", "num": [100.0], "den": [1.0, 20.0, 400.0]}}})
    model = from_config.model(config)
    run = sine_run()
    one = simulate_run(model, None, run, 1).y
    five = simulate_run(model, None, run, 5).y
    np.testing.assert_allclose(five, one, rtol=0, atol=1e-12 * np.max(np.abs(one)))


@pytest.mark.parametrize("b", [0.1, 0.3, 0.6])
def test_backlash_describing_function(b):
    # Describing function of backlash with half width b under A sin(w t) (Gelb & Vander Velde 1968):
    # Re N = 1/2 + (asin(w) + w sqrt(1 - w^2)) / pi with w = 1 - 2b/A, and Im N = -(loop area) /
    # (pi A^2) = -4 b (A - b) / (pi A^2). The sampled play operator is exact at the samples; the
    # output's harmonics decay as 1/k^2, so aliasing onto line 1 of a 2^16-sample period is
    # about 1/N^2 ~ 1e-10: 1e-7 is a wide margin. The second period is analysed (the first
    # starts from y = 0).
    N, A = 2**16, 1.0
    x = A * np.sin(2 * np.pi * np.arange(2 * N) / N)
    y = block(type="backlash", width=2 * b)(x)[N:]
    describing = (2 * np.fft.fft(y)[1] / N) / (-1j * A)
    w = 1 - 2 * b / A
    expected = 0.5 + (np.arcsin(w) + w * np.sqrt(1 - w * w)) / np.pi - 1j * 4 * b * (A - b) / (np.pi * A * A)
    assert describing == pytest.approx(expected, abs=1e-7)
