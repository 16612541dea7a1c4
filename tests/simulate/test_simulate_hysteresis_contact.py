"""The Bouc-Wen force, the end stops and a cubic spring at the joint of a two-mass stage, simulated
by nlsid against the independent Runge-Kutta records of tests/generators/independent_forces.py.

The reference's own error is measured by halving its step (RK4: 1/16 per halving in smooth parts,
1/4 at the kinks of |v| and |z|; the contact instants located). nlsid holds each force over a
sub-step (nlsid.models.forces), by steps of second order (the end stops' with the contact's
share of the sub-step), so 4x finer sub-steps divide the error by about 16 (asserted > 10), and at
64 sub-steps it is below 1 % of the force's effect on the output.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from generators import independent_forces
from nlsid.diagnose.simulation import ModelRunner
from nlsid.errors import InputError
from nlsid.io.run import Run

FS = 1000.0
MSD = {"type": "mass_spring_damper", "mass": 0.5, "damping": 6.0, "stiffness": 1.0e4, "gain": 1.0}
STAGE = {"type": "two_mass_stage", "motor_mass": 1.0, "load_mass": 0.5, "stiffness": 2.0e4, "damping": 4.0,
         "motor_damping": 20.0, "load_damping": 5.0, "gain": 1.0, "output_at": "load"}
CASES = {
    "bouc_wen": (dict(MSD, nonlinearities=[{"type": "bouc_wen", "k": 1.0e4, "beta": 3.0e3, "gamma": 1.0e3}]),
                 independent_forces.bouc_wen_response, 10.0),
    "end_stop": (dict(MSD, nonlinearities=[{"type": "end_stop", "upper": 2e-4, "lower": -3e-4, "stiffness": 2e5,
                                            "damping": 40.0}]), independent_forces.end_stop_response, 10.0),
    "joint": (dict(STAGE, nonlinearities=[{"type": "cubic_stiffness", "k3": 3e11, "at": "joint"}]),
              independent_forces.joint_response, 10.0),
}


def _input() -> np.ndarray:
    rng = np.random.default_rng(1)
    return 3.0 * lfilter([0.2], [1.0, -0.8], rng.standard_normal(2000))


def _simulate(model: dict, u: np.ndarray, substeps: int) -> np.ndarray:
    runner = ModelRunner.from_data({"model": model, "simulation": {"substeps": substeps}}, "model.yaml")
    return runner.simulate(Run("r", FS, "arbitrary", u)).y


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


@pytest.mark.parametrize("case", list(CASES))
def test_the_force_converges_to_the_independent_record(case):
    model, reference, ratio = CASES[case]
    u = _input()
    fine, finer = (reference(model, u[None], FS, s)[0] for s in (32, 64))
    linear = _simulate(dict(model, nonlinearities=[]), u, 1)
    effect = _rms(finer - linear)
    assert _rms(fine - finer) < 1e-4 * effect  # the reference's own error, far below what is compared
    errors = [_rms(_simulate(model, u, s) - finer) for s in (4, 16, 64)]
    assert errors[0] / errors[1] > ratio and errors[1] / errors[2] > ratio, errors
    assert errors[2] < 1e-2 * effect, (errors, effect)


def test_a_bouc_wen_force_settles_on_its_bound_under_a_long_stroke():
    """Under a slow ramp (a monotone stroke much longer than the bound) z tends to
    (A / (beta + gamma))^(1/n), so the force on a free mass driven by a constant force is k times
    it: the mass is held by the spring alone beyond it (m v' = F0 - c v - k z): final velocity
    (F0 - k zmax) / c."""
    k, a, beta, gamma, n = 50.0, 1.0, 30.0, 10.0, 2.0
    bound = (a / (beta + gamma)) ** (1 / n)
    model = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "gain": 1.0, "output": "velocity",
             "nonlinearities": [{"type": "bouc_wen", "k": k, "A": a, "beta": beta, "gamma": gamma, "n": n}]}
    y = _simulate(model, np.full(20000, 10.0), 4)
    assert y[-1] == pytest.approx((10.0 - k * bound) / 20.0, rel=1e-6)


@pytest.mark.parametrize("force, message", [
    ({"type": "bouc_wen", "k": 1.0, "beta": 1.0, "gamma": 2.0}, "-beta < gamma <= beta"),
    ({"type": "bouc_wen", "k": 1.0, "beta": 1.0, "gamma": -1.0}, "-beta < gamma <= beta"),
    ({"type": "bouc_wen", "k": 1.0, "beta": 1.0, "n": 0.5}, "must be >= 1.0, got 0.5"),
    ({"type": "end_stop", "stiffness": 1.0}, "give upper, lower or both"),
    ({"type": "end_stop", "stiffness": 1.0, "upper": -1.0, "lower": 1.0}, "lower < upper"),
])
def test_bad_force_keys_are_refused_with_their_reason(force, message):
    with pytest.raises(InputError, match=message):
        ModelRunner.from_data({"model": dict(MSD, nonlinearities=[force])}, "model.yaml")


def test_a_joint_force_needs_a_two_mass_stage():
    with pytest.raises(InputError, match="expected one of mass, got 'joint'"):
        ModelRunner.from_data({"model": dict(MSD, nonlinearities=[{"type": "cubic_stiffness", "k3": 1.0, "at": "joint"}])},
                              "model.yaml")
