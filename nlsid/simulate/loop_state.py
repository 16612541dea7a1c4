"""The state a closed loop is in at the start of a record that starts in motion, estimated from the
record's first samples of the output y and of the drive's command u.

A record cut from a running machine starts with the plant moving, commands issued before the
record still in the drive's dead time, and the drive's own memory full: an integrator's sum, the
past positions of a velocity estimate (a two-tap difference reads y[k - 2]). Simulated from rest,
the loop replays a start-up that never happened: the command jumps, the position lags, and a fit
bends the parameters to explain it. The loop state

    z = [x(0), u[-d] .. u[-1], xc(0)]

(plant state, the d pending commands of the dead time, the drive's state in the order of
:func:`nlsid.models.controller.two_input`; :class:`nlsid.simulate.engine.LoopStart`) is estimated
by least squares on the first L samples of both recorded signals, each scaled by its standard
deviation over the record so that neither unit decides:

    z = argmin  || (y[0:L] - y_z[0:L]) / s_y ||^2 + || (u[0:L] - u_z[0:L]) / s_u ||^2,

with (y_z, u_z) the model's loop run from z. The loop's linear part (forces, blocks and offsets
aside, the reference at zero) gives the free responses O = [O_y; O_u] of each unit component of z,
and a Gauss-Newton iteration with this fixed Jacobian,

    z <- z + argmin_dz || r(z) - O dz ||,   r(z) the scaled residual of the model's own loop,

starts from z = 0 (the loop at rest) and stops when the residual no longer falls (at most
REFINEMENTS steps). For a linear loop the first step is the exact least-squares solution (Ljung
1999, System Identification, Sec. 10.1 on initial conditions); for a loop with friction it is the
estimate of its linearisation, and the steps that follow evaluate the residual of the nonlinear
loop (a Coulomb force acts from the first sample of a record in motion, not from a start at rest).
The record is then simulated from z, exactly, by :func:`nlsid.simulate.engine.simulate_plant`.

L is the samples in which the slowest mode of the sampled loop decays to
:data:`~nlsid.simulate.engine.STEADY_TOLERANCE` (:func:`nlsid.simulate.initial_state.transient_length`);
none is estimated where that exceeds a quarter of the record, or without a measured y. Without a
recorded command the estimate reads y alone. Not estimated: the state of a reference prefilter
(it starts at rest; the reference is known before the record in a set-point profile).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from nlsid.io.run import Run
from nlsid.models import blocks
from nlsid.models.from_config import ClosedLoop, Offsets, Plant
from nlsid.simulate.engine import LoopStart, _controller, simulate_plant, timing
from nlsid.simulate.initial_state import InitialState, transient_length
from nlsid.simulate.noise import Noise

REFINEMENTS = 3  # Gauss-Newton steps after the first, with the linear loop's free responses


@dataclass
class LoopExcitation(Run):
    """The run a closed loop is simulated on: ``u`` the reference (as the engine takes it) and
    ``command`` the drive output u the record measured, where it did (read only to estimate the
    loop's initial state, module docstring)."""

    command: np.ndarray | None = None


def loop_excitation(run: Run) -> LoopExcitation:
    """The excitation of a measured closed-loop run: its reference r as u, its recorded u as the command."""
    fields = {f.name: getattr(run, f.name) for f in dataclasses.fields(Run)}
    return LoopExcitation(**(fields | {"u": run.r, "r": None}), command=run.u)


@dataclass(frozen=True)
class LoopState(InitialState):
    """A closed loop's fitted initial state: the plant state ``x0`` added to the model's own, the
    pending ``commands`` of the dead time (oldest first), the drive's state ``controller``; the
    free response of the loop from it (less the loop's response from rest) in y, ``transient``,
    and in the command, ``command_transient``, over the ``samples`` it was fitted on."""

    commands: np.ndarray = field(default_factory=lambda: np.zeros(0))
    controller: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command_transient: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def command_transient_rms(self) -> float:
        return float(np.sqrt(np.mean(self.command_transient ** 2))) if self.command_transient.size else 0.0

    def summary(self) -> dict:
        """:meth:`InitialState.summary` and ``commands``, ``controller``, ``command_transient_rms``."""
        return {**super().summary(), "commands": [float(x) for x in self.commands],
                "controller": [float(x) for x in self.controller], "command_transient_rms": self.command_transient_rms}

    def start(self, plant: Plant) -> LoopStart:
        """The :class:`~nlsid.simulate.engine.LoopStart` of this state for ``plant``."""
        return LoopStart(plant.x0 + self.x0, self.commands, self.controller)


def _head(run: Run, length: int) -> Run:
    """The first ``length`` samples of an arbitrary record, its channels too."""
    return Run(run.run_id, run.fs, "arbitrary", run.u[:length], y=None, units=dict(run.units),
               channels={name: x[:length] for name, x in run.channels.items()})


def _sizes(plant: Plant, loop: ClosedLoop, run: Run) -> tuple[int, int, int]:
    """(plant states, pending commands, drive states) of the loop at the run's rate."""
    d = timing(plant, run.fs, run.n_samples, True, loop.computation_delay).delay
    return plant.ss.order, d, _controller(loop, run.fs)[0].shape[0]


def _split(z: np.ndarray, sizes: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n, d, _ = sizes
    return z[:n], z[n:n + d], z[n + d:]


def free_responses(plant: Plant, loop: ClosedLoop, run: Run, length: int) -> tuple[np.ndarray, np.ndarray]:
    """(O_y, O_u), each (length, n + d + nc): the recorded y and command u of the loop's linear part
    (module docstring) from each unit component of the loop state, the reference at zero."""
    linear = dataclasses.replace(plant, forces=[], input_block=blocks.encode(None), output_block=blocks.encode(None),
                                 offsets=Offsets(), force_bias=0.0, x0=np.zeros(plant.ss.order))
    sizes = _sizes(plant, loop, run)
    # zero channels: the drive's added excitation and the plant's input channels take no part
    rest = Run(run.run_id, run.fs, "arbitrary", np.zeros(length),
               channels={name: np.zeros(length) for name in run.channels})
    ys, us = [], []
    for unit in np.eye(sum(sizes)):
        out = simulate_plant(linear, loop, rest, 1, Noise.zero(length), LoopStart(*_split(unit, sizes)))
        ys.append(out.y)
        us.append(out.u)
    empty = np.zeros((length, 0))
    return (np.column_stack(ys), np.column_stack(us)) if ys else (empty, empty)


def _scale(x: np.ndarray) -> float:
    s = float(np.std(x))
    return s if s > 0 else 1.0


def estimate(plant: Plant, loop: ClosedLoop, run: Run, substeps: int | None) -> LoopState | None:
    """The loop state fitted to the start of ``run`` (module docstring): ``run.u`` the reference,
    ``run.y`` the measured output, the recorded command from a :class:`LoopExcitation`; None where
    none is estimated."""
    length = transient_length(plant, loop, run)
    if length is None or run.y is None:
        return None
    sizes = _sizes(plant, loop, run)
    if not sum(sizes):
        return None
    command = getattr(run, "command", None)
    O_y, O_u = free_responses(plant, loop, run, length)
    head = _head(run, length)
    s_y = _scale(run.y)
    targets, columns = [run.y[:length] / s_y], [O_y / s_y]
    if command is not None:
        s_u = _scale(command)
        targets.append(command[:length] / s_u)
        columns.append(O_u / s_u)
    target, basis = np.concatenate(targets), np.vstack(columns)

    def simulated(z: np.ndarray) -> Run:
        start = LoopStart(plant.x0 + _split(z, sizes)[0], *_split(z, sizes)[1:])
        return simulate_plant(plant, loop, head, substeps, Noise.zero(length), start)

    def residual(out: Run) -> np.ndarray:
        parts = [out.y / s_y] + ([out.u / s_u] if command is not None else [])
        return target - np.concatenate(parts)

    rest = simulate_plant(plant, loop, head, substeps, Noise.zero(length))
    z, best = np.zeros(sum(sizes)), residual(rest)
    cost = float(best @ best)
    for _ in range(1 + REFINEMENTS):
        step, *_ = np.linalg.lstsq(basis, best, rcond=None)
        trial = z + step
        r = residual(out := simulated(trial))
        if not float(r @ r) < cost:
            break
        z, best, cost, fitted = trial, r, float(r @ r), out
    if not z.any():
        return None
    x0, commands, controller = _split(z, sizes)
    return LoopState(x0, length, fitted.y - rest.y, commands, controller, fitted.u - rest.u)


def simulate_from_start(plant: Plant, loop: ClosedLoop, run: Run, substeps: int | None, noise: Noise) -> Run:
    """``run`` simulated by the loop from the state fitted to its start (:func:`estimate`), from
    rest where none is estimated."""
    state = estimate(plant, loop, run, substeps)
    return simulate_plant(plant, loop, run, substeps, noise, None if state is None else state.start(plant))
