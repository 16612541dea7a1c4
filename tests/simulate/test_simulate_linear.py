"""Linear plants: the simulated steady state at each excited line equals G(w_k) U(k) to 1e-9.

For a continuous plant driven through a zero-order hold (a DAC), G(w_k) at the sample instants is
the ZOH equivalent G_zoh(z) = (1 - z^-1) Z{G(s)/s}, z = e^{j 2 pi k / N}. The reference here is
computed independently of the simulator (which uses a matrix exponential): from the partial
fractions of G(s)/s = sum_i r_i / (s - p_i) + (direct term), whose z-transform of the sampled step
response is sum_i r_i / (1 - e^{p_i Ts} z^-1). For a discrete plant G(z) is evaluated from its
polynomial coefficients. 1e-9 relative holds because the simulation is exact up to rounding
(about 1e-15 per step, a few thousand steps) and the transient has decayed below 1e-12 before the
analysed period (the decay rates are stated per test).
"""

import numpy as np
import pytest
from scipy.signal import residue

from nlsid.io.run import Run
from nlsid.models.from_config import Plant
from nlsid.models.lti import from_matrices, from_transfer_function, from_zpk
from nlsid.models.mechanical import two_mass_stage
from nlsid.simulate.runs import simulate_run

FS, N = 1000.0, 1000
BINS = np.array([1, 3, 7, 20, 51, 130, 333, 480])


def multisine_run(periods: int, transient: int, seed: int = 1) -> Run:
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, BINS.size)
    n = np.arange(N * periods)
    u = sum(np.cos(2 * np.pi * k * n / N + p) for k, p in zip(BINS, phases))
    return Run("ms", FS, "multisine", u, period=N, transient_periods=transient, excited_bins=BINS)


def measured_frf(run: Run) -> np.ndarray:
    y = np.fft.fft(run.periods("y")[-1])[BINS]
    u = np.fft.fft(run.periods("u")[-1])[BINS]
    return y / u


def zoh_reference(num, den, ts=1 / FS) -> np.ndarray:
    """(1 - z^-1) Z{G(s)/s} from partial fractions (distinct poles)."""
    r, p, _ = residue(num, np.polymul(den, [1.0, 0.0]))
    z = np.exp(2j * np.pi * BINS / N)
    return (1 - 1 / z) * sum(ri / (1 - np.exp(pi * ts) / z) for ri, pi in zip(r, p))


def simulate_linear(ss, periods=3, transient=2, substeps=None) -> Run:
    return simulate_run(Plant(ss, np.zeros(ss.order)), None, multisine_run(periods, transient), substeps)


def test_continuous_resonance_matches_zoh_equivalent():
    # Poles -18 +- 57j: decay e^{-18 t}, after 2 s of transient below 1e-15.
    num, den = [100.0, 3600.0], [1.0, 36.0, 3600.0]
    out = simulate_linear(from_transfer_function(num, den, False, 0.0, "m"))
    np.testing.assert_allclose(measured_frf(out), zoh_reference(num, den), rtol=1e-9)


def test_substeps_do_not_change_a_linear_plant():
    # ZOH propagation over M sub-steps of a held input composes to the one-step ZOH exactly.
    num, den = [100.0, 3600.0], [1.0, 36.0, 3600.0]
    ss = from_transfer_function(num, den, False, 0.0, "m")
    np.testing.assert_allclose(measured_frf(simulate_linear(ss, substeps=7)), zoh_reference(num, den), rtol=1e-9)


def test_zpk_and_state_space_give_the_same_plant():
    # (s + 36) 100 / ((s + 18)^2 + 57^2): the tf of the test above in other forms.
    num, den = [100.0, 3600.0], [1.0, 36.0, 3600.0]
    pole_im = np.sqrt(3600.0 - 18.0**2)
    zpk = from_zpk([-36.0], [[-18.0, float(pole_im)]], 100.0, False, 0.0, "m")
    np.testing.assert_allclose(measured_frf(simulate_linear(zpk)), zoh_reference(num, den), rtol=1e-9)
    ss = from_matrices([[0.0, 1.0], [-3600.0, -36.0]], [0.0, 1.0], [3600.0 * 100 / 100, 100.0], 0.0, False, 0.0, "m")
    np.testing.assert_allclose(measured_frf(simulate_linear(ss)), zoh_reference(num, den), rtol=1e-9)


