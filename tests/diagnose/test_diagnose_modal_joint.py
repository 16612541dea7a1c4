"""A nonlinear joint in modal form: a cubic spring on the modal coordinate of one mode of a six-mode
structure (``modal_joint``, nlsid/diagnose/hypotheses/modal_joint.py), and the force ``points`` of
``nonlinear_feedback`` it is written with.

The structure (tests/generators/modal_cases.py): six modes at 7.5-55 Hz, damping 2-3 %, modal
superposition stepped exactly (ZOH) but for the mode at 21 Hz, whose modal coordinate carries a
softening cubic K3 q^3 (Runge-Kutta, 8 steps per sample, checked against 16). K3 shifts that mode
by 3/2 K3 sigma^2 / w^2 = -1.5 % at the highest level (sigma the modal coordinate's rms there,
1.33e-4). Multisines at four levels (rms 0.25 .. 1) x two realizations, coloured noise of std
NOISE (-57 dB of the highest level's output, -45 dB of the lowest's) and a 50 Hz mains line on y;
held out: two further levels (0.375, 0.875) the fits never see.

The user's model is the truth's linear part 3 % off (each mode's w^2, 2 zeta w and output
coefficient by +-3 %), given as a discrete state space (its ZOH equivalent in random coordinates),
as a fit from the BLA would give it in no particular basis.

Measured when written: the mode at 20.98 Hz found moving by -1.85 +- 0.32 % (six levels: the
held-out ones are in the BLA comparison too), k3 started at -1.04e10 +- 0.07e10 from the frequency
shift and refined to -1.001e10 (truth -1e10), 1.2 dB above the floor on the held-out levels
(seeds 21, 31: -1.002e10 and -1.001e10, 1.2 and 2.0 dB); 5 s for the diagnosis.
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import modal_cases as cases
from generators.exact_zoh import zoh
from nlsid.diagnose.diagnosis import diagnose
from nlsid.diagnose.hypotheses.modal_joint import continuous_model, modal_state_space, modes_of
from nlsid.diagnose.simulation import ModelRunner
from nlsid.errors import InputError
from nlsid.models.lti import StateSpace

K3 = -1.0e10
NOISE, LEVELS, HELD_OUT = cases.NOISE, cases.LEVELS, cases.HELD_OUT


def _truth_config() -> dict:
    """The truth in the config language: the modal blocks with the cubic at the moving mode's point."""
    A, B, C = cases.blocks()
    force, position = np.zeros(12), np.zeros(12)
    force[2 * cases.MOVING + 1] = position[2 * cases.MOVING] = 1.0
    return {"model": {"type": "nonlinear_feedback",
                      "linear": {"type": "state_space", "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": 0.0},
                      "points": {"joint": {"force": force.tolist(), "position": position.tolist()}},
                      "nonlinearities": [{"type": "cubic_stiffness", "k3": K3, "at": "joint"}]}}


def _outputs(U: np.ndarray) -> np.ndarray:
    return cases.response(U, K3, 8)


def test_the_modal_form_has_the_model_s_response():
    """Four modes and a real pole in random coordinates, to modal blocks and back: the same
    frequency response (scipy's, of the original matrices) to rounding."""
    rng = np.random.default_rng(3)
    poles = [complex(-2 * np.pi * f * 0.03, 2 * np.pi * f * np.sqrt(1 - 0.03**2)) for f in (3.0, 11.0, 17.0, 40.0)]
    n = 9
    A = np.zeros((n, n))
    for i, p in enumerate(poles):
        A[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[p.real, p.imag], [-p.imag, p.real]]
    A[8, 8] = -30.0
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A, B, C = Q.T @ A @ Q, rng.standard_normal(n), rng.standard_normal(n)
    modes = modes_of(StateSpace(A, B, C, 0.0, False))
    expected_hz = sorted([3.0, 11.0, 17.0, 40.0, 30 / (2 * np.pi)])  # |lambda| / 2 pi, the real pole's too
    assert [m.frequency_hz for m in modes] == pytest.approx(expected_hz, rel=1e-9)
    assert [m.pair for m in modes] == [True, False, True, True, True]
    config = modal_state_space(modes)
    s = 2j * np.pi * np.linspace(0.5, 60, 200)
    expected = _frequency_response(A, B, C, s)
    got = _frequency_response(np.array(config["A"]), np.array(config["B"]), np.array(config["C"]), s)
    assert np.max(np.abs(got - expected) / np.abs(expected)) < 1e-9


def test_a_feedthrough_beyond_rounding_is_not_dropped():
    """A discrete model's D is set to 0 where it is a fit's rounding (1e-7 of the peak), kept where
    it is the output's own (an acceleration's: 30 % of the peak; the ZOH passes D unchanged)."""
    A, B, C = cases.blocks()
    Phi, Gamma = zoh(A, B, 1 / cases.FS)
    peak = np.max(np.abs(_frequency_response(Phi, Gamma, C, np.exp(2j * np.pi * np.linspace(0, 0.5, 4096)))))
    small = continuous_model(StateSpace(Phi, Gamma, C, 1e-7 * peak, True, 0.0, cases.FS), cases.FS)
    assert isinstance(small[0], StateSpace) and small[0].D == 0 and "set to 0" in small[1][0]
    large, notes = continuous_model(StateSpace(Phi, Gamma, C, 0.3 * peak, True, 0.0, cases.FS), cases.FS)
    assert isinstance(large, StateSpace) and not large.discrete and large.D == 0.3 * peak
    assert "acceleration output" in notes[0] and "30.0% of the peak response" in notes[0], notes


