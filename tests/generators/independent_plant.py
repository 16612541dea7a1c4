"""A measured plant for the tests, written independently of nlsid's simulator: linear dynamics
stepped exactly for a zero-order-hold input, a fractional dead time, and static blocks on the
input and the output, as docs/configs.md defines them.

Linear part. A continuous transfer function num/den (descending powers of s; a
``mass_spring_damper`` m p'' + c p' + k p = gain u is gain / (m s^2 + c s + k)), strictly proper,
in a state-space form (A, B, C) (scipy's ``tf2ss``). The plant input v(t) is the held sample
sequence v[k] on [k T, (k + 1) T). A dead time d = (m + f) T (m whole samples, 0 <= f < 1) shifts
the switching instants: on [k T, (k + 1) T) the plant sees v[k - m - 1] during the first f T and
v[k - m] after it, so, with Phi(tau) = e^{A tau} and Gamma(tau) = int_0^tau e^{A s} ds B (the block
exponential of Van Loan 1978, tests/generators/exact_zoh.py),

    x[k + 1] = Phi(T) x[k] + Phi((1 - f) T) Gamma(f T) v[k - m - 1] + Gamma((1 - f) T) v[k - m],
    y[k] = C x[k]   (the output sampled at t_k = k T, from rest),

the modified z-transform of the held input (e.g. Franklin, Powell and Workman 1998, Digital Control
of Dynamic Systems, Sec. 4.3.4): exact. The recursion runs as two discrete transfer functions
(``ss2tf``, ``lfilter``).

A cubic spring (``cubic_stiffness``, F = k3 p^3 against the motion, docs/configs.md): m p'' + c p'
+ k p + k3 p^3 = gain u, u held over each sample, integrated by the classical Runge-Kutta method
with RK_SUBSTEPS steps per sample, all runs at once (:func:`cubic_response`). Its error: the
step h = T / RK_SUBSTEPS against the fastest linear rate omega = sqrt(k / m) gives a local error
of order (omega h)^5; at 1024 Hz, omega = 200 rad/s and 8 steps, halving the step changes the
output by 3e-8 to 6e-8 of its rms (measured on the hidden suite's cubic cases), far below the
tests' noise (2e-3 of it); 1.5 s for 8 runs of 4096 samples.

Coulomb friction with stick-slip (``coulomb``: F = fc sign(v) + fv v, sticking while the other
forces stay within +-fc, docs/configs.md) on an underdamped mass_spring_damper, exactly
(:func:`coulomb_response`): while the mass slides in direction s the force is constant over the
held sample, so the motion is the closed-form damped oscillation about p_eq = (gain u - s fc) / k,

    q = p - p_eq:  q(t) = e^{sigma t} (q0 cos wd t + (v0 - sigma q0) / wd sin wd t),
    v(t) = e^{sigma t} (v0 cos wd t + (sigma (v0 - sigma q0) / wd - wd q0) sin wd t),

sigma = -(c + fv) / 2m, wd = sqrt(k / m - sigma^2); the instant v returns to 0 within the sample is
found by Brent's method on v(t) (at most one: half a period of the oscillation is longer than a
sample), and there the mass sticks if |gain u - k p| <= fc, else slides on the other way. A stuck
mass feels a constant force until the held input changes, so it leaves only at a sample instant.
No time step: the trajectory is exact to the root finder's tolerance.

A PID loop (:func:`closed_loop_response`): the drive's law of docs/configs.md, u[k] = C(e)[k],
e[k] = r[k] - y[k], y[k] the measured output (with its noise), C the PID through Tustin's
substitution as a difference equation, u held over the sample; the plant (a mass-spring-damper, or
a continuous transfer function) stepped exactly as above.

Stribeck and LuGre friction (symmetric laws): tests/generators/independent_friction.py, Runge-Kutta on a fine
grid with the stick events located.

Blocks (docs/configs.md, "blocks"): ``input_nonlinearity`` acts on the input samples before the hold
(saturation, deadzone, backlash: a play operator starting at 0), ``output_nonlinearity`` (a
polynomial) on the output samples.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq
from scipy.signal import bilinear, lfilter, ss2tf, tf2ss

from generators import independent_friction
from generators.exact_zoh import zoh

LINEAR_TYPES = ("mass_spring_damper", "transfer_function")
RK_SUBSTEPS = 8


def transfer_function(model: dict) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) in s of a continuous transfer_function or a mass_spring_damper (position output)."""
    if model["type"] == "mass_spring_damper":
        return (np.array([float(model.get("gain", 1.0))]),
                np.array([float(model["mass"]), float(model.get("damping", 0.0)), float(model.get("stiffness", 0.0))]))
    return np.asarray(model["num"], dtype=float), np.asarray(model["den"], dtype=float)


