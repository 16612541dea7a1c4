"""A cubic joint around a transfer function model (joint_feedback, nlsid/diagnose/hypotheses/joint.py):
the transfer function from force to the motor's position or velocity read as the two-mass stage it
is, and the joint's estimate and refinement tested directly (no whole diagnosis).

The stage and its record are tests/diagnose/test_joint.py's (motor 1 kg, load 0.5 kg, coupling 2e4
N/m and 4 N s/m, ground dampers 20 and 5 N s/m, gain 40 N per unit of u, the motor's velocity
recorded; k3 = 4e8 N/m^3 in the joint, RK4 in tests/generators/independent_forces.py checked by
halving; sensor offset and coloured noise at -50 dB), its two runs at the higher level. The user's
model is the stage's linear transfer function, computed here by scipy's ss2tf from Newton's laws
written here. In units of u (gain 1) the truth is the masses, dampers and stiffnesses over 40 and
k3 = 1e7 per unit of deflection cubed.

Measured when written: the start k3 = 2.5e6 (first order), refined to 9.985e6 +- 1.3e4, the
mechanics within 0.1 %, the steady-state error 0.993 times the noise; with the four runs 9.977e6
+- 1.0e4. Around the same transfer function the modal joint has no modal form for a free stage
(its double pole at s = 0 is defective), and the cubic feedback acts on the motor, not the joint.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import ss2tf

from diagnose.test_joint import K3, STAGE, _response
from generators import effect_cases as cases
from nlsid.diagnose.diagnosis import refine
from nlsid.diagnose.hypotheses import by_name
from nlsid.diagnose.hypotheses.base import Context
from nlsid.diagnose.hypotheses.joint import MECHANICS, two_mass_of
from nlsid.diagnose.simulation import ModelRunner, steady_mean


def _transfer_function(stage: dict) -> dict:
    """The stage's transfer function from u to the motor's ``output``: m1 p1'' = gain u - c1 v1 -
    k (p1 - p2) - c (v1 - v2), m2 p2'' = -c2 v2 + k (p1 - p2) + c (v1 - v2), by ss2tf; coefficients
    of its rounding (below 1e-9 of the largest) set to 0."""
    m1, m2, k, c, c1, c2 = (stage.get(key, 0.0) for key in MECHANICS)
    A = np.array([[0, 1, 0, 0], [-k / m1, -(c + c1) / m1, k / m1, c / m1], [0, 0, 0, 1],
                  [k / m2, c / m2, -k / m2, -(c + c2) / m2]])
    C = np.array([[1.0, 0, 0, 0]]) if stage.get("output", "position") == "position" else np.array([[0, 1.0, 0, 0]])
    num, den = ss2tf(A, np.array([[0], [stage["gain"] / m1], [0], [0]]), C, np.zeros((1, 1)))
    num = num[0]
    num[np.abs(num) < 1e-9 * np.abs(num).max()] = 0.0
    den[np.abs(den) < 1e-9 * np.abs(den).max()] = 0.0
    return {"type": "transfer_function", "num": [float(v) for v in num], "den": [float(v) for v in den]}


@pytest.mark.parametrize("stage", [
    {**STAGE, "output": "position"},
    STAGE,
    {"motor_mass": 2.0, "load_mass": 0.7, "stiffness": 3e4, "damping": 10.0, "gain": 1.0},  # free: s^2 in den
    {"motor_mass": 1.0, "load_mass": 3.0, "stiffness": 1e3, "damping": 1.0, "motor_damping": 2.0, "gain": 1.0,
     "output": "velocity"},
])
def test_the_transfer_function_is_read_back_as_its_two_mass_stage(stage):
    """The stage's parameters in units of u (over its gain) from its transfer function, to 1e-7."""
    model = _transfer_function(stage)
    found = two_mass_of(model["num"], model["den"])
    assert not isinstance(found, str), found
    got, error = found
    assert error < 1e-9 and got["output"] == stage.get("output", "position") and got["output_at"] == "motor"
    for key in MECHANICS:
        assert got[key] == pytest.approx(stage.get(key, 0.0) / stage["gain"], rel=1e-7, abs=1e-12), key


@pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")  # cont2discrete on a num with a zero s^n term
def test_a_discrete_transfer_function_is_read_through_its_continuous_equivalent():
    """The motor velocity's ZOH discretisation at 1024 Hz (scipy's cont2discrete), written with its
    fs as ``nlsid fit --domain z`` writes one: the hypothesis applies, and the stage it extends has
    the parameters in units of u to 1e-6 (the ZOH inverse's rounding); without fs it says why."""
    from scipy.signal import cont2discrete

    model = _transfer_function(STAGE)
    b, a, _ = cont2discrete((model["num"], model["den"]), 1 / cases.FS, method="zoh")
    discrete = {"type": "transfer_function", "domain": "discrete", "fs": cases.FS,
                "num": [float(v) for v in np.ravel(b)], "den": [float(v) for v in a]}
    hypothesis = by_name("joint_feedback")
    assert hypothesis.applies(ModelRunner.from_data({"model": discrete}, "model.yaml")) is None
    stage = hypothesis.extend({"model": discrete}, {"k3": 1.0})["model"]
    for key in MECHANICS:
        assert stage[key] == pytest.approx(STAGE[key] / STAGE["gain"], rel=1e-6), key
    assert "model.fs" in hypothesis.applies(ModelRunner.from_data({"model": {**discrete, "fs": None}}, "m.yaml"))


def test_the_load_transfer_function_is_refused_with_the_reason():
    """The load's numerator (c s + k) does not fix the masses' split: not applied, said why."""
    model = _transfer_function({**STAGE, "output": "position"})
    assert "split" in two_mass_of([4.0 * 40, 2e4 * 40], model["den"])


def test_a_cubic_joint_around_the_stage_transfer_function_reaches_the_noise_floor():
    """k3 within 4 of its standard errors and 10 % of the truth, the masses and the coupling
    stiffness within 1 %, and the steady-state error within 1 dB of the noise (the noise alone
    gives its std within about 2 % on these 4096 samples)."""
    runs = cases.recording(41, _response)[2:]
    data = {"model": _transfer_function(STAGE)}
    runner = ModelRunner.from_data(data, "model.yaml")
    hypothesis = by_name("joint_feedback")
    assert hypothesis.applies(runner) is None
    residuals = [steady_mean(r, r.y) - steady_mean(r, y) for r, y in zip(runs, runner.simulate_each(runs))]
    estimate = hypothesis.estimate(Context(runner, runs, residuals, [{} for _ in runs]))
    refined, config, *_ = refine(hypothesis, data, estimate, runs, "model.yaml", data)
    k3, std = refined.values["k3"], refined.std["k3"]
    truth = K3 / STAGE["gain"]
    assert cases.within(k3, truth, std) and k3 == pytest.approx(truth, rel=0.10), (k3, std)
    model = config["model"]
    assert model["type"] == "two_mass_stage" and model["nonlinearities"][0]["at"] == "joint"
    for key in ("motor_mass", "load_mass", "stiffness"):
        assert model[key] == pytest.approx(STAGE[key] / STAGE["gain"], rel=0.01), (key, model[key])
    simulated = ModelRunner.from_data(config, "model.yaml").simulate_each(runs)
    error = np.concatenate([(r.y - y)[r.period * r.transient_periods:] for r, y in zip(runs, simulated)])
    assert np.sqrt(np.mean(error**2)) < cases.NOISE * 10 ** (1 / 20)