def _frequency_response(A: np.ndarray, B: np.ndarray, C: np.ndarray, s: np.ndarray) -> np.ndarray:
    """C (s I - A)^-1 B at every s."""
    return np.array([C @ np.linalg.solve(sk * np.eye(A.shape[0]) - A, B) for sk in s])


def test_a_force_point_in_the_state_space_simulates_the_modal_cubic():
    """The truth written with ``points`` runs in nlsid as the independent Runge-Kutta truth does:
    the difference is nlsid's sub-step error, of second order (the force held over each sub-step:
    measured 1.3e-7, 3.2e-8, 8.0e-9 rms at the highest level for 10, 20, 40 sub-steps), so it falls
    by 4 +- 1 per halving and is below a hundredth of the noise at 40 sub-steps."""
    runs = cases.recording(21, (0.25, 1.0), 1, lambda U: np.zeros(U.shape), 0.0)
    U = np.stack([run.u for run in runs])
    finer = cases.response(U, K3, 16)
    fine = cases.response(U[:, :cases.N], K3, 8)  # the Runge-Kutta error, checked by halving the step
    assert np.max(np.abs(fine - finer[:, :cases.N])) < 1e-2 * NOISE  # its power 1e-4 of the noise's
    errors = []
    for substeps in (10, 20, 40):
        data = {**_truth_config(), "simulation": {"substeps": substeps}}
        simulated = ModelRunner.from_data(data, "truth.yaml").simulate_each(runs)
        errors.append(max(float(np.sqrt(np.mean((y - truth) ** 2))) for y, truth in zip(simulated, finer)))
    assert 3 < errors[0] / errors[1] < 5 and 3 < errors[1] / errors[2] < 5, errors
    assert errors[2] < 1e-2 * NOISE, errors


def _transfer_function(model: dict) -> None:
    model["linear"] = {"type": "transfer_function", "num": [1.0], "den": [1.0, 1.0, 1.0]}


def _short_column(model: dict) -> None:
    model["points"]["joint"]["force"] = [0.0, 1.0]


def _taken_name(model: dict) -> None:
    model["points"] = {"plant": model["points"]["joint"]}


@pytest.mark.parametrize("change, where", [(_transfer_function, "model.points"),
                                           (_short_column, "model.points.joint.force"),
                                           (_taken_name, "model.points.plant")])
def test_force_points_refused_where_they_cannot_be(change, where):
    data = _truth_config()
    change(data["model"])
    with pytest.raises(InputError) as error:
        ModelRunner.from_data(data, "model.yaml")
    assert f"{where}:" in str(error.value), error.value


def test_a_cubic_on_one_mode_is_named_at_that_mode():
    runs = cases.recording(11, LEVELS, 2, _outputs, NOISE)
    held_out = cases.recording(12, HELD_OUT, 1, _outputs, NOISE, prefix="v")
    steady = runs[0].y[cases.N:].reshape(cases.PERIODS, cases.N).mean(axis=0)
    spectrum = np.abs(np.fft.rfft(steady))
    mains = int(50.0 * cases.N / cases.FS)  # an even line, not excited; its even neighbours hold noise only
    neighbours = [k for k in range(mains - 20, mains + 21, 2) if k != mains]
    assert spectrum[mains] > 5 * np.median(spectrum[neighbours])  # the mains line stands out of the noise
    result = diagnose(cases.user_model(), "model.yaml", runs, "recording.h5", validate_on=held_out, yardstick=False)
    assert [o.hypothesis.name for o in result.chain] == ["modal_joint"], result.headline()
    est = result.winner.estimate
    assert est.values["k3"] == pytest.approx(K3, rel=0.10), (est.values["k3"], est.std["k3"])
    model = result.final.extended["model"]
    A = np.array(model["linear"]["A"])
    f_joint = np.sqrt(-A[1, 0]) / (2 * np.pi)  # the block with the cubic is the moving mode's
    assert f_joint == pytest.approx(cases.FREQUENCIES_HZ[cases.MOVING], rel=0.005), f_joint
    assert model["nonlinearities"][0]["at"] == "mode" and model["points"]["mode"]["position"][0] == 1.0
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()
    outcomes = {o.hypothesis.name: o for o in result.outcomes}
    assert "mode near 20.9" in outcomes["modal_joint"].estimate.note  # the BLA's moving mode, at the truth's 21 Hz
    assert outcomes["modal_damping"].score is None  # the spring leaves the mode's damping: not fitted
    assert "damping significantly" in outcomes["modal_damping"].reason, outcomes["modal_damping"].reason
