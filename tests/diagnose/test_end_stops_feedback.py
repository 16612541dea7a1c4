"""End stops fed back around a transfer function fitted in the z domain (end_stops_feedback), its
estimate and refinement tested directly (no whole diagnosis).

The record is tests/diagnose/test_transfer_function_forces.py's: the mass-spring-damper of
tests/generators/effect_cases.py (1e4 / (s^2 + 20 s + 4e4) from u to position) with stops at +0.5
m and -0.6 m (4e5 N/m, 200 N s/m: ks = 40 and cs = 0.02 in units of u), integrated by RK4 with
the contact changes located (tests/generators/independent_forces.py) and checked by halving the
step, recorded with a sensor offset of 2e-3 and coloured noise of std 1e-3. The user's model is a
2/2 in z fitted to the measured BLA by Sanathanan-Koerner (b0 = 0). Biased by the stops, its
numerator's zero sits at z = 0.28, and its continuous equivalent is (6.2 s + 7128) / D(s), a
zero at 182 Hz.

Measured when written, seed 45: around G(z) itself (the force held over whole samples, the
velocity a backward difference) the diagnosis named the stops 34.4 dB above the noise floor;
with the equivalent's leading term dropped (relative degree 2), 0.8 dB above it (as from a
continuous fit), ks 40.02 +- 0.019, cs 0.02000 +- 9e-6, the edges as recorded 0.5020 and
-0.5980, the steady-state error 1.007 (estimation) and 1.012 (held-out record) times the noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from diagnose.test_transfer_function_forces import STOPS, _checked, _fitted_discrete, _stops
from generators import effect_cases as cases
from nlsid.diagnose.diagnosis import refine
from nlsid.diagnose.hypotheses import by_name
from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.hypotheses.velocity_feedback import degree_two
from nlsid.diagnose.simulation import ModelRunner, steady_mean


def test_dropping_the_leading_term_is_the_least_squares_projection_on_the_same_poles():
    """(a s + b) / D -> b / D: against an independent least-squares fit of c / D to G at random
    frequencies (any set: a s / D is in quadrature with 1 / D), c equals b to rounding."""
    rng = np.random.default_rng(5)
    w = rng.uniform(1.0, 3000.0, 40)
    num, den = [6.2, 7128.0], [1.0, 28.6, 41910.0]
    lead, reduced = degree_two({"num": num, "den": den})
    G = np.polyval(num, 1j * w) / np.polyval(den, 1j * w)
    basis = 1.0 / np.polyval(den, 1j * w)
    c = np.linalg.lstsq(np.concatenate([basis.real, basis.imag])[:, None], np.concatenate([G.real, G.imag]),
                        rcond=None)[0][0]
    assert lead == 6.2 and reduced["den"] == den
    assert reduced["num"] == [pytest.approx(c, rel=1e-12)]


def _steady_error(config: dict, runs) -> float:
    """The rms of the recorded minus simulated output after the transient period, over the runs."""
    simulated = ModelRunner.from_data(config, "model.yaml").simulate_each(runs)
    return float(np.sqrt(np.mean(np.concatenate([(r.y - y)[r.period * r.transient_periods:]
                                                 for r, y in zip(runs, simulated)]) ** 2)))


def test_end_stops_around_a_z_domain_fit_reach_the_noise_floor():
    """From the z-domain fit the refined feedback recovers ks and cs within 4 standard errors, the
    edges as recorded (edge + sensor offset) within 0.5 % (4 times their standard error of 0.12 %),
    and errs within 1 dB of the noise after the transient: the noise alone gives its std within
    about 2 % there (thousands of effectively independent samples; the 12 fitted parameters lower
    it by about 12 / 2N, under 0.1 %), the route around G(z) 34 dB above it."""
    runs = cases.recording(45, _checked(_stops))
    data = _fitted_discrete(runs)
    runner = ModelRunner.from_data(data, "model.yaml")
    residuals = [steady_mean(r, r.y) - steady_mean(r, y) for r, y in zip(runs, runner.simulate_each(runs))]
    hypothesis = by_name("end_stops_feedback")
    estimate = hypothesis.estimate(Context(runner, runs, residuals, [{} for _ in runs]))
    assert "leading term" in estimate.note and estimate.lti["domain"] == "continuous", estimate.note
    refined, config, *_ = refine(hypothesis, data, estimate, runs, "model.yaml", data)
    values, std = refined.values, refined.std
    assert cases.within(values["ks"], STOPS["stiffness"] / cases.GAIN, std["ks"]), (values, std)
    assert cases.within(values["cs"], STOPS["damping"] / cases.GAIN, std["cs"]), (values, std)
    assert values["upper_seen"] == pytest.approx(STOPS["upper"] + cases.OFFSET, rel=0.005), values
    assert values["lower_seen"] == pytest.approx(STOPS["lower"] + cases.OFFSET, rel=0.005), values
    assert _steady_error(config, runs) < cases.NOISE * 10 ** (1 / 20), _steady_error(config, runs)
