"""Mechanical plant templates: a mass with viscous damping and a spring, and a two-mass stage.

Both are linear state-space models driven by an actuator force ``gain * u``; nonlinear forces
(friction, cubic stiffness, see :mod:`nlsid.models.forces`) act on a named mass as a feedback on
that mass's velocity or position. A template therefore exposes, per mass, the state-space column
through which a force enters and the rows that read its position and velocity.

Mass-spring-damper, state x = [p, v]:

    m p'' + c p' + k p = gain u - F_nl,    A = [[0, 1], [-k/m, -c/m]],  B = [0, gain/m].

Two-mass stage, state x = [p1, v1, p2, v2] (1 = motor, driven; 2 = load), coupling spring k and
damper c, ground dampers c1, c2:

    m1 p1'' = gain u - k (p1 - p2) - c (v1 - v2) - c1 v1 - F_nl,1
    m2 p2'' =          k (p1 - p2) + c (v1 - v2) - c2 v2 - F_nl,2

A force may also act in the coupling itself, ``at: joint``: it reads the relative position
p1 - p2 (or velocity v1 - v2) and acts on the two masses equal and opposite, - F on the motor and
+ F on the load, as a spring between them does (a cubic joint: ``cubic_stiffness`` at the joint,
k (p1 - p2) + k3 (p1 - p2)^3 in the coupling).

Its transfer function from force to load position, for c1 = c2 = 0, is
(c s + k) / (s^2 (m1 m2 s^2 + c (m1 + m2) s + k (m1 + m2))): a rigid-body double integrator and a
flexible mode at w = sqrt(k (m1 + m2) / (m1 m2)).

Nonlinear feedback around a general linear system (the same structure for any mechanics): a
continuous state space G(s) = C (sI - A)^-1 B from force to position, strictly proper (D = 0, else
a position force would form an algebraic loop), driven by gain u - F:

    x' = A x + B (gain u - F),   p = C x,   v = p' = C A x + C B (gain u - F).

The velocity is a state read-out v = (C A) x exactly when C B = 0, i.e. G has relative degree >= 2
(a force then accelerates, as in Newton's law); only then can a friction force or a velocity
output be fed back. The single point where the forces act is named ``plant``. A discrete G(z)
(the model ``nlsid fit`` writes) reads the velocity as the backward difference of the position
(:func:`_discrete_feedback`).

Inside a continuous state space further points may be named (:func:`with_points`): a force at
point j enters along its own column b_j and reads its own row c_j, x' = A x + B (gain u - F) -
b_j F_j, p_j = c_j x, v_j = c_j A x where c_j b_j = 0 (a modal coordinate of a modal realisation,
a relative deflection), while the output stays C x.

An acceleration output (a structure driven by a force, its accelerations measured) has relative
degree 0: G(s) = C (sI - A)^-1 B + D. Such a G is taken (continuous, ``output: position``, the
output y = C x + D gain u) where its forces act at points only: a force where u enters would
reach the output through D in the instant the output is read, an algebraic loop for a force read
from that output. A force at a point may reach the output directly as well, y = C x + D gain u -
sum_j d_j F_j (its feedthrough d_j: the acceleration it gives the coordinate the output reads,
:mod:`nlsid.diagnose.hypotheses.modal_joint`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.models.lti import StateSpace


@dataclass(frozen=True)
class MechanicalPlant:
    """A linear mechanical model with force inputs and position/velocity read-outs per mass."""

    ss: StateSpace                      # actuator input u -> measured output
    x0: np.ndarray                      # initial state
    force_columns: dict[str, np.ndarray] = field(default_factory=dict)   # mass -> dx'/dF
    position_rows: dict[str, np.ndarray] = field(default_factory=dict)   # mass -> p = row . x
    velocity_rows: dict[str, np.ndarray] = field(default_factory=dict)   # mass -> v = row . x
    difference: bool = False  # velocity rows are backward differences per sample (times fs: a velocity)
    no_velocity: str = ""     # why there is no velocity read-out (when velocity_rows is empty)
    force_outputs: dict[str, float] = field(default_factory=dict)  # mass -> d: the output gets - d F directly

    @property
    def masses(self) -> list[str]:
        return list(self.force_columns)


def _unit(n: int, i: int) -> np.ndarray:
    out = np.zeros(n)
    out[i] = 1.0
    return out


def mass_spring_damper(mass: float, damping: float, stiffness: float, gain: float, output: str,
                       position0: float = 0.0, velocity0: float = 0.0, delay: float = 0.0) -> MechanicalPlant:
    """m p'' + c p' + k p = gain u; output position or velocity; one mass named ``mass``."""
    A = np.array([[0.0, 1.0], [-stiffness / mass, -damping / mass]])
    B = np.array([0.0, gain / mass])
    rows = {"position": _unit(2, 0), "velocity": _unit(2, 1)}
    ss = StateSpace(A, B, rows[output], 0.0, False, delay)
    return MechanicalPlant(
        ss, np.array([position0, velocity0]),
        force_columns={"mass": np.array([0.0, 1.0 / mass])},
        position_rows={"mass": rows["position"]},
        velocity_rows={"mass": rows["velocity"]},
    )