def _block_exponential(A: np.ndarray, B: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    if tau == 0.0:
        return np.eye(A.shape[0]), np.zeros(A.shape[0])
    return zoh(A, B, tau)


def linear_response(num: np.ndarray, den: np.ndarray, v: np.ndarray, fs: float, delay: float = 0.0) -> np.ndarray:
    """The sampled output of num/den (strictly proper) to the held input v with a dead time
    ``delay`` (seconds), from rest (module docstring)."""
    A, B, C, D = tf2ss(num, den)
    assert np.allclose(D, 0.0), "a strictly proper plant"
    B, C = B[:, 0], C[0]
    T = 1.0 / fs
    whole = math.floor(delay * fs + 1e-12)
    f = delay * fs - whole
    Phi, _ = _block_exponential(A, B, T)
    Phi_rest, Gamma_rest = _block_exponential(A, B, (1 - f) * T)
    _, Gamma_first = _block_exponential(A, B, f * T)
    early = Phi_rest @ Gamma_first      # multiplies v[k - m - 1]
    late = Gamma_rest                    # multiplies v[k - m]
    y = np.zeros(v.size)
    for gain, shift in ((early, whole + 1), (late, whole)):
        b, a = ss2tf(Phi, gain[:, None], C[None, :], np.zeros((1, 1)))
        # x[k+1] = Phi x[k] + gain w[k], y[k] = C x[k]: y = C (zI - Phi)^-1 gain w, b[0] = 0
        w = np.concatenate([np.zeros(shift), v[: v.size - shift]]) if shift else v
        y += lfilter(np.ravel(b), np.ravel(a), w)
    return y


def cubic_response(model: dict, U: np.ndarray, fs: float, substeps: int = RK_SUBSTEPS) -> np.ndarray:
    """The sampled positions (runs x samples) of m p'' + c p' + k p + k3 p^3 = gain u for the held
    inputs U (runs x samples), from rest: classical RK4, ``substeps`` per sample (module docstring)."""
    m, c, k = (float(model.get(key, 0.0)) for key in ("mass", "damping", "stiffness"))
    gain = float(model.get("gain", 1.0))
    (force,) = model["nonlinearities"]
    k3 = float(force["k3"])
    h = 1.0 / (fs * substeps)

    def acceleration(p, v, drive):
        return (drive - c * v - k * p - k3 * p**3) / m

    p, v = np.zeros(U.shape[0]), np.zeros(U.shape[0])
    Y = np.empty_like(U)
    for n in range(U.shape[1]):
        Y[:, n] = p
        drive = gain * U[:, n]
        for _ in range(substeps):
            k1p, k1v = v, acceleration(p, v, drive)
            k2p, k2v = v + 0.5 * h * k1v, acceleration(p + 0.5 * h * k1p, v + 0.5 * h * k1v, drive)
            k3p, k3v = v + 0.5 * h * k2v, acceleration(p + 0.5 * h * k2p, v + 0.5 * h * k2v, drive)
            k4p, k4v = v + h * k3v, acceleration(p + h * k3p, v + h * k3v, drive)
            p = p + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
            v = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return Y


def _slide(p0: float, v0: float, p_eq: float, sigma: float, wd: float, t: float) -> tuple[float, float]:
    """(p, v) after sliding for t from (p0, v0) about p_eq (module docstring)."""
    q0 = p0 - p_eq
    b = (v0 - sigma * q0) / wd
    decay, cos, sin = math.exp(sigma * t), math.cos(wd * t), math.sin(wd * t)
    return p_eq + decay * (q0 * cos + b * sin), decay * (v0 * cos + (sigma * b - wd * q0) * sin)


def _msd_step(p: float, v: float, drive: float, T: float, m: float, c: float, k: float, fc: float,
              fv: float) -> tuple[float, float]:
    """(p, v) one held sample T later, under the drive force and Coulomb friction fc + fv v (fc = 0:
    a linear mass_spring_damper, c + fv its damping), exactly (module docstring)."""
    sigma = -(c + fv) / (2 * m)
    wd = math.sqrt(k / m - sigma**2)
    if fc == 0.0:
        return _slide(p, v, drive / k, sigma, wd, T)
    left = T
    while left > 0.0:
        if v == 0.0:
            applied = drive - k * p
            if abs(applied) <= fc:
                return p, v  # stuck until the input changes
            direction = math.copysign(1.0, applied)
        else:
            direction = math.copysign(1.0, v)
        p_eq = (drive - direction * fc) / k
        p_end, v_end = _slide(p, v, p_eq, sigma, wd, left)
        if v_end * direction > 0.0:
            return p_end, v_end
        start = left * 1e-12 if v == 0.0 else 0.0
        stop = brentq(lambda t: _slide(p, v, p_eq, sigma, wd, t)[1] * direction, start, left, xtol=1e-15,
                      rtol=4 * np.finfo(float).eps)
        p, v = _slide(p, v, p_eq, sigma, wd, stop)[0], 0.0
        left -= stop
    return p, v


def _mechanics(model: dict) -> tuple[float, float, float, float, float, float]:
    """(m, c, k, gain, fc, fv) of a mass_spring_damper with at most one Coulomb force."""
    m, c, k = (float(model.get(key, 0.0)) for key in ("mass", "damping", "stiffness"))
    forces = model.get("nonlinearities") or []
    fc = float(forces[0]["fc"]) if forces else 0.0
    fv = float(forces[0].get("fv", 0.0)) if forces else 0.0
    return m, c, k, float(model.get("gain", 1.0)), fc, fv


def coulomb_response(model: dict, u: np.ndarray, fs: float) -> np.ndarray:
    """The sampled position of m p'' + c p' + k p = gain u - F, F Coulomb friction with stick-slip,
    for the held input u, from rest (module docstring)."""
    m, c, k, gain, fc, fv = _mechanics(model)
    p = v = 0.0
    y = np.empty(u.size)
    for n, drive in enumerate(gain * np.asarray(u, dtype=float)):
        y[n] = p
        p, v = _msd_step(p, v, drive, 1.0 / fs, m, c, k, fc, fv)
    return y


def pid_tustin(controller: dict, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a), a[0] = 1, of C(s) = kp + ki / s + kd s / (tau s + 1) = (kp s (tau s + 1) + ki (tau s + 1)
    + kd s^2) / (s (tau s + 1)) through Tustin's s = 2 fs (z - 1) / (z + 1) (scipy's ``bilinear``),
    in powers of z^-1."""
    kp, ki, kd, tau = (float(controller.get(key, 0.0)) for key in ("kp", "ki", "kd", "tau"))
    b, a = bilinear([kp * tau + kd, kp + ki * tau, ki], [tau, 1.0, 0.0], fs)
    return b / a[0], a / a[0]


def closed_loop_response(data: dict, r: np.ndarray, noise: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(u, y): the plant input the drive computes and the measured output, in the loop of
    docs/configs.md: y[k] = p(t_k) + noise[k], e[k] = r[k] - y[k], u = C(e) by the difference
    equation of :func:`pid_tustin`, held over the sample (no computation delay), the plant stepped
    exactly (:func:`_msd_step`), from rest."""
    b, a = pid_tustin(data["closed_loop"]["controller"], fs)
    read, step = _plant_stepper(data["model"], fs)
    e_past, u_past = np.zeros(b.size), np.zeros(a.size)
    u, y = np.empty(r.size), np.empty(r.size)
    for n in range(r.size):
        y[n] = read() + noise[n]
        e_past = np.roll(e_past, 1)
        e_past[0] = r[n] - y[n]
        u[n] = float(b @ e_past - a[1:] @ u_past[:-1])
        u_past = np.roll(u_past, 1)
        u_past[0] = u[n]
        step(u[n])
    return u, y


