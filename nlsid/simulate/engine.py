"""Simulate one run of an excitation through a plant (open or closed loop) or a block structure.

The result is a :class:`~nlsid.io.run.Run` with the excitation's metadata and the signals a
measurement would record: ``u`` (the plant input as measured, + input measurement noise), ``y``
(the output as measured), and in closed loop ``r`` (the excitation, used as the reference).
Numerical method: :mod:`nlsid.simulate.kernels` and :mod:`nlsid.models.forces`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models import blocks, equations, forces
from nlsid.models.controller import discrete_path, feedforward, tustin, two_input
from nlsid.models.from_config import ClosedLoop, Plant, Structure
from nlsid.models.lti import StateSpace, check_rate, delay_samples, stepped, zoh
from nlsid.simulate.channels import weighted_sum
from nlsid.simulate.kernels import SIZED_SAMPLES, apply_block, simulate_loop
from nlsid.simulate.noise import Noise
from nlsid.simulate.propagation import propagation

DEFAULT_SUBSTEPS = 10  # sub-steps per sample for a plant with nonlinear forces (none needed without)


def _substeps(requested: int | None, ss: StateSpace, nonlinear: bool) -> int:
    if ss.discrete:
        if requested not in (None, 1):
            raise InputError("simulation.substeps", "a discrete-time model runs one step per sample; remove substeps")
        return 1
    if requested is not None:
        return requested
    return DEFAULT_SUBSTEPS if nonlinear else 1


def _delay(ss: StateSpace, fs: float, n: int, where: str) -> int:
    d = delay_samples(ss.delay, fs, f"{where}.delay")
    if d >= n:
        raise InputError(f"{where}.delay", f"dead time of {d} samples is not shorter than the record ({n} samples)")
    return d


_EMPTY_I = np.zeros(0, dtype=np.int64)
_EMPTY_2 = np.zeros((0, 0))
_EMPTY_1 = np.zeros(0)
_IDENTITY = blocks.encode(None)


def _f64(a) -> np.ndarray:
    """A writable C-ordered float64 copy: one kernel signature whatever the source (cached
    discretisations are read-only), so numba compiles and caches the kernel once."""
    return np.array(a, dtype=np.float64, order="C")


def _signal(a) -> np.ndarray:
    """A signal for the kernel: float64, C-ordered, writable (copied only when it is not)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


@dataclass(frozen=True)
class Timing:
    """The recorded output against the held input: ``delay`` whole samples of dead time on the
    plant input, and the output read at the fraction ``phi`` of a sample (``lag``: of the previous one)."""

    delay: int = 0
    phi: float = 0.0
    lag: bool = False


def timing(plant: Plant, fs: float, n: int, closed: bool, computation_delay: int = 0) -> Timing:
    """The dead time and output timing of a plant at ``fs`` as one shift of the output.

    The plant is time-invariant and starts at rest, so a dead time of tau seconds on its input and
    an output read at t_k + t Ts give the same samples as a read at t_k + (t - tau fs) Ts without
    the dead time: the total shift T = t - tau fs - computation_delay (samples) is split into
    d = floor(-T) >= 0 whole samples of input delay and a fraction: a lead phi = T in [0, 1) when
    T >= 0, else a lag phi = 1 + T + d, read in the previous sample. This makes a fractional dead
    time exact for a ZOH input. In closed loop the output must not need this sample's input, so
    T <= 0: a lead needs at least as much dead time (else the loop would be algebraic).
    """
    if plant.ss.discrete:
        total = -float(delay_samples(plant.ss.delay, fs, "model.delay") + computation_delay)
    else:
        total = plant.output_timing - plant.ss.delay * fs - computation_delay
    whole = max(0, math.floor(-total + 1e-9))
    fraction = total + whole
    if abs(fraction) <= 1e-9:
        fraction = 0.0
    if whole >= n:
        raise InputError("model.delay", f"dead time of {whole} samples is not shorter than the record ({n} samples)")
    if closed and fraction > 0:
        raise InputError("model.output_timing",
                         f"an output leading the input by {fraction:g} samples makes the loop algebraic: in closed "
                         "loop a lead needs a dead time (model.delay, closed_loop.computation_delay) at least as long")
    return Timing(whole, fraction if fraction >= 0 else 1.0 + fraction, fraction < 0)