def two_mass_stage(motor_mass: float, load_mass: float, stiffness: float, damping: float,
                   motor_damping: float, load_damping: float, gain: float, output: str, output_at: str,
                   delay: float = 0.0) -> MechanicalPlant:
    """Motor mass driven by the actuator, coupled to a load mass by a spring and damper."""
    m1, m2, k, c, c1, c2 = motor_mass, load_mass, stiffness, damping, motor_damping, load_damping
    A = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [-k / m1, -(c + c1) / m1, k / m1, c / m1],
        [0.0, 0.0, 0.0, 1.0],
        [k / m2, c / m2, -k / m2, -(c + c2) / m2],
    ])
    B = np.array([0.0, gain / m1, 0.0, 0.0])
    positions = {"motor": _unit(4, 0), "load": _unit(4, 2)}
    velocities = {"motor": _unit(4, 1), "load": _unit(4, 3)}
    C = (positions if output == "position" else velocities)[output_at]
    return MechanicalPlant(
        StateSpace(A, B, C, 0.0, False, delay), np.zeros(4),
        force_columns={"motor": np.array([0.0, 1.0 / m1, 0.0, 0.0]), "load": np.array([0.0, 0.0, 0.0, 1.0 / m2]),
                       "joint": np.array([0.0, 1.0 / m1, 0.0, -1.0 / m2])},
        position_rows={**positions, "joint": positions["motor"] - positions["load"]},
        velocity_rows={**velocities, "joint": velocities["motor"] - velocities["load"]},
    )


def force_feedback(G: StateSpace, gain: float, output: str, delay: float, where: str) -> MechanicalPlant:
    """Forces fed back around a G from force to position (module docstring): strictly proper, or
    continuous with a feedthrough D and a position output (an acceleration output, its forces at
    points: the caller sees to that)."""
    if G.delay:
        raise InputError(f"{where}.linear.delay", f"put the actuator dead time on {where}.delay")
    if G.order == 0 or (G.D != 0 and (G.discrete or output != "position")):
        raise InputError(f"{where}.linear", "the linear part (force to position) must be strictly proper (D = 0); "
                                            "a direct feedthrough (an acceleration output) is taken with a continuous "
                                            "linear part, output: position and the forces at points")
    if G.discrete:
        return _discrete_feedback(G, gain, output, delay, where)
    C_velocity = G.C @ G.A
    velocity_rows = {}
    if abs(G.C @ G.B) <= 1e-12 * np.linalg.norm(G.C) * np.linalg.norm(G.B):
        velocity_rows["plant"] = C_velocity
    elif output == "velocity":
        raise InputError(f"{where}.output", "a velocity output needs a linear part of relative degree >= 2 "
                                            "(force to position; C B = 0)")
    C = G.C if output == "position" else C_velocity
    return MechanicalPlant(
        StateSpace(G.A, gain * G.B, C, gain * G.D, False, delay), np.zeros(G.order),
        force_columns={"plant": G.B}, position_rows={"plant": G.C}, velocity_rows=velocity_rows,
    )


