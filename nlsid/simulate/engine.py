"""Simulate one run of an excitation through a plant (open or closed loop) or a block structure.

The result is a :class:`~nlsid.io.run.Run` with the excitation's metadata and the signals a
measurement would record: ``u`` (the plant input as measured, + input measurement noise), ``y``
(the output as measured), and in closed loop ``r`` (the excitation, used as the reference).
Numerical method: :mod:`nlsid.simulate.kernels` and :mod:`nlsid.models.forces`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models import blocks
from nlsid.models.controller import feedforward, tustin
from nlsid.models.from_config import ClosedLoop, Plant, Structure
from nlsid.models.lti import StateSpace, delay_samples, stepped, zoh
from nlsid.simulate.kernels import SIZED_SAMPLES, simulate_loop
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


def _run_kernel(Phi, Gu, ss: StateSpace, x0, forces_, substeps: int, h: float, delay: int,
                controller: StateSpace | None, r, ff, u, process, y_noise,
                input_block=_IDENTITY, output_block=_IDENTITY) -> tuple[np.ndarray, np.ndarray]:
    n_el = len(forces_)
    n = ss.order
    kinds = np.array([f.kind for f in forces_], dtype=np.int64) if n_el else _EMPTY_I
    params = np.array([f.params for f in forces_]) if n_el else np.zeros((0, 6))
    rows = np.array([f.row for f in forces_]) if n_el else np.zeros((0, n))
    cols = zoh(ss.A, np.array([f.column for f in forces_]).T, h)[1].T.copy() if n_el else np.zeros((0, n))
    prop = propagation(Phi, Gu, rows, cols, substeps)
    closed = controller is not None
    c = controller if closed else StateSpace(_EMPTY_2, _EMPTY_1, _EMPTY_1, 0.0, True)
    length = (r if closed else u).shape[0]
    u_out, y_out = np.empty(length), np.empty(length)
    sizes = (n, c.order) if length >= SIZED_SAMPLES else None
    simulate_loop(n_el, sizes)(_f64(prop.phi), _f64(prop.gamma), _f64(ss.C), float(ss.D), _f64(x0), kinds, _f64(params),
                  _f64(prop.row_pow), _f64(prop.row_gamma), _f64(prop.coupling), _f64(prop.col_pow),
                  float(h), int(delay), closed, _f64(c.A), _f64(c.B), _f64(c.C), float(c.D),
                  _signal(r), _signal(ff), _signal(u), _signal(process), _signal(y_noise),
                  int(input_block[0]), _f64(input_block[1]), int(output_block[0]), _f64(output_block[1]), u_out, y_out)
    return u_out, y_out


def _check_finite(y: np.ndarray, run_id: str) -> None:
    # no |y| temporary: 0.29 ms instead of 0.79 per 1e6 samples
    peak = max(np.max(y, initial=0.0), -np.min(y, initial=0.0))
    if not peak <= 1e150:  # NaN propagates through max/min and fails the comparison
        raise InputError("model", f"run {run_id}: the simulation diverged (an unstable model or loop?)")


def closed_loop_poles(plant: Plant, controller: StateSpace, fs: float, delay: int) -> np.ndarray:
    """Poles (z) of the linear part of the sampled closed loop: plant (ZOH), dead time, controller
    (forces and blocks left out).

    State [x, q_1..q_d, xc]; with r = 0: u = Cc xc - Dc C x, the plant gets q_d (or u if d = 0).
    """
    Phi, Gam = stepped(plant.ss, 1.0 / fs)
    C = plant.ss.C
    n, nc = plant.ss.order, controller.order
    N = n + delay + nc
    M = np.zeros((N, N))
    u_row = np.zeros(N)
    u_row[:n] = -controller.D * C
    u_row[n + delay:] = controller.C
    M[:n, :n] = Phi
    if delay:
        M[:n, n + delay - 1] += Gam
        M[n, :] = u_row
        for i in range(1, delay):
            M[n + i, n + i - 1] = 1.0
    else:
        M[:n, :] += np.outer(Gam, u_row)
    M[n + delay:, :n] = -np.outer(controller.B, C)
    M[n + delay:, n + delay:] = controller.A
    return np.linalg.eigvals(M) if N else np.zeros(0)


def simulate_plant(plant: Plant, loop: ClosedLoop | None, run: Run, substeps: int | None, noise: Noise) -> Run:
    """Run ``plant`` on ``run`` (open loop: u is the plant input; closed loop: u is the reference)."""
    ss, n = plant.ss, run.n_samples
    m = _substeps(substeps, ss, bool(plant.forces))
    h = 1.0 / (run.fs * m)
    delay = _delay(ss, run.fs, n, "model")
    Phi, Gu = stepped(ss, h)
    controller = None
    r = ff = _EMPTY_1
    if loop is not None:
        if ss.D != 0:
            raise InputError("model", "a closed loop needs a strictly proper plant (no direct feed-through D)")
        controller = tustin(loop.controller, 1.0 / run.fs)
        worst = np.max(np.abs(closed_loop_poles(plant, controller, run.fs, delay)), initial=0.0)
        if worst >= 1.0:
            raise InputError("closed_loop", f"the linear closed loop is unstable at fs = {run.fs:g} Hz "
                                            f"(pole with |z| = {worst:.6g} >= 1)")
        r = run.u
        ff = feedforward(r, run.fs, run.period is not None, loop.coulomb, loop.velocity)
    u_out, y_out = _run_kernel(Phi, Gu, ss, plant.x0, plant.forces, m, h, delay, controller, r, ff,
                               run.u, noise.process, noise.y, plant.input_block, plant.output_block)
    _check_finite(y_out, run.run_id)
    u_out += noise.u  # in place: a fresh 8 MB array costs ~2 ms of page faults per 1e6 samples
    if loop is None:
        return dataclasses.replace(run, u=u_out, y=y_out, r=None)
    # Closed loop: the excitation is the reference (it keeps the excitation's unit of u); the
    # recorded u is the plant input, whose unit the config does not state.
    units = {"r": run.units["u"]} if "u" in run.units else {}
    return dataclasses.replace(run, u=u_out, y=y_out, r=run.u.copy(), units=units)


def _filter(ss: StateSpace, x: np.ndarray, fs_step: float, delay: int) -> np.ndarray:
    Phi, Gu = stepped(ss, 1.0 / fs_step)
    zero = np.zeros_like(x)
    return _run_kernel(Phi, Gu, ss, np.zeros(ss.order), [], 1, 1.0 / fs_step, delay, None, _EMPTY_1, _EMPTY_1,
                       x, zero, zero)[1]


def simulate_structure(structure: Structure, run: Run, substeps: int | None, noise: Noise) -> Run:
    """Run a block structure on ``run``: each branch's stages in series, branches summed.

    With ``substeps`` M > 1 the held input is evaluated M times per sample, so the signals between
    blocks are sampled M times finer (continuous LTI blocks only); y is then read every M-th value.
    """
    stages = [s for branch in structure.branches for s in branch if isinstance(s, StateSpace)]
    m = substeps or 1
    if m > 1 and any(s.discrete for s in stages):
        raise InputError("simulation.substeps", "a structure with discrete-time blocks runs one step per sample")
    n = run.n_samples
    x = np.repeat(run.u + noise.process, m)
    y = np.zeros_like(x)
    for i, branch in enumerate(structure.branches):
        signal = x
        for stage in branch:
            if isinstance(stage, StateSpace):
                delay = _delay(stage, run.fs, n, "model") * m
                signal = _filter(stage, signal, run.fs * m, delay)
            else:
                signal = stage(signal)
        y += signal
    y = y[::m] + noise.y
    _check_finite(y, run.run_id)
    return dataclasses.replace(run, u=run.u + noise.u, y=y, r=None)


def simulate_run(model: Plant | Structure, loop: ClosedLoop | None, run: Run, substeps: int | None,
                 noise: Noise | None = None) -> Run:
    """Simulate one run; ``noise`` defaults to none."""
    noise = noise or Noise.zero(run.n_samples)
    if isinstance(model, Structure):
        return simulate_structure(model, run, substeps, noise)
    return simulate_plant(model, loop, run, substeps, noise)
