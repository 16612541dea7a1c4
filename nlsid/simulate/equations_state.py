"""The initial states of a model written as equations, fitted to an arbitrary record's first samples.

A record cut from a longer run starts where the system was, not at the states written in the
model (:mod:`nlsid.models.equations`). As for a plant (:mod:`nlsid.simulate.initial_state`), an
arbitrary record with a measured output is simulated "as measured" from the states that fit its
first L samples best,

    x0 = argmin || y[0:L] - g(x0)[0:L] ||^2,   x0 within the states' bounds,

g(x0) the model's noise-free recorded output from x0 (offsets and output block included). The
model is nonlinear in x0, so this is Gauss-Newton from the written states: the Jacobian S (L x n)
by forward differences of the simulation (one per state, step STEP max(|x_i|, 1)), the step the
least-squares solution of S dx = r, halved up to HALVINGS times until it lowers the cost, at
most ITERATIONS steps, stopping where a step changes no state by more than TOLERANCE of its
scale. Inside a fit this runs at every evaluation (variable projection, Golub and Pereyra 1973).

L is where the states stop mattering: the samples after which every column of S at the written
states stays below :data:`~nlsid.simulate.engine.STEADY_TOLERANCE` of its largest value, found
on the first :data:`~nlsid.simulate.initial_state.RECORD_SHARE` of the record (the same rule as a
plant's slowest mode; for a linear model the same L). A state the output does not see (its
column zero) keeps its written value. Not fitted (the record runs from the written states, as
before): a periodic run (its periodic steady state), a run without a measured output, a model
whose states' influence does not decay within a quarter of the record (a pure integrator, such as
a tank without outflow: its level is an offset the record cannot tell apart), and a fit that
frees ``model.states.NAME`` (the written values are then the parameters the fit estimates:
:class:`nlsid.fit.simulation_cost.Problem`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.equations import Equations
from nlsid.simulate.engine import STEADY_TOLERANCE, simulate_equations
from nlsid.simulate.initial_state import RECORD_SHARE, InitialState
from nlsid.simulate.noise import Noise

STEP = 1e-6        # forward-difference step of a state, relative to max(|x_i|, 1)
ITERATIONS = 10    # Gauss-Newton steps at most
HALVINGS = 8       # halvings of a step that does not lower the cost
TOLERANCE = 1e-10  # a step below this (relative to max(|x_i|, 1)) in every state has converged


def _first(run: Run, length: int) -> Run:
    """The first ``length`` samples of every signal of ``run``."""
    return dataclasses.replace(run, u=run.u[:length], y=None if run.y is None else run.y[:length],
                               r=None if run.r is None else run.r[:length],
                               channels={k: v[:length] for k, v in run.channels.items()})


def _output(model: Equations, run: Run, x0: np.ndarray, substeps: int | None) -> np.ndarray:
    """The noise-free recorded output of ``model`` on ``run`` from the states ``x0``."""
    return simulate_equations(dataclasses.replace(model, x0=x0), run, substeps, Noise.zero(run.n_samples)).y


def _jacobian(model: Equations, run: Run, x0: np.ndarray, base: np.ndarray, substeps: int | None) -> np.ndarray:
    """(samples, n) forward differences of the output in each state (stepping down at an upper bound)."""
    columns = []
    for i in range(x0.size):
        step = STEP * max(abs(x0[i]), 1.0)
        if x0[i] + step > model.upper[i]:
            step = -step
        moved = x0.copy()
        moved[i] += step
        columns.append((_output(model, run, moved, substeps) - base) / step)
    return np.column_stack(columns)


def transient_length(columns: np.ndarray) -> int | None:
    """The samples L after which every nonzero column of ``columns`` (the output's sensitivities to
    the initial states over the first RECORD_SHARE of a record) stays below STEADY_TOLERANCE of its
    largest magnitude; None where one does not decay within them or none is nonzero."""
    peaks = np.max(np.abs(columns), axis=0)
    seen = peaks > 0
    if not np.any(seen):
        return None
    above = np.any(np.abs(columns[:, seen]) > STEADY_TOLERANCE * peaks[seen], axis=1)
    length = int(np.flatnonzero(above)[-1]) + 1
    return length if length < columns.shape[0] else None


def estimate(model: Equations, run: Run, substeps: int | None) -> InitialState | None:
    """The states fitted to the first samples of ``run``'s measured output (module docstring), with
    ``transient`` the change they make to the output over those samples (from the written
    states); None where none are fitted."""
    if run.period is not None or run.y is None or not model.states:
        return None
    share = int(RECORD_SHARE * run.n_samples)
    if share < 2:  # too short a record for a transient to decay in a quarter of it
        return None
    written = np.clip(np.asarray(model.x0, float), model.lower, model.upper)
    prefix = _first(run, share)
    start = _output(model, prefix, written, substeps)
    columns = _jacobian(model, prefix, written, start, substeps)
    length = transient_length(columns)
    if length is None:
        return None
    head = _first(run, length)
    seen = np.max(np.abs(columns), axis=0) > 0
    x, fitted, jacobian = written, start[:length], columns[:length]
    cost = float(np.sum((head.y - fitted) ** 2))
    for _ in range(ITERATIONS):
        step = np.zeros_like(x)
        step[seen] = np.linalg.lstsq(jacobian[:, seen], head.y - fitted, rcond=None)[0]
        for _ in range(HALVINGS + 1):
            trial = np.clip(x + step, model.lower, model.upper)
            try:
                output = _output(model, head, trial, substeps)
            except InputError:  # a trial the equations refuse (a value not finite): a shorter step
                output = None
            if output is not None and float(np.sum((head.y - output) ** 2)) < cost:
                break
            step = step / 2
        else:
            break
        converged = np.all(np.abs(trial - x) <= TOLERANCE * np.maximum(np.abs(x), 1.0))
        x, fitted, cost = trial, output, float(np.sum((head.y - output) ** 2))
        if converged:
            break
        jacobian = _jacobian(model, head, x, fitted, substeps)
    return InitialState(x, length, fitted - start[:length])


def with_initial_state(model: Equations, run: Run, substeps: int | None, noise: Noise) -> Run:
    """``run`` simulated from the states fitted to its start (:func:`estimate`), or from the
    written states where none are fitted."""
    state = estimate(model, run, substeps)
    start = model if state is None else dataclasses.replace(model, x0=state.x0)
    return simulate_equations(start, run, substeps, noise)
