"""The modal form of a structure with an acceleration output (nlsid/diagnose/hypotheses/modal_joint.py,
"Acceleration output"): force in, accelerations out, a transfer function of relative degree 0.

The structure, written here independently of nlsid: three modes, q_i'' + 2 zeta_i w_i q_i' +
w_i^2 q_i = b_i u (b_i the modal participation of the force), a cubic spring K3 q^3 on the
coordinate of mode MOVING, and the output y = sum c_i q_i''. Its transfer function is
G(s) = sum c_i b_i s^2 / (s^2 + 2 zeta_i w_i s + w_i^2), D = sum c_i b_i. The user's model is its
linear part as a continuous state space in random orthogonal coordinates (or its exact ZOH
equivalent, a discrete one).

In the modal form's coordinate q~ = q / b (unit participation) the cubic is K3 b^2 q~^3 and the
mode's acceleration participation a2 = c b: the force point's feedthrough -beta / w^2 must be
that (beta = -w^2 c b).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import dlsim

from generators.exact_zoh import zoh
from nlsid.diagnose.hypotheses.modal_joint import (
    MODAL_JOINT, acceleration_share, continuous_model, modal_state_space, modes_of)
from nlsid.diagnose.nuisances import free_nuisances
from nlsid.diagnose.simulation import ModelRunner
from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.lti import StateSpace
from nlsid.simulate.engine import with_feedthrough

FS, N = 256.0, 384
FREQUENCIES_HZ = np.array([6.0, 15.0, 33.0])
DAMPING = np.array([0.03, 0.02, 0.025])
PARTICIPATION = np.array([1.0, 0.8, 1.2])  # b_i
SHAPE = np.array([1.0, -0.8, 0.6])  # c_i
MOVING = 1
K3 = -8.0e9  # softening: the cubic is 25 % of the output's rms at the input below (white, rms 1)
K3_2 = -2.0e11  # a second cubic, on the mode at 33 Hz


def _truth_blocks() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(A, B, C, D) of the linear structure, states (q_i, q_i'), output sum c_i q_i''."""
    w, z = 2 * np.pi * FREQUENCIES_HZ, DAMPING
    n = 2 * w.size
    A, B, C = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    for i in range(w.size):
        j = 2 * i
        A[j, j + 1], A[j + 1, j], A[j + 1, j + 1] = 1.0, -w[i] ** 2, -2 * z[i] * w[i]
        B[j + 1] = PARTICIPATION[i]
        C[j], C[j + 1] = -w[i] ** 2 * SHAPE[i], -2 * z[i] * w[i] * SHAPE[i]
    return A, B, C, float(SHAPE @ PARTICIPATION)


def _user_model(discrete: bool) -> StateSpace:
    A, B, C, D = _truth_blocks()
    Q, _ = np.linalg.qr(np.random.default_rng(4).standard_normal(A.shape))
    A, B, C = Q.T @ A @ Q, Q.T @ B, C @ Q
    if discrete:
        Phi, Gamma = zoh(A, B, 1 / FS)
        return StateSpace(Phi, Gamma, C, D, True, 0.0, FS)
    return StateSpace(A, B, C, D, False)


def _transfer_function(s: np.ndarray) -> np.ndarray:
    """G(s) of the structure from its modal parameters (module docstring)."""
    w, z = 2 * np.pi * FREQUENCIES_HZ, DAMPING
    return sum(c * b * s**2 / (s**2 + 2 * zi * wi * s + wi**2) for c, b, zi, wi in zip(SHAPE, PARTICIPATION, z, w))


def _modal_form(discrete: bool) -> dict:
    """The modal state space the hypothesis writes (the moving mode first)."""
    ss, notes = continuous_model(_user_model(discrete), FS)
    assert isinstance(ss, StateSpace) and "acceleration output" in notes[0], notes
    modes = modes_of(ss)
    moving = min(modes, key=lambda m: abs(m.frequency_hz - FREQUENCIES_HZ[MOVING]))
    return modal_state_space([moving] + [m for m in modes if m is not moving], ss.D)


def _response(linear: dict, s: np.ndarray) -> np.ndarray:
    A, B, C = (np.array(linear[key]) for key in "ABC")
    return np.array([C @ np.linalg.solve(sk * np.eye(A.shape[0]) - A, B) for sk in s]) + linear["D"]


@pytest.mark.parametrize("discrete", [False, True])
def test_the_modal_form_with_feedthrough_has_the_structure_s_response(discrete):
    """The modal blocks and D of the user's model (continuous, or its ZOH equivalent through the
    ZOH inverse) have the structure's transfer function, feedthrough included, to 1e-9; the
    moving mode's acceleration participation is c b."""
    linear = _modal_form(discrete)
    s = 2j * np.pi * np.concatenate([np.linspace(0.0, 120.0, 241), FREQUENCIES_HZ])
    expected = _transfer_function(s)
    assert np.max(np.abs(_response(linear, s) - expected)) < 1e-9 * np.max(np.abs(expected))
    assert linear["D"] == pytest.approx(SHAPE @ PARTICIPATION, rel=1e-9)
    assert acceleration_share(linear) == pytest.approx(SHAPE[MOVING] * PARTICIPATION[MOVING], rel=1e-9)