def test_biproper_plant_direct_feedthrough():
    # G(s) = (s + 50) / (s + 10) = 1 + 40 / (s + 10): pole -10, e^{-10 * 3} ~ 1e-13 after 3 s.
    num, den = [1.0, 50.0], [1.0, 10.0]
    out = simulate_linear(from_transfer_function(num, den, False, 0.0, "m"), periods=4, transient=3)
    np.testing.assert_allclose(measured_frf(out), zoh_reference(num, den), rtol=1e-9)


def test_discrete_plant_matches_polynomial_evaluation():
    # The book's G1 = 1 / (1 - 0.5 z^-1 + 0.9 z^-2) (digest: Project 4); |poles| = sqrt(0.9),
    # 0.9^(2000/2) ~ 1e-46 after the two transient periods.
    b, a = [1.0], [1.0, -0.5, 0.9]
    out = simulate_linear(from_transfer_function(b, a, True, 0.0, "m"))
    zinv = np.exp(-2j * np.pi * BINS / N)
    expected = np.polyval(b[::-1], zinv) / np.polyval(a[::-1], zinv)
    np.testing.assert_allclose(measured_frf(out), expected, rtol=1e-9)


def test_dead_time_is_a_pure_delay_of_whole_samples():
    # A dead time of d samples multiplies the response by z^-d = e^{-j 2 pi k d / N}.
    num, den = [100.0, 3600.0], [1.0, 36.0, 3600.0]
    d = 17
    out = simulate_linear(from_transfer_function(num, den, False, d / FS, "m"))
    expected = zoh_reference(num, den) * np.exp(-2j * np.pi * BINS * d / N)
    np.testing.assert_allclose(measured_frf(out), expected, rtol=1e-9)


def test_two_mass_stage_matches_its_transfer_function():
    # Force -> load velocity of the two-mass stage with ground dampers, derived by hand from the
    # equations of motion in nlsid.models.mechanical: P_load / F = (c s + k) / Den(s) with
    # Den = (m1 s^2 + (c + c1) s + k)(m2 s^2 + (c + c2) s + k) - (c s + k)^2, which has a root at
    # s = 0 (the free rigid body); the velocity s P_load / F = (c s + k) / (Den(s) / s) is stable.
    m1, m2, k, c, c1, c2, gain = 1.0, 0.5, 2.0e4, 40.0, 30.0, 20.0, 5.0
    mech = two_mass_stage(m1, m2, k, c, c1, c2, gain, "velocity", "load")
    num = gain * np.array([c, k])
    full = np.polysub(np.polymul([m1, c + c1, k], [m2, c + c2, k]), np.polymul([c, k], [c, k]))
    assert abs(full[-1]) < 1e-9 * abs(full[-2])
    den = full[:-1]
    slowest = np.max(np.roots(den).real)
    assert slowest * 4.0 < -np.log(1e15)  # transient decayed below 1e-15 after 4 periods (4 s)
    run = multisine_run(5, 4)
    out = simulate_run(Plant(mech.ss, mech.x0), None, run, None)
    np.testing.assert_allclose(measured_frf(out), zoh_reference(num, den), rtol=1e-9)


@pytest.mark.parametrize("num, den", [([1.0, 0.0, 0.0], [1.0, 1.0]), ([1.0, 2.0], [3.0])])
def test_improper_transfer_function_is_refused(num, den):
    from nlsid.errors import InputError

    with pytest.raises(InputError, match="improper"):
        from_transfer_function(num, den, False, 0.0, "model")