def _plant_stepper(model: dict, fs: float):
    """(read, step) of a plant from rest: read() the output at this sample instant, step(u) one held
    sample on: a mass_spring_damper by :func:`_msd_step`, a continuous transfer function (strictly
    proper) by its exact ZOH state step."""
    if model["type"] == "mass_spring_damper":
        m, c, k, gain, fc, fv = _mechanics(model)
        state = [0.0, 0.0]

        def step(u):
            state[:] = _msd_step(state[0], state[1], gain * u, 1.0 / fs, m, c, k, fc, fv)

        return (lambda: state[0]), step
    A, B, C, D = tf2ss(*transfer_function(model))
    assert np.allclose(D, 0.0), "a strictly proper plant"
    Phi, Gamma = zoh(A, B[:, 0], 1.0 / fs)
    x = np.zeros(A.shape[0])

    def step_linear(u):
        x[:] = Phi @ x + Gamma * u

    return (lambda: float(C[0] @ x)), step_linear


def input_block(block: dict | None, u: np.ndarray) -> np.ndarray:
    """docs/configs.md's input blocks on the samples (held afterwards)."""
    if block is None:
        return u
    kind = block["type"]
    if kind == "saturation":
        return np.clip(u, block["lower"], block["upper"])
    if kind == "deadzone":
        lower, upper = block["lower"], block["upper"]
        return np.where(u > upper, u - upper, np.where(u < lower, u - lower, 0.0))
    if kind == "backlash":
        half, out, y = block["width"] / 2, np.empty_like(u), 0.0
        for k, x in enumerate(u):
            if x - y > half:
                y = x - half
            elif y - x > half:
                y = x + half
            out[k] = y
        return out
    raise ValueError(f"no independent model of the input block {kind!r}")


