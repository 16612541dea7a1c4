"""The initial states of a block structure's filters on an arbitrary record, fitted to its first samples.

A record cut from a longer run (the test part of a benchmark, a recording started while the machine
was moving) begins with every filter of a block structure in some state. Simulated from rest, the
structure misses the transient that state leaves, and a fit would bend its parameters to explain it.
So an arbitrary record with a measured output is simulated "as measured" from the stage states
(x_1, ..., x_S) (:func:`nlsid.simulate.engine.structure_stages`) that fit its first L samples best:

    (x_1, ..., x_S) = argmin sum_{n < L} ( y(n) - y_sim(n; x_1, ..., x_S) )^2.

The state of a stage that ends its branch enters the output linearly, through its free response
O_s x_s (the stage's output from the unit states, excitation zero); the states of the inner stages
(the first filter of a Wiener-Hammerstein branch, G1 in y = G2[f(G1 u)]) pass a static curve. So
the output stages' states are eliminated by linear least squares at every trial of the inner ones
(variable projection, Golub and Pereyra 1973), and the inner ones are searched by a trust-region
least-squares method (scipy's ``trf``, forward-difference Jacobian), starting from rest. Both in
coordinates w (x_s = T_s w) in which each stage's own free response is orthonormal
(:func:`_coordinates`): the states of a state-space form can differ by many decades in scale. This is
the exact (nonlinear) least-squares estimate over the window, not a linearisation; for a structure
whose every filter ends its branch (Hammerstein, parallel Hammerstein) it is one linear solve.

L is the sum over a branch's filters of the samples in which each one's slowest mode decays to
:data:`~nlsid.simulate.engine.STEADY_TOLERANCE` and of their dead times (a transient of G1 passes
G2 before it is gone), the longest branch's. Not fitted (the record is simulated from rest, as
before): a structure with a filter whose slowest mode does not decay within :data:`~nlsid.simulate.initial_state.RECORD_SHARE`
of the record, and a run without a measured output. The input a dead time holds at the start (the
excitation before the record) is not known and stays zero; only the filters' states are fitted.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from nlsid.io.run import Run
from nlsid.models.from_config import Structure
from nlsid.models.lti import StateSpace, delay_samples
from nlsid.simulate.engine import STEADY_TOLERANCE, _decay_rate, _delay, _filter, simulate_structure, structure_stages
from nlsid.simulate.initial_state import RECORD_SHARE, InitialState
from nlsid.simulate.noise import Noise

MAX_EVALUATIONS = 60  # residual evaluations of the inner states' search at most (its Jacobian's besides)


def transient_length(structure: Structure, run: Run) -> int | None:
    """L of the module docstring, or None where it exceeds RECORD_SHARE of the record (or never ends)."""

    longest = 0
    for branch in structure.branches:
        stages = [stage for stage in branch if isinstance(stage, StateSpace)]
        rates = [_decay_rate(stage, run.fs) for stage in stages]
        if any(not rate > 0 for rate in rates):
            return None
        longest = max(longest, sum(math.log(1 / STEADY_TOLERANCE) / rate * run.fs
                                   for rate in rates if math.isfinite(rate))
                      + sum(delay_samples(stage.delay, run.fs, "model.delay") for stage in stages))
    length = math.ceil(longest)
    return length if 0 < length <= RECORD_SHARE * run.n_samples else None


def _output_stages(structure: Structure) -> list[bool]:
    """For each LTI stage (engine order): does it end its branch (its state enters y linearly)?"""
    return [k == len(branch) - 1
            for branch in structure.branches for k, stage in enumerate(branch) if isinstance(stage, StateSpace)]


def _head(run: Run, noise: Noise, length: int) -> tuple[Run, Noise]:
    """The first ``length`` samples of a run and its noise."""
    cut = dataclasses.replace(run, u=run.u[:length], y=None if run.y is None else run.y[:length],
                              r=None if run.r is None else run.r[:length],
                              channels={k: v[:length] for k, v in run.channels.items()})
    return cut, Noise(noise.u[:length], noise.y[:length], noise.process[:length])


def _free_response(stage: StateSpace, fs: float, substeps: int, length: int) -> np.ndarray:
    """(length, n): the stage's output from each unit state, input zero, read every sample."""

    m = substeps
    delay = _delay(stage, fs, length, "model") * m
    zero = np.zeros(length * m)
    return np.column_stack([_filter(stage, zero, fs * m, delay, unit)[::m] for unit in np.eye(stage.order)]) \
        if stage.order else np.zeros((length, 0))