def readout(ss: StateSpace, force_columns: np.ndarray, h: float, substeps: int, phi: float, fs: float):
    """Coefficients of the output at t_k + phi Ts: y = c_x x(t_k) + c_p p - sum_{j,e} c_f[j, e] F_j[e].

    With t = phi Ts, the ZOH solution gives c_x = C e^{A t}, c_p = C Gamma(t) + D, and a force of
    element e held over sub-step j, [j h, (j + 1) h], enters by its part within [0, t]:
    c_f[j, e] = C e^{A (t - b)} Gamma_F[e](b - j h), b = min((j + 1) h, t) (Gamma_F(s) the ZOH
    column over a length s). Rows of c_f stop at the last sub-step that starts before t.
    """
    E = force_columns.shape[0]
    if phi == 0.0:
        return ss.C, ss.D, np.zeros((0, E))
    t = phi / fs
    Phi_t, Gamma_t = zoh(ss.A, ss.B, t)
    rows = []
    for j in range(substeps if E else 0):
        start = j * h
        if start >= t * (1 - 1e-12):
            break
        end = min(start + h, t)
        remaining = zoh(ss.A, ss.B, t - end)[0] if t - end > 0 else np.eye(ss.order)
        rows.append(ss.C @ remaining @ zoh(ss.A, force_columns.T.copy(), end - start)[1])
    return ss.C @ Phi_t, float(ss.C @ Gamma_t + ss.D), np.array(rows).reshape(len(rows), E)


def with_feedthrough(c_f: np.ndarray, outputs: np.ndarray, substeps: int, phi: float) -> np.ndarray:
    """``c_f`` (:func:`readout`) with each force's direct term in the output, y(t) = ... - d_e F_e(t)
    at t = phi Ts (an acceleration output, :mod:`nlsid.models.mechanical`).

    The kernel holds F_e over each sub-step j at its value at the sub-step's middle, (j + 1/2) h,
    to O(h^2) (the laws' mid-point and mean rules, :mod:`nlsid.models.forces`); F_e(t) is the
    straight line through the two middles nearest t (extrapolated before the first and after the
    last), of the same second order, on rows j, j + 1 of c_f: weights 1 - x, x with
    x = t / h - (j + 1/2). One sub-step gives the held force itself (first order).
    """
    if not np.any(outputs):
        return c_f
    if substeps == 1:
        weights = {0: 1.0}
    else:
        at = phi * substeps - 0.5  # t in sub-steps from the first sub-step's middle
        j = min(max(math.floor(at), 0), substeps - 2)
        weights = {j: 1.0 - (at - j), j + 1: at - j}
    out = np.zeros((max(c_f.shape[0], max(weights) + 1), outputs.size))
    out[:c_f.shape[0]] = c_f
    for j, weight in weights.items():
        out[j] += weight * outputs
    return out


def _force_outputs(plant: Plant) -> np.ndarray:
    """Each force's direct term in the output (:attr:`nlsid.models.from_config.Force.output`)."""
    return np.array([f.output for f in plant.forces], dtype=float)


