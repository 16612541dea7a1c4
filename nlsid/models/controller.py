"""Digital controllers and feed-forward of the closed loop (seed 003, Fig. 1).

The drive computes once per sample, from the measured y[k] and the reference r[k],

    u[k] = C(e)[k] - M(y)[k] + u_ff[k],   e[k] = F(r)[k] - y[k],

with C the controller on the error, M optional terms on the measurement (e.g. the velocity loop
of a cascade, acting on a difference of y, :func:`difference`), F an optional reference
prefilter; u[k] is held by the DAC (ZOH) from sample k + computation delay on. A continuous controller C(s) is implemented through its Tustin
(bilinear) equivalent, s = (2/Ts) (z - 1)/(z + 1), the usual digital implementation; its frequency
response at the sample rate is C(j (2/Ts) tan(w Ts / 2)). A discrete controller is used as given.

PID with a first-order filter on the derivative:

    C(s) = kp + ki / s + kd s / (tau s + 1)
         = ((kp tau + kd) s^2 + (kp + ki tau) s + ki) / (tau s^2 + s).

Feed-forward (added to the controller output):

    u_ff[k] = K_fc sign(r'(t_k)) + K_v r'(t_k)

with the reference velocity r' from the central difference (r[k+1] - r[k-1]) fs / 2, taken
periodically for periodic runs (a record of whole periods) and one-sided at the ends otherwise.
sign(0) = 0. The reference is known in advance (a set-point), so using r[k+1] is causal in practice.
"""

from __future__ import annotations

import numpy as np

from nlsid.models.lti import StateSpace, check_rate, from_transfer_function


def pid(kp: float, ki: float, kd: float, tau: float) -> StateSpace:
    """The continuous PID of the module docstring as a state-space model."""
    if kd > 0 and ki > 0:
        num, den = [kp * tau + kd, kp + ki * tau, ki], [tau, 1.0, 0.0]
    elif kd > 0:  # PD: the common factor s of the PID form cancels (no integrator state)
        num, den = [kp * tau + kd, kp], [tau, 1.0]
    elif ki > 0:
        num, den = [kp, ki], [1.0, 0.0]
    else:
        num, den = [kp], [1.0]
    return from_transfer_function(num, den, False, 0.0, "closed_loop.controller")


def tustin(ss: StateSpace, ts: float) -> StateSpace:
    """Bilinear (Tustin) discretisation of a continuous model: exact map of s = (2/Ts)(z-1)/(z+1)."""
    if ss.discrete:
        return ss
    n = ss.order
    if n == 0:
        return StateSpace(ss.A, ss.B, ss.C, ss.D, True)
    eye = np.eye(n)
    q = np.linalg.inv(eye - ss.A * ts / 2)
    A = q @ (eye + ss.A * ts / 2)
    B = q @ ss.B * ts
    # C (zI - A_d)^-1 B_d + D_d = C (sI - A)^-1 B + D with the state scaled so that C_d = C q.
    C = ss.C @ q
    D = ss.D + ss.C @ q @ ss.B * ts / 2
    return StateSpace(A, B, C, float(D), True)


def difference(name: str, fs: float) -> StateSpace:
    """A causal velocity estimate of a sampled signal as a discrete model: ``backward``
    fs (1 - z^-1), i.e. (y[k] - y[k-1]) fs, or ``two_tap`` fs/2 (1 - z^-2), i.e. (y[k] - y[k-2]) fs / 2."""
    num = {"backward": [fs, -fs], "two_tap": [fs / 2, 0.0, -fs / 2]}[name]
    return from_transfer_function(num, [1.0], True, 0.0, name)


def series(first: StateSpace, second: StateSpace) -> StateSpace:
    """Discrete ``second`` after ``first``: state [x1; x2],

        x1+ = A1 x1 + B1 u,  x2+ = A2 x2 + B2 (C1 x1 + D1 u),  y = D2 C1 x1 + C2 x2 + D2 D1 u.
    """
    n1, n2 = first.order, second.order
    A = np.zeros((n1 + n2, n1 + n2))
    A[:n1, :n1] = first.A
    A[n1:, :n1] = np.outer(second.B, first.C)
    A[n1:, n1:] = second.A
    B = np.concatenate([first.B, second.B * first.D])
    C = np.concatenate([second.D * first.C, second.C])
    return StateSpace(A, B, C, float(second.D * first.D), True)


def discrete_path(stages: list, fs: float) -> StateSpace | None:
    """The series connection of a controller path at the sample rate ``fs`` (continuous stages by
    Tustin, velocity estimates by :func:`difference`); None for an empty path."""
    out = None
    for stage in stages:
        if not isinstance(stage, str):
            check_rate(stage, fs, "closed_loop.controller")
        ss = difference(stage, fs) if isinstance(stage, str) else tustin(stage, 1.0 / fs)
        out = ss if out is None else series(out, ss)
    return out


def two_input(error: StateSpace, measurement: StateSpace | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, C, D) of u = C_e(e) - C_m(y) with input [e, y]: B is (n, 2), D is (2,)."""
    m = measurement if measurement is not None else StateSpace(np.zeros((0, 0)), np.zeros(0), np.zeros(0), 0.0, True)
    ne, nm = error.order, m.order
    A = np.zeros((ne + nm, ne + nm))
    A[:ne, :ne], A[ne:, ne:] = error.A, m.A
    B = np.zeros((ne + nm, 2))
    B[:ne, 0], B[ne:, 1] = error.B, m.B
    C = np.concatenate([error.C, -m.C])
    D = np.array([error.D, -m.D])
    return A, B, C, D


def reference_velocity(r: np.ndarray, fs: float, periodic: bool) -> np.ndarray:
    """Central-difference velocity of the reference (periodic wrap for a record of whole periods)."""
    if not periodic:
        return np.gradient(r, 1.0 / fs)
    n = r.shape[0]
    v = np.empty_like(r)  # (r[k+1] - r[k-1]) fs / 2, indices modulo n, without temporaries
    np.subtract(r[2:], r[:-2], out=v[1:-1])
    v[0] = r[1 % n] - r[-1]
    v[-1] = r[0] - r[(n - 2) % n]
    v *= fs / 2
    return v


def feedforward(r: np.ndarray, fs: float, periodic: bool, coulomb: float, velocity: float) -> np.ndarray:
    """u_ff = K_fc sign(r') + K_v r' (seed 003, Fig. 1 for the Coulomb term)."""
    if coulomb == 0 and velocity == 0:
        return np.zeros_like(r)
    v = reference_velocity(r, fs, periodic)
    out = np.sign(v, out=None if velocity else v)  # in place without a velocity term: one array
    out *= coulomb
    if velocity:
        v *= velocity
        out += v
    return out