def _runge_kutta_mode(u: np.ndarray, substeps: int, i: int, k3: float) -> np.ndarray:
    """c q'' of mode i with a cubic, q'' = b u - 2 zeta w q' - w^2 q - k3 q^3, by RK4 with u held
    over each sample, read at the sample instants (u[k] the held value there)."""
    w, z, b, c = 2 * np.pi * FREQUENCIES_HZ[i], DAMPING[i], PARTICIPATION[i], SHAPE[i]
    h = 1 / (FS * substeps)

    def rates(p, v, force):
        return v, force - 2 * z * w * v - w * w * p - k3 * p**3

    p = v = 0.0
    y = np.zeros(u.size)
    for k in range(u.size):
        y[k] = c * rates(p, v, b * u[k])[1]
        for _ in range(substeps):
            k1p, k1v = rates(p, v, b * u[k])
            k2p, k2v = rates(p + h / 2 * k1p, v + h / 2 * k1v, b * u[k])
            k3p, k3v = rates(p + h / 2 * k2p, v + h / 2 * k2v, b * u[k])
            k4p, k4v = rates(p + h * k3p, v + h * k3v, b * u[k])
            p, v = p + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p), v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return y


def _truth(u: np.ndarray, substeps: int, joints: dict[int, float]) -> np.ndarray:
    """The structure's acceleration output with the cubics ``joints`` (mode -> k3): the linear
    modes by their exact ZOH (scipy's dlsim), those with a cubic by RK4."""
    w, z = 2 * np.pi * FREQUENCIES_HZ, DAMPING
    y = sum(_runge_kutta_mode(u, substeps, i, k3) for i, k3 in joints.items())
    for i in (i for i in range(w.size) if i not in joints):
        a = np.array([[0.0, 1.0], [-w[i] ** 2, -2 * z[i] * w[i]]])
        Phi, Gamma = zoh(a, np.array([0.0, PARTICIPATION[i]]), 1 / FS)
        C = SHAPE[i] * a[1:]  # c q'' = c (-w^2 q - 2 zeta w q') + c b u
        _, out, _ = dlsim((Phi, Gamma[:, None], C, [[SHAPE[i] * PARTICIPATION[i]]], 1 / FS), u)
        y += np.ravel(out)
    return y


def _nlsid(linear: dict, u: np.ndarray, substeps: int, values: dict) -> np.ndarray:
    data = {**MODAL_JOINT.extend({"model": linear}, values), "simulation": {"substeps": substeps}}
    run = Run("r", FS, "noise", u)
    return ModelRunner.from_data(data, "model.yaml").simulate_each([run])[0]


def test_the_modal_cubic_with_an_acceleration_output_simulates_the_structure():
    """The modal form with the cubic at the moving mode's point and its feedthrough runs as the
    independent simulation of the structure does: the difference is nlsid's sub-step error, of
    second order (the force held over each sub-step; its value at the sample instant extrapolated
    from the two first sub-steps' middles), so it falls by 4 +- 1 per halving. Without the
    feedthrough the force's acceleration is missing from y: an error far above that."""
    u = np.random.default_rng(8).standard_normal(N)
    truth = _truth(u, 16, {MOVING: K3})
    linear = _modal_form(False)
    values = {"k3": K3 * PARTICIPATION[MOVING] ** 2, "feedthrough": acceleration_share(linear)}
    nonlinear = np.std(truth - _truth_linear(u))
    assert nonlinear > 0.1 * np.std(truth)  # the cubic matters: 10 % of y at least
    errors = [_rms(_nlsid(linear, u, m, values) - truth) for m in (5, 10, 20)]
    # RK4's own error, 1/15 of its change on halving the step: below 1 % of the smallest error here
    assert _rms(_truth(u, 8, {MOVING: K3}) - truth) < 0.15 * errors[2], errors
    assert 3 < errors[0] / errors[1] < 5 and 3 < errors[1] / errors[2] < 5, errors
    assert errors[2] < 1e-3 * nonlinear, (errors, nonlinear)
    assert _rms(_nlsid(linear, u, 20, {**values, "feedthrough": 0.0}) - truth) > 100 * errors[2]