def _force_rows(plant: Plant, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the forces, (E, n): a backward-difference row times fs is a velocity."""
    n = plant.ss.order
    if not plant.forces:
        return np.zeros((0, n)), np.zeros((0, n))
    rows = np.array([f.row * fs if f.difference else f.row for f in plant.forces])
    return rows, np.array([f.column for f in plant.forces])


def _kernel_arguments(Phi, Gu, ss: StateSpace, x0, kinds, params, rows, columns, substeps: int, h: float,
                      shift: Timing, fs: float, controller, r, ff, u, process, y_noise,
                      input_block=_IDENTITY, output_block=_IDENTITY, p_bias: float = 0.0, outputs=_EMPTY_1) -> tuple:
    """The arguments of the kernel's ``loop`` (:func:`nlsid.simulate.kernels._make_loop`) but its
    two output arrays, in its order, as the kernel takes them (float64, C-ordered); ``outputs``
    the forces' direct terms in the output (:func:`with_feedthrough`)."""
    n_el = len(kinds)
    force_gammas = columns if ss.discrete else (zoh(ss.A, columns.T.copy(), h)[1].T.copy() if n_el else columns)
    prop = propagation(Phi, Gu, rows, force_gammas, substeps)
    c_x, c_p, c_f = readout(ss, columns, h, substeps, shift.phi, fs)
    c_f = with_feedthrough(c_f, np.asarray(outputs, dtype=float), substeps, shift.phi)
    closed = controller is not None
    Ac, Bc, Cc, Dc = controller if closed else (_EMPTY_2, np.zeros((0, 2)), _EMPTY_1, np.zeros(2))
    return (_f64(prop.phi), _f64(prop.gamma), _f64(ss.C), _f64(x0), kinds, _f64(params),
            _f64(prop.row_pow), _f64(prop.row_gamma), _f64(prop.coupling), _f64(prop.col_pow),
            float(h), int(shift.delay), closed, _f64(Ac), _f64(Bc), _f64(Cc), _f64(Dc),
            _signal(r), _signal(ff), _signal(u), _signal(process), _signal(y_noise),
            int(input_block[0]), _f64(input_block[1]), int(output_block[0]), _f64(output_block[1]),
            float(p_bias), bool(shift.lag), _f64(c_x), float(c_p), _f64(c_f))


def _run_kernel(*args, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """The kernel on :func:`_kernel_arguments` (same parameters): (u_out, y_out)."""
    arguments = _kernel_arguments(*args, **kwargs)
    n, length = arguments[0].shape[0], max(arguments[17].shape[0], arguments[19].shape[0])
    nc = arguments[13].shape[0]
    u_out, y_out = np.empty(length), np.empty(length)
    sizes = (n, nc) if length >= SIZED_SAMPLES else None
    simulate_loop(len(arguments[4]), sizes)(*arguments, u_out, y_out)
    return u_out, y_out


def _check_finite(y: np.ndarray, run_id: str) -> None:
    # no |y| temporary: 0.29 ms instead of 0.79 per 1e6 samples
    peak = max(np.max(y, initial=0.0), -np.min(y, initial=0.0))
    if not peak <= 1e150:  # NaN propagates through max/min and fails the comparison
        raise InputError("model", f"run {run_id}: the simulation diverged (an unstable model or loop?)")


def closed_loop_poles(ss: StateSpace, controller, fs: float, shift: Timing) -> np.ndarray:
    """Poles (z) of the linear part of the sampled closed loop: plant (ZOH), dead time, output
    timing, controller (forces, blocks and offsets left out).

    State [x, q_1..q_d, xc, c] (c: the lagging output read in the previous sample, if any). With
    r = 0 the controller (Ac, Bc, Cc, Dc) of inputs [e, y] = [-y, y] reads y = c (lag) or C x, and
    outputs u = Cc xc + (Dc[1] - Dc[0]) y; the plant gets q_d (or u if d = 0).
    """
    Ac, Bc, Cc, Dc = controller
    Phi, Gam = stepped(ss, 1.0 / fs)
    n, nc, d, lag = ss.order, Ac.shape[0], shift.delay, int(shift.lag)
    N = n + d + nc + lag
    read = np.zeros(N)
    if lag:
        read[-1] = 1.0
    else:
        read[:n] = ss.C
    u_row = (Dc[1] - Dc[0]) * read
    u_row[n + d:n + d + nc] += Cc
    p_row = np.zeros(N)
    if d:
        p_row[n + d - 1] = 1.0
    else:
        p_row = u_row
    M = np.zeros((N, N))
    M[:n, :n] = Phi
    M[:n] += np.outer(Gam, p_row)
    if d:
        M[n] = u_row
        for i in range(1, d):
            M[n + i, n + i - 1] = 1.0
    M[n + d:n + d + nc, n + d:n + d + nc] = Ac
    M[n + d:n + d + nc] += np.outer(Bc[:, 1] - Bc[:, 0], read)
    if lag:
        c_x, c_p, _ = readout(ss, np.zeros((0, n)), 1.0 / fs, 1, shift.phi, fs)
        M[-1, :n] = c_x
        M[-1] += c_p * p_row
    return np.linalg.eigvals(M) if N else np.zeros(0)


def plant_input_terms(offsets, run: Run, process: np.ndarray) -> np.ndarray:
    """process + input offset + sum gain * channel: everything added to the command at the plant input
    (:func:`nlsid.simulate.channels.weighted_sum`: a channel the run lacks is refused, or zero)."""
    return process + offsets.input + weighted_sum(offsets.channels, offsets.zero_if_absent, run,
                                                  "model.input_channels")


def _controller(loop: ClosedLoop, fs: float):
    """(Ac, Bc, Cc, Dc) of the drive's law at fs, inputs [e, y] (:func:`nlsid.models.controller.two_input`)."""
    return two_input(discrete_path(loop.controller, fs), discrete_path(loop.measurement, fs))


@dataclass(frozen=True)
class LoopStart:
    """The state a closed loop is in at the first sample of a record that starts in motion.

    ``plant``: the plant state x(0) (in place of the model's own initial state); ``commands``: the
    drive outputs u[-d] .. u[-1] issued before the record and still in the dead time of d samples
    (:func:`timing`), applied at samples 0 .. d-1; ``controller``: the drive's state xc(0) in the
    order of :func:`nlsid.models.controller.two_input` (the controller on the error, then the terms
    on the measurement, e.g. a velocity estimate's past positions).

    The drive is linear, so its state enters the command as its free response alone,
    u[k] += Cc Ac^k xc(0), and a command in the dead time adds to the plant input of its sample:
    the kernel runs such a start exactly from rest with these two terms added, whatever the plant's
    forces and blocks.
    """

    plant: np.ndarray
    commands: np.ndarray
    controller: np.ndarray


def _start_terms(start: LoopStart, controller, shift: Timing, fs: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(command term, plant-input term) of ``start`` over n samples (:class:`LoopStart`)."""
    Ac, Bc, Cc, _ = controller
    command = np.zeros(n)
    if Ac.shape[0] and np.any(start.controller):
        drive = StateSpace(Ac, Bc[:, 0].copy(), Cc, 0.0, True)
        command = _filter(drive, np.zeros(n), fs, 0, start.controller)
    plant_input = np.zeros(n)
    d = min(shift.delay, n)
    if d:
        plant_input[:d] = start.commands[len(start.commands) - shift.delay:][:d]
    return command, plant_input


def plant_arguments(plant: Plant, loop: ClosedLoop | None, run: Run, substeps: int | None, noise: Noise,
                    start: LoopStart | None = None) -> tuple:
    """The parameters of :func:`_kernel_arguments` for ``plant`` on ``run`` (open loop: u is the
    plant input; closed loop: u is the reference), in closed loop from ``start`` (default rest)."""
    ss, n, fs = plant.ss, run.n_samples, run.fs
    check_rate(ss, fs, "model", run.run_id)
    if plant.difference_output:
        ss = dataclasses.replace(ss, C=ss.C * fs)
    m = _substeps(substeps, ss, bool(plant.forces))
    h = 1.0 / (fs * m)
    shift = timing(plant, fs, n, loop is not None, loop.computation_delay if loop else 0)
    Phi, Gu = stepped(ss, h)
    controller = None
    r = ff = _EMPTY_1
    if loop is not None:
        if ss.D != 0 or np.any(_force_outputs(plant)):
            raise InputError("model", "a closed loop needs a strictly proper plant (no direct feed-through D, "
                                      "no force point with a feedthrough)")
        controller = _controller(loop, fs)
        worst = np.max(np.abs(closed_loop_poles(ss, controller, fs, shift)), initial=0.0)
        if worst >= 1.0:
            raise InputError("closed_loop", f"the linear closed loop is unstable at fs = {fs:g} Hz "
                                            f"(pole with |z| = {worst:.6g} >= 1)")
        r = run.u if loop.prefilter is None else _filter(tustin(loop.prefilter, 1.0 / fs), run.u, fs, 0)
        ff = feedforward(run.u, fs, run.period is not None, loop.coulomb, loop.velocity) + weighted_sum(
            loop.excitation, loop.excitation_zero_if_absent, run, "closed_loop.excitation_channels")
    x0, process = plant.x0, plant_input_terms(plant.offsets, run, noise.process)
    if start is not None and loop is not None:
        command, plant_input = _start_terms(start, controller, shift, fs, n)
        x0, ff, process = _f64(start.plant), ff + command, process + plant_input
    kinds = np.array([f.kind for f in plant.forces], dtype=np.int64) if plant.forces else _EMPTY_I
    params = np.array([f.params for f in plant.forces]) if plant.forces else np.zeros((0, forces.MAX_PARAMS))
    rows, columns = _force_rows(plant, fs)
    return (Phi, Gu, ss, x0, kinds, params, rows, columns, m, h, shift, fs, controller, r, ff, run.u,
            process, noise.y + plant.offsets.output,
            plant.input_block, plant.output_block, plant.force_bias, _force_outputs(plant))


def simulate_plant(plant: Plant, loop: ClosedLoop | None, run: Run, substeps: int | None, noise: Noise,
                   start: LoopStart | None = None) -> Run:
    """Run ``plant`` on ``run`` (open loop: u is the plant input; closed loop: u is the reference,
    the loop from ``start``, default rest: :class:`LoopStart`)."""
    u_out, y_out = _run_kernel(*plant_arguments(plant, loop, run, substeps, noise, start))
    _check_finite(y_out, run.run_id)
    u_out += noise.u  # in place: a fresh 8 MB array costs ~2 ms of page faults per 1e6 samples
    if loop is None:
        return dataclasses.replace(run, u=u_out, y=y_out, r=None)
    # Closed loop: the excitation is the reference (it keeps the excitation's unit of u); the
    # recorded u is the plant input, whose unit the config does not state.
    units = {"r": run.units["u"]} if "u" in run.units else {}
    return dataclasses.replace(run, u=u_out, y=y_out, r=run.u.copy(), units=units)


def simulate_equations(model: equations.Equations, run: Run, substeps: int | None, noise: Noise) -> Run:
    """Run a model written as equations on ``run`` (:mod:`nlsid.models.equations`) as the kernel
    runs a plant: the plant input f_in(u[k - d] + input offset + channels + process noise), the
    recorded y = f_out(output) + output offset + output noise."""
    d = delay_samples(model.delay, run.fs, "model.delay")
    if d >= run.n_samples:
        raise InputError("model.delay", f"dead time of {d} samples is not shorter than the record "
                                        f"({run.n_samples} samples)")
    command = np.concatenate([np.zeros(d), run.u[:run.n_samples - d]])
    plant_input = command + plant_input_terms(model.offsets, run, noise.process)
    if model.input_block[0] != blocks.IDENTITY:
        plant_input = apply_block(model.input_block[0], model.input_block[1], plant_input)
    y = equations.response(model, run, plant_input, substeps)
    if model.output_block[0] != blocks.IDENTITY:
        y = apply_block(model.output_block[0], model.output_block[1], y)
    y = y + noise.y + model.offsets.output
    _check_finite(y, run.run_id)
    return dataclasses.replace(run, u=run.u + noise.u, y=y, r=None)


def _filter(ss: StateSpace, x: np.ndarray, fs_step: float, delay: int, x0: np.ndarray | None = None) -> np.ndarray:
    """An LTI block alone on the held signal x at the rate fs_step, with ``delay`` samples of dead
    time, from the state ``x0`` (default rest)."""
    Phi, Gu = stepped(ss, 1.0 / fs_step)
    zero = np.zeros_like(x)
    none = np.zeros((0, ss.order))
    start = np.zeros(ss.order) if x0 is None else _f64(x0)
    return _run_kernel(Phi, Gu, ss, start, _EMPTY_I, np.zeros((0, forces.MAX_PARAMS)), none, none, 1,
                       1.0 / fs_step, Timing(delay), fs_step, None, _EMPTY_1, _EMPTY_1, x, zero, zero)[1]


def apply_static(block: blocks.StaticBlock, x: np.ndarray) -> np.ndarray:
    """A nonlinear block (:mod:`nlsid.models.blocks`) along the signal ``x``, a backlash from y = 0."""
    return apply_block(block.kind, block.params, np.ascontiguousarray(x, dtype=np.float64))


def structure_stages(structure: Structure) -> list[StateSpace]:
    """The LTI stages of a structure, branch by branch, each branch's in series order."""
    return [s for branch in structure.branches for s in branch if isinstance(s, StateSpace)]


def simulate_structure(structure: Structure, run: Run, substeps: int | None, noise: Noise,
                       states: list[np.ndarray] | None = None) -> Run:
    """Run a block structure on ``run``: each branch's stages in series, branches summed; each LTI
    stage from its state in ``states`` (in :func:`structure_stages` order; default all at rest).

    With ``substeps`` M > 1 the held input is evaluated M times per sample, so the signals between
    blocks are sampled M times finer (continuous LTI blocks only); y is then read every M-th value.
    """
    stages = structure_stages(structure)
    starts = iter(states if states is not None else [None] * len(stages))
    m = substeps or 1
    if m > 1 and any(s.discrete for s in stages):
        raise InputError("simulation.substeps", "a structure with discrete-time blocks runs one step per sample")
    n = run.n_samples
    x = np.repeat(run.u + plant_input_terms(structure.offsets, run, noise.process), m)
    y = np.zeros_like(x)
    for i, branch in enumerate(structure.branches):
        signal = x
        for stage in branch:
            if isinstance(stage, StateSpace):
                check_rate(stage, run.fs, "model", run.run_id)
                delay = _delay(stage, run.fs, n, "model") * m
                signal = _filter(stage, signal, run.fs * m, delay, next(starts))
            else:
                signal = apply_static(stage, signal)
        y += signal
    y = y[::m] + noise.y + structure.offsets.output
    _check_finite(y, run.run_id)
    return dataclasses.replace(run, u=run.u + noise.u, y=y, r=None)


STEADY_TOLERANCE = 1e-6   # a transient below this fraction of its start counts as settled
MAX_LEAD_PERIODS = 20     # periods simulated ahead of a run at most


def _decay_rate(ss: StateSpace, fs: float) -> float:
    """The slowest decay rate (1/s) of the modes of ``ss``: min -Re(s), a discrete pole z as
    s = fs ln z; 0 with an integrator or an unstable mode, inf without modes."""
    poles = ss.poles()
    if poles.size == 0:
        return math.inf
    if ss.discrete:
        with np.errstate(divide="ignore"):
            rates = -np.log(np.abs(poles)) * fs
    else:
        rates = -poles.real
    return max(float(np.min(rates)), 0.0)


def _loop_decay_rate(plant: Plant, loop: ClosedLoop, fs: float, n: int) -> float:
    """The slowest decay rate (1/s) of the sampled closed loop (:func:`closed_loop_poles`: plant,
    dead time, output timing, the drive's law) and of the reference's prefilter, a pole z as
    s = fs ln z; 0 with a pole on or outside the unit circle."""
    ss = dataclasses.replace(plant.ss, C=plant.ss.C * fs) if plant.difference_output else plant.ss
    shift = timing(plant, fs, n, True, loop.computation_delay)
    poles = closed_loop_poles(ss, _controller(loop, fs), fs, shift)
    if loop.prefilter is not None:
        poles = np.concatenate([poles, tustin(loop.prefilter, 1.0 / fs).poles()])
    if poles.size == 0:
        return math.inf
    with np.errstate(divide="ignore"):
        return max(float(np.min(-np.log(np.abs(poles)) * fs)), 0.0)


def lead_samples(model: Plant | Structure | equations.Equations, loop: ClosedLoop | None, run: Run) -> int:
    """The samples t fs in which the slowest mode of the linear dynamics (rate sigma:
    :func:`_decay_rate` of a plant's linear part, forces aside, or of every stage of a structure; in
    closed loop :func:`_loop_decay_rate`, the loop's modes) decays to STEADY_TOLERANCE, t =
    ln(1 / STEADY_TOLERANCE) / sigma, at most MAX_LEAD_PERIODS periods. 0 for an arbitrary record,
    a run with transient periods (simulated as measured), and a model (or loop) with an integrator
    or an unstable mode (no periodic steady state to reach) or without modes, a model written as
    equations (its initial states are part of the model: no lead-in), and a hybrid model (each of
    its parts runs its own lead-in, :mod:`nlsid.models.hybrid`)."""
    from nlsid.io.ranges import RangeRun

    if run.period is None or isinstance(run, RangeRun) or run.transient_periods:
        return 0
    if isinstance(model, equations.Equations):  # starts at its written initial states (nlsid.models.equations)
        return 0
    if not isinstance(model, (Plant, Structure)):  # a hybrid model: each part runs its own lead-in (models.hybrid)
        return 0
    if loop is not None:
        sigma = _loop_decay_rate(model, loop, run.fs, run.n_samples)
    else:
        stages = structure_stages(model) if isinstance(model, Structure) else [model.ss]
        sigma = min((_decay_rate(ss, run.fs) for ss in stages), default=math.inf)
    if sigma == 0 or not math.isfinite(sigma):
        return 0
    return min(math.ceil(math.log(1 / STEADY_TOLERANCE) / sigma * run.fs), MAX_LEAD_PERIODS * run.period)


def hysteretic(model: Plant | Structure) -> bool:
    """Whether a nonlinearity of ``model`` keeps a memory of the excitation's past that its decay
    does not erase: friction (a stuck mass holds its place), backlash (the play's position), the
    Bouc-Wen state (which a stroke of the motion, not time, relaxes). Such
    a memory is wiped out by the excitation's extremes (Mayergoyz 1991, the wiping-out property of
    rate-independent hysteresis), which a whole period of a periodic excitation holds."""
    from nlsid.models import blocks, forces

    if isinstance(model, Structure):
        return any(getattr(stage, "memory", False) for branch in model.branches for stage in branch)
    return (any(f.kind in (forces.COULOMB, forces.STRIBECK, forces.LUGRE, forces.BOUC_WEN) for f in model.forces)
            or blocks.BACKLASH in (model.input_block[0], model.output_block[0]))


def lead_periods(model: Plant | Structure, loop: ClosedLoop | None, run: Run) -> int:
    """The periods to simulate ahead of a periodic run without transient periods, so that its first
    period is in periodic steady state, as it was measured: :func:`lead_samples` in whole periods
    (0 where no lead is simulated)."""
    return -(-lead_samples(model, loop, run) // run.period) if run.period else 0


def _lead(x: np.ndarray | None, period: int, count: int) -> np.ndarray | None:
    return None if x is None else np.concatenate([np.tile(x[:period], count), x])


def with_lead(run: Run, count: int) -> Run:
    """``run`` with its first period repeated ``count`` times ahead of it, in every signal."""
    return dataclasses.replace(run, u=_lead(run.u, run.period, count), y=_lead(run.y, run.period, count),
                               r=_lead(run.r, run.period, count),
                               channels={k: _lead(v, run.period, count) for k, v in run.channels.items()})