def output_block(block: dict | None, y: np.ndarray) -> np.ndarray:
    """docs/configs.md's output polynomial: sum_i c_i y^i."""
    if block is None:
        return y
    assert block["type"] == "polynomial", block
    return sum(c * y**i for i, c in enumerate(block["coefficients"]))


def _coulomb(model: dict) -> bool:
    forces = model.get("nonlinearities") or []
    return len(forces) == 1 and forces[0]["type"] == "coulomb" and model["type"] == "mass_spring_damper"


def _cubic(model: dict) -> bool:
    forces = model.get("nonlinearities") or []
    return len(forces) == 1 and forces[0]["type"] == "cubic_stiffness" and model["type"] == "mass_spring_damper"


def _dynamic_friction(model: dict) -> bool:
    forces = model.get("nonlinearities") or []
    return len(forces) == 1 and independent_friction.models(forces[0]) and model["type"] == "mass_spring_damper"


def applies(data: dict) -> bool:
    """Whether this module models the config in open loop: a linear template or continuous transfer
    function with at most input/output blocks and a dead time, or a mass_spring_damper with one
    cubic spring, one Coulomb force or one symmetric Stribeck or LuGre force, and nothing else."""
    model = data["model"]
    known = {"type", "mass", "damping", "stiffness", "gain", "num", "den", "domain", "delay", "input_nonlinearity",
             "output_nonlinearity"}
    if "closed_loop" in data or model.get("output", "position") != "position":
        return False
    if _cubic(model) or _coulomb(model) or _dynamic_friction(model):
        return not set(model) - {"type", "mass", "damping", "stiffness", "gain", "nonlinearities"}
    return (model["type"] in LINEAR_TYPES and not set(model) - known
            and model.get("domain", "continuous") == "continuous")


def applies_in_closed_loop(data: dict) -> bool:
    """Whether :func:`closed_loop_response` models the config: a PID loop (nothing else in
    ``closed_loop``) around a mass_spring_damper with at most one Coulomb force, or around a
    continuous transfer function."""
    model, loop = data["model"], data.get("closed_loop")
    if loop is None or set(loop) != {"controller"} or loop["controller"].get("type") != "pid":
        return False
    if model["type"] == "transfer_function":
        return not set(model) - {"type", "num", "den", "domain"} and model.get("domain", "continuous") == "continuous"
    return (model["type"] == "mass_spring_damper" and model.get("output", "position") == "position"
            and not set(model) - {"type", "mass", "damping", "stiffness", "gain", "nonlinearities"}
            and (not model.get("nonlinearities") or _coulomb(model)))


def outputs(data: dict, U: np.ndarray, fs: float) -> np.ndarray:
    """The noise-free sampled outputs (runs x samples) of the plant ``data`` to the commands U."""
    assert applies(data), data
    model = data["model"]
    if _cubic(model):
        return cubic_response(model, U, fs)
    if _coulomb(model):
        return np.stack([coulomb_response(model, u, fs) for u in U])
    if _dynamic_friction(model):
        return independent_friction.response(model, U, fs)
    num, den = transfer_function(model)
    delay = float(model.get("delay", 0.0))
    return np.stack([output_block(model.get("output_nonlinearity"),
                                  linear_response(num, den, input_block(model.get("input_nonlinearity"), u), fs, delay))
                     for u in U])