def with_points(plant: MechanicalPlant, A: np.ndarray,
                points: dict[str, tuple[np.ndarray, np.ndarray, float]], where: str) -> MechanicalPlant:
    """``plant`` (a continuous :func:`force_feedback` with state matrix ``A``) with further force
    points, name -> (column b, row c, feedthrough d) in its state coordinates (module docstring): a
    force there enters along -b, reads the position c x, and the velocity c A x where c b = 0, and
    adds - d F to the output."""
    columns, positions, velocities = dict(plant.force_columns), dict(plant.position_rows), dict(plant.velocity_rows)
    outputs = dict(plant.force_outputs)
    for name, (column, row, feedthrough) in points.items():
        column, row = np.asarray(column, float), np.asarray(row, float)
        if name in columns:
            raise InputError(f"{where}.points.{name}", f"the name {name!r} is taken (the plant's own point)")
        for key, vector in (("force", column), ("position", row)):
            if vector.size != A.shape[0]:
                raise InputError(f"{where}.points.{name}.{key}",
                                 f"expected {A.shape[0]} numbers (the linear part's states), got {vector.size}")
        columns[name], positions[name] = column, row
        if feedthrough:
            outputs[name] = float(feedthrough)
        if abs(row @ column) <= 1e-12 * np.linalg.norm(row) * np.linalg.norm(column):
            velocities[name] = row @ A
    return MechanicalPlant(plant.ss, plant.x0, columns, positions, velocities, plant.difference, plant.no_velocity,
                           outputs)


def _discrete_feedback(G: StateSpace, gain: float, output: str, delay: float, where: str) -> MechanicalPlant:
    """Forces fed back around a discrete G(z) from force to position, one step per sample.

    The force F[k] is held over sample k like the input: x[k+1] = A x[k] + B (gain u[k] - F[k]),
    p[k] = C x[k]. The velocity is the backward difference v[k] = (p[k] - p[k-1]) fs, a read-out of
    the state augmented by the previous position q[k] = p[k-1]:

        [x; q][k+1] = [[A, 0], [C, 0]] [x; q][k] + [B; 0] (gain u - F),   v = fs [C, -1] [x; q].

    A friction force is chosen by the step of :mod:`nlsid.models.forces` over the sample (its
    velocity path from v[k] to v[k+1] taken as linear; sensitivity g = fs C B): it needs C B != 0, a force that
    moves the position within the sample it acts (the ZOH equivalent of a mass has C B = Ts^2 / 2m).
    """
    n = G.order
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = G.A
    A[n, :n] = G.C
    B = np.append(G.B, 0.0)
    position = np.append(G.C, 0.0)
    difference = np.append(G.C, -1.0)
    moves = abs(G.C @ G.B) > 1e-12 * np.linalg.norm(G.C) * np.linalg.norm(G.B)
    reason = "" if moves else ("needs C B != 0 on a discrete linear part (a force that moves the position "
                               "within the sample it acts)")
    if output == "velocity" and not moves:
        raise InputError(f"{where}.output", "a velocity output " + reason)
    C = position if output == "position" else difference
    return MechanicalPlant(
        StateSpace(A, gain * B, C, 0.0, True, delay, G.fs), np.zeros(n + 1),
        force_columns={"plant": B}, position_rows={"plant": position},
        velocity_rows={"plant": difference} if moves else {}, difference=True, no_velocity=reason,
    )