def _coordinates(response: np.ndarray) -> np.ndarray:
    """T (n, r) with x = T w: coordinates w in which the stage's free response is orthonormal
    (response = U S V^T, T = V S^-1 over the r singular values above 1e-10 of the largest). A
    state-space form's states can differ by many decades in scale (a continuous transfer
    function's controller form at a high rate); these do not, and the directions that do not
    reach the output are left out."""
    if response.shape[1] == 0:
        return np.zeros((0, 0))
    _, sv, vt = np.linalg.svd(response, full_matrices=False)
    keep = sv > 1e-10 * sv[0] if sv.size and sv[0] > 0 else np.zeros(sv.size, bool)
    return vt[keep].T / sv[keep]


def fit_states(structure: Structure, run: Run, substeps: int | None, noise: Noise) -> list[np.ndarray] | None:
    """The stage states of the module docstring, in engine order; None where none are fitted."""
    from scipy.optimize import least_squares

    stages = structure_stages(structure)
    length = transient_length(structure, run)
    if run.y is None or length is None or not any(stage.order for stage in stages):
        return None
    head, head_noise = _head(run, noise, length)
    m = substeps or 1
    outer = _output_stages(structure)
    responses = [_free_response(stage, run.fs, m, length) for stage in stages]
    maps = [_coordinates(response) for response in responses]
    basis = np.column_stack([np.zeros((length, 0))] + [r @ t for r, t, last in zip(responses, maps, outer) if last])
    sizes_in = [t.shape[1] for t, last in zip(maps, outer) if not last]
    sizes_out = [t.shape[1] for t, last in zip(maps, outer) if last]

    def states(inner: np.ndarray, linear: np.ndarray) -> list[np.ndarray]:
        parts = {False: iter(np.split(inner, np.cumsum(sizes_in)[:-1]) if sizes_in else []),
                 True: iter(np.split(linear, np.cumsum(sizes_out)[:-1]) if sizes_out else [])}
        return [t @ next(parts[last]) for t, last in zip(maps, outer)]

    def solve(inner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The output stages' coordinates given the inner ones, and the residual."""
        zero_out = np.zeros(basis.shape[1])
        with np.errstate(all="ignore"):
            y = simulate_structure(structure, head, m, head_noise, states(inner, zero_out)).y
        e = head.y - y
        if not np.all(np.isfinite(e)):
            return zero_out, np.full(length, 1e6 * (1 + float(np.max(np.abs(head.y)))))
        linear = np.linalg.lstsq(basis, e, rcond=None)[0] if basis.shape[1] else zero_out
        return linear, e - basis @ linear

    inner = np.zeros(sum(sizes_in))
    if inner.size:
        inner = least_squares(lambda v: solve(v)[1], inner, method="trf", max_nfev=MAX_EVALUATIONS).x
    return states(inner, solve(inner)[0])


def with_initial_states(structure: Structure, run: Run, substeps: int | None, noise: Noise, rest: Run) -> Run:
    """The structure on ``run`` from the stage states fitted to its measured output; ``rest`` (its
    simulation from rest) where none are fitted."""

    fitted = fit_states(structure, run, substeps, noise)
    if fitted is None:
        return rest
    return simulate_structure(structure, run, substeps, noise, fitted)


def estimate(structure: Structure, run: Run, substeps: int | None) -> InitialState | None:
    """The fitted stage states as an :class:`~nlsid.simulate.initial_state.InitialState` (noise-free
    simulation): ``x0`` the stages' states one after the other (engine order), ``transient`` what
    they change in the output over the L samples; None where none are fitted."""

    noise = Noise.zero(run.n_samples)
    fitted = fit_states(structure, run, substeps, noise)
    if fitted is None:
        return None
    length = transient_length(structure, run)
    head, head_noise = _head(run, noise, length)
    change = (simulate_structure(structure, head, substeps, head_noise, fitted).y
              - simulate_structure(structure, head, substeps, head_noise).y)
    return InitialState(np.concatenate(fitted), length, change)