def test_two_joints_at_two_points_simulate_the_structure():
    """Cubics on the modes at 15 and 33 Hz (``k3`` at ``mode``, ``k3_2`` at ``mode_2``, blocks
    first and second, each with its feedthrough c b): the same second-order agreement with the
    independent simulation, and the second joint's part of y is no rounding (10 % of the cubics')."""
    joints = {MOVING: K3, 2: K3_2}
    u = np.random.default_rng(9).standard_normal(N)
    truth = _truth(u, 16, joints)
    ss, _ = continuous_model(_user_model(False), FS)
    six, fifteen, thirty_three = modes_of(ss)  # by frequency
    linear = modal_state_space([fifteen, thirty_three, six], ss.D)
    values = {"k3": K3 * PARTICIPATION[MOVING] ** 2, "k3_2": K3_2 * PARTICIPATION[2] ** 2,
              "feedthrough": acceleration_share(linear), "feedthrough_2": acceleration_share(linear, 2)}
    assert values["feedthrough_2"] == pytest.approx(SHAPE[2] * PARTICIPATION[2], rel=1e-9)
    second = np.std(truth - _truth(u, 16, {MOVING: K3}))
    assert second > 0.1 * np.std(truth - _truth_linear(u))
    errors = [_rms(_nlsid(linear, u, m, values) - truth) for m in (10, 20)]
    assert 3 < errors[0] / errors[1] < 5 and errors[1] < 1e-3 * second, (errors, second)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def _truth_linear(u: np.ndarray) -> np.ndarray:
    """The structure without its cubic (exact ZOH of the user's model)."""
    ss = _user_model(True)
    _, out, _ = dlsim((ss.A, ss.B[:, None], ss.C[None, :], [[ss.D]], 1 / FS), u)
    return np.ravel(out)


def test_the_held_forces_give_a_straight_force_line_at_any_instant():
    """F(t) = 2 + 3 t held over each sub-step at its middle's value: the weights of
    :func:`with_feedthrough` reproduce F at any read-out instant phi Ts exactly (the straight line
    through two middles); one sub-step gives the held force."""
    substeps, h = 4, 1.0 / 4
    held = 2 + 3 * (np.arange(substeps) + 0.5) * h
    for phi in (0.0, 0.1, 0.5, 0.97):
        weights = with_feedthrough(np.zeros((0, 1)), np.array([1.0]), substeps, phi)[:, 0]
        assert weights @ held[:weights.size] == pytest.approx(2 + 3 * phi, rel=1e-12)
    existing = np.array([[0.5]])  # an output timing's rows are kept, the direct term added to them
    assert with_feedthrough(existing, np.array([2.0]), 4, 0.0)[:, 0].tolist() == [0.5 + 3.0, -1.0]
    assert with_feedthrough(np.zeros((0, 1)), np.array([2.0]), 1, 0.0)[:, 0].tolist() == [2.0]


def _feedback(at: str | None, points: bool, output: str = "position") -> dict:
    force = {"type": "cubic_stiffness", "k3": 1.0, **({"at": at} if at else {})}
    model = {"type": "nonlinear_feedback", "output": output, "nonlinearities": [force],
             "linear": {"type": "state_space", "A": [[0, 1], [-100, -1]], "B": [0, 1], "C": [-100, -1], "D": 1}}
    if points:
        model["points"] = {"q": {"force": [0, 1], "position": [1, 0], "feedthrough": 1.0}}
    return {"model": model}


@pytest.mark.parametrize("data, where", [(_feedback(None, True), "model.nonlinearities[0].at"),
                                         (_feedback("plant", True), "model.nonlinearities[0].at"),
                                         (_feedback("q", False), "model.linear"),
                                         (_feedback("q", True, "velocity"), "model.linear")])
def test_a_feedthrough_with_a_force_where_u_enters_is_refused(data, where):
    """A linear part with D: a force where u enters (an algebraic loop), no points, or a velocity
    output is refused at its key; the force at a point is taken."""
    with pytest.raises(InputError) as error:
        ModelRunner.from_data(data, "model.yaml")
    assert f"{where}:" in str(error.value), error.value
    ModelRunner.from_data(_feedback("q", True), "model.yaml")


def test_the_output_timing_of_an_acceleration_output_is_not_fitted_as_a_lag():
    """An output with a direct term steps with the held input at each sample instant: a lag would
    read the previous sample's input, so the nuisance fit keeps the timing in [0, 1) there (D, or
    a force point's feedthrough alone), in (-1, 1) for a strictly proper model."""
    linear = _modal_form(False)
    u = np.random.default_rng(1).standard_normal(N)
    runs = [Run("r", FS, "noise", u, y=u)]
    values = {"k3": K3, "feedthrough": acceleration_share(linear)}
    bounds = {}
    for name, D, feedthrough in (("both", linear["D"], values["feedthrough"]), ("point", 0.0, values["feedthrough"]),
                                 ("neither", 0.0, 0.0)):
        data = MODAL_JOINT.extend({"model": {**linear, "D": D}}, {**values, "feedthrough": feedthrough})
        free = free_nuisances(ModelRunner.from_data(data, "model.yaml"), runs)["model.output_timing"]
        bounds[name] = (free.lower, free.upper)
    assert bounds == {"both": (0.0, 0.99), "point": (0.0, 0.99), "neither": (-0.99, 0.99)}, bounds


def test_a_feedthrough_beside_an_integrator_is_no_acceleration_output():
    """A pole at s = 0 (an unbounded response, which no acceleration output has) with a D: no modal
    form, and a reason instead of a singular matrix."""
    A = np.zeros((5, 5))
    A[1:, 1:] = _truth_blocks()[0][:4, :4]
    ss = StateSpace(A, np.ones(5), np.ones(5), 0.5, False)
    reason, _ = continuous_model(ss, FS)
    assert isinstance(reason, str) and "pole on the frequency axis" in reason, reason
