"""A PNLSS model (:mod:`nlsid.models.pnlss`) on measured runs as they were measured, and the
exact sensitivities of its output (``docs/pnlss.md``).

* A periodic run: its mean steady-state period, simulated in periodic steady state. The steady
  state is found by shooting (:func:`periodic_state`: Newton on the state that one period brings
  back to itself, with the period's monodromy matrix from the state sensitivities), and the
  Jacobian is the total derivative through it (:func:`steady_jacobian`): one period simulated
  where a lead-in of as many periods as the slowest mode needs to decay to STEADY_TOLERANCE was
  (up to MAX_LEAD_PERIODS for a lightly damped model). Where shooting does not settle, the orbit
  is not attracting, or the record's Jacobian would exceed SHOOTING_BYTES, the period is
  repeated ahead as a lead-in (:func:`lead_periods`), whose output is discarded. With P >= 2
  steady periods y_p and the model's periodic response y_sim,
  sum_p ||y_sim - y_p||^2 = P ||y_sim - mean_p y_p||^2 + sum_p ||y_p - mean_p y_p||^2,
  so the record keeps the mean period, its weight P and the last sum (``within``, which does not
  depend on the model): costs, Jacobians and rms values over the mean period, weighted, are those
  of every period, at 1/P of the simulation and of the normal matrix's work. The input is the
  mean period too (its measurement noise averaged like the output's).
* An arbitrary run: whole, from an initial state x0, fitted to its measured output over its first
  :func:`transient_samples` (:func:`estimate_x0`: Gauss-Newton on x0 alone, with the x0 columns of
  the exact sensitivities).

:func:`jacobian_blocks` yields the Jacobian rows of a record in chunks (the kernel
:func:`nlsid.simulate.pnlss_kernels.sensitivities` carries the state and its sensitivities from
one chunk to the next), so a long record never holds its whole Jacobian.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.pnlss import Pnlss
from nlsid.simulate.channels import weighted_sum
from nlsid.simulate.pnlss_kernels import sensitivities, simulate

STEADY_TOLERANCE = 1e-6  # the linear part's slowest mode decays to this within the lead-in
MAX_LEAD_PERIODS = 20
CHUNK_BYTES = 32 * 2 ** 20  # Jacobian rows are formed in chunks of at most this size
X0_ITERATIONS = 6
SHOOTING_ITERATIONS = 20  # Newton steps on a periodic record's steady state at most
SHOOTING_TOLERANCE = 1e-11  # a Newton correction this small relative to the state ends them
SHOOTING_BYTES = 64 * 2 ** 20  # a periodic record's Jacobian held whole for the steady-state correction, at most
DIVERGED = 1e150  # a state beyond this has diverged (as the other models' simulations)




@dataclass(eq=False)
class Record:
    """A run prepared for the fit: ``u`` (the mean steady-state period of a periodic run, or the
    whole arbitrary record), the measured ``y`` over it, ``period`` (None: arbitrary, its initial
    state fitted); ``weight``, the periods averaged (P), and ``within``, sum_p ||y_p - mean y||^2
    over them (module docstring): a squared error e'e over the record stands for
    ``weight * e'e + within`` over the run's periods."""

    run_id: str
    u: np.ndarray
    y: np.ndarray
    period: int | None
    weight: int = 1
    within: float = 0.0
    steady: np.ndarray | None = None  # the last periodic steady state found (:func:`periodic_state`'s start)

    @property
    def arbitrary(self) -> bool:
        return self.period is None

    @property
    def samples(self) -> int:
        """The run's samples the record stands for (``weight`` x its own)."""
        return self.weight * int(self.y.size)

    def squared_error(self, e: np.ndarray) -> float:
        """The squared error over the run's samples of the residual ``e`` over the record."""
        return self.weight * float(e @ e) + self.within

    def floor(self) -> float | None:
        """The noise variance per sample, from the spread of the periods about their mean
        (within / ((P - 1) N)); None for an arbitrary record or a single period."""
        if self.weight < 2:
            return None
        return self.within / ((self.weight - 1) * self.y.size)


def records(runs: Sequence[Run], where: str) -> list[Record]:
    """The runs as :class:`Record`: a periodic run's mean steady-state period (of the whole periods
    after its transient periods, with their count and spread: module docstring), an arbitrary run
    whole; each needs a measured y."""
    out = []
    for run in runs:
        if run.y is None:
            raise InputError(f"{where}: run {run.run_id}", "has no measured output y")
        if run.period is not None and run.n_periods >= 1:
            u, y = run.periods("u").astype(float), run.periods("y").astype(float)
            mean = y.mean(axis=0)
            out.append(Record(run.run_id, np.ascontiguousarray(u.mean(axis=0)), np.ascontiguousarray(mean),
                              int(run.period), run.n_periods, float(np.sum((y - mean) ** 2))))
        else:
            out.append(Record(run.run_id, np.ascontiguousarray(run.u, dtype=float),
                              np.ascontiguousarray(run.y, dtype=float), None))
    return out


def lead_periods(model: Pnlss, period: int) -> int:
    """Periods ahead of a periodic record in which the linear part's slowest mode decays to
    STEADY_TOLERANCE: ceil(ln(tol) / ln(rho) / period) for the spectral radius rho of A, at least
    1 (the nonlinear part's transient) and at most MAX_LEAD_PERIODS."""
    rho = model.spectral_radius()
    if rho >= 1.0:
        return MAX_LEAD_PERIODS
    if rho <= 0.0:
        return 1
    samples = math.log(STEADY_TOLERANCE) / math.log(rho)
    return int(min(MAX_LEAD_PERIODS, max(1, math.ceil(samples / period))))


def driven_input(model: Pnlss, record: Record) -> tuple[np.ndarray, int]:
    """The input the kernel runs on (lead-in ahead for a periodic record, input offset added) and
    the lead samples to discard."""
    if record.arbitrary:
        return record.u + model.input_offset, 0
    count = lead_periods(model, record.period)
    u = np.concatenate([np.tile(record.u[:record.period], count), record.u])
    return u + model.input_offset, count * record.period


def shoots(model: Pnlss, record: Record) -> bool:
    """Whether a record's periodic steady state is found by shooting: every periodic record. The
    costs and the Jacobians of one fit then come from one steady state (the lead-in's is exact
    only to STEADY_TOLERANCE, at most MAX_LEAD_PERIODS ahead: 6e-4 apart on a lightly damped
    stage), and an iteration costs less: ``benchmarks/pnlss_periodic_steady_state.py`` measured
    the Jacobian 1.6 times and a cost 0.8 times as fast as with leads of 2 and 3 periods, 6 to 9
    and 3 to 5 times with leads of 14 and 20."""
    return not record.arbitrary


def periodic_state(model: Pnlss, record: Record, bound: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The periodic steady state of a periodic record by shooting (module docstring): the state
    x_ss at the start of a period that one period of the input brings back to itself, with the
    period's monodromy M = dx[N]/dx[0] there and the output over the record from x_ss. None where
    Newton's iteration does not settle within SHOOTING_ITERATIONS, the orbit is not attracting
    (a multiplier of M on or outside the unit circle: the lead-in would not reach it either) or
    the simulation leaves ``bound``; the caller then takes the lead-in.

    Newton on x -> Phi(x) - x, Phi the state after one period from x: x += (I - M)^-1 (Phi(x) - x),
    M and Phi from one pass of the kernel with the n state sensitivities alone; it starts from
    the record's last steady state (``record.steady``), so a fit's next iterate usually takes one
    or two passes. It ends where the correction is below SHOOTING_TOLERANCE of the state's size:
    the state error is then of the order of its square (quadratic convergence)."""
    n, N = model.order, record.period
    u = record.u[:N] + model.input_offset
    matrices = model.kernel_matrices()
    x = np.zeros(n) if record.steady is None else record.steady.copy()
    y, Jx = np.empty(N), np.empty((N, n))
    for _ in range(SHOOTING_ITERATIONS):
        x_end, M = x.copy(), np.eye(n)
        if sensitivities(*matrices, model.lfr, u, x_end, M, False, float(bound), y, Jx) >= 0:
            return None
        residual = x_end - x
        scale = max(float(np.max(np.abs(x))), float(np.max(np.abs(x_end))), np.finfo(float).tiny)
        if float(np.max(np.abs(residual))) <= SHOOTING_TOLERANCE * scale:
            if np.max(np.abs(np.linalg.eigvals(M))) >= 1.0:
                return None
            record.steady = x.copy()
            if record.u.shape[0] > N:  # a record of several periods: the rest from the end of the first
                rest = np.empty(record.u.shape[0] - N)
                if simulate(*matrices, record.u[N:] + model.input_offset, x_end, float(bound), rest) >= 0:
                    return None
                y = np.concatenate([y, rest])
            return x, M, y + model.output_offset
        try:
            x = x + np.linalg.solve(np.eye(n) - M, residual)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(x)):
            return None
    return None


def simulate_record(model: Pnlss, record: Record, x0: np.ndarray | None, bound: float) -> np.ndarray | None:
    """The simulated output over the record (None if it diverged): steady state for a periodic
    record (by shooting, else after a lead-in: :func:`periodic_state`), from ``x0`` for an
    arbitrary one."""
    if shoots(model, record):
        steady = periodic_state(model, record, bound)
        if steady is not None:
            return steady[2]
    u, lead = driven_input(model, record)
    start = np.zeros(model.order) if x0 is None or not record.arbitrary else np.asarray(x0, dtype=float)
    y = np.empty(u.shape[0])
    if simulate(*model.kernel_matrices(), u, start, float(bound), y) >= 0:
        return None
    out = y[lead:]
    out += model.output_offset
    return out


def _chunk_rows(columns: int) -> int:
    return int(max(256, min(65536, CHUNK_BYTES // (8 * max(columns, 1)))))


def jacobian_blocks(model: Pnlss, record: Record, x0: np.ndarray | None, bound: float, full: bool = True,
                    samples: int | None = None):
    """Yield (residual, J) chunks over the record's first ``samples`` (default all; lead-in rows
    dropped): residual = y_sim - y and the Jacobian rows in the kernel's column layout
    (:mod:`nlsid.simulate.pnlss_kernels`: x0, A, B, E, [Cz, Dz of the LFR form], C, D, F; x0
    alone if not ``full``). Raises FloatingPointError if the simulation diverges."""
    n = model.order
    matrices = model.kernel_matrices()
    mixing = model.lfr_inputs * (n + 1)
    ps = n + (n * n + n + n * matrices[6].shape[0] + mixing if full else 0)
    width = ps + (n + 1 + matrices[7].shape[0] if full else 0)
    if shoots(model, record) and full and samples is None and record.u.shape[0] * width * 8 <= SHOOTING_BYTES:
        steady = periodic_state(model, record, bound)
        if steady is not None:
            yield steady_jacobian(model, record, steady[0], ps, width, bound)
            return
    u, lead = driven_input(model, record)
    if samples is not None:
        u = u[:lead + samples]
    x = np.zeros(n) if x0 is None or not record.arbitrary else np.array(x0, dtype=float)
    S = np.zeros((n, ps))
    S[:, :n] = np.eye(n)
    rows = _chunk_rows(width)
    J = np.empty((min(rows, u.shape[0]), width))
    y = np.empty(J.shape[0])
    for start in range(0, u.shape[0], rows):
        stop = min(start + rows, u.shape[0])
        m = stop - start
        t = sensitivities(*matrices, model.lfr, u[start:stop], x, S, full, float(bound), y[:m], J[:m])
        if t >= 0:
            raise FloatingPointError(f"diverged at sample {start + t}")
        first = max(lead - start, 0)
        if first >= m:
            continue
        measured = record.y[start + first - lead:stop - lead]
        yield y[first:m] + model.output_offset - measured, J[first:m]


def steady_jacobian(model: Pnlss, record: Record, steady: np.ndarray, ps: int, width: int,
                    bound: float) -> tuple[np.ndarray, np.ndarray]:
    """(residual, J) over a periodic record in periodic steady state, J the total derivative.

    One pass from the steady state x_ss with the state sensitivities started at [I 0] gives the
    rows dy/dx0 and dy/dtheta at x0 held, and after one period S = [M  dPhi/dtheta]. The steady
    state moves with theta: (I - M) dx_ss/dtheta = dPhi/dtheta (differentiating x_ss =
    Phi(x_ss, theta)), so dy/dtheta = dy/dtheta|x0 + dy/dx0 dx_ss/dtheta, added to the state
    parameters' columns (the output equation's do not move the state)."""
    n, N = model.order, record.period
    matrices = model.kernel_matrices()
    u = record.u + model.input_offset
    x = steady.copy()
    S = np.zeros((n, ps))
    S[:, :n] = np.eye(n)
    J, y = np.empty((u.shape[0], width)), np.empty(u.shape[0])
    if sensitivities(*matrices, model.lfr, u[:N], x, S, True, float(bound), y[:N], J[:N]) >= 0:
        raise FloatingPointError("diverged in the steady period")
    moves = np.linalg.solve(np.eye(n) - S[:, :n], S[:, n:])
    if u.shape[0] > N and sensitivities(*matrices, model.lfr, u[N:], x, S, True, float(bound), y[N:], J[N:]) >= 0:
        raise FloatingPointError("diverged in the steady periods")
    J[:, n:ps] += J[:, :n] @ moves
    return y + model.output_offset - record.y, J


def transient_samples(model: Pnlss, limit: int) -> int:
    """Samples in which the linear part's slowest mode decays to STEADY_TOLERANCE (at least 10 n,
    at most ``limit``): the part of a record that tells its initial state."""
    rho = model.spectral_radius()
    if rho >= 1.0:
        return limit
    samples = math.log(STEADY_TOLERANCE) / math.log(rho) if rho > 0 else 1.0
    return int(min(limit, max(10 * model.order, math.ceil(samples))))


def estimate_x0(model: Pnlss, record: Record, bound: float = DIVERGED, start: np.ndarray | None = None) -> np.ndarray | None:
    """The initial state of an arbitrary record that fits its measured output best over its first
    :func:`transient_samples` (Gauss-Newton on x0 alone, from ``start`` or rest; exact in one step
    for a linear model); None for a periodic record or a divergence."""
    if not record.arbitrary:
        return None
    n = model.order
    length = transient_samples(model, record.y.size)
    x0 = np.zeros(n) if start is None else np.array(start, dtype=float)
    last = math.inf
    for _ in range(X0_ITERATIONS):
        H, g, cost = np.zeros((n, n)), np.zeros(n), 0.0
        try:
            for e, J in jacobian_blocks(model, record, x0, bound, full=False, samples=length):
                H += J.T @ J
                g += J.T @ e
                cost += float(e @ e)
        except FloatingPointError:
            return None
        if not cost < last * (1 - 1e-6):
            break
        last = cost
        x0 = x0 + np.linalg.lstsq(H, -g, rcond=1e-12)[0]
    return x0


def rms_on(model: Pnlss, recs: Sequence[Record], bound: float, starts: dict | None = None) -> float:
    """rms of the simulation error over the records (initial states fitted, each from its value in
    ``starts`` by run id, which is updated; inf if one diverges)."""
    total, count = 0.0, 0
    starts = {} if starts is None else starts
    for rec in recs:
        x0 = estimate_x0(model, rec, bound, starts.get(rec.run_id))
        if x0 is not None:
            starts[rec.run_id] = x0
        if rec.arbitrary and x0 is None:
            return math.inf
        y = simulate_record(model, rec, x0, bound)
        if y is None:
            return math.inf
        total += rec.squared_error(y - rec.y)
        count += rec.samples
    return math.sqrt(total / count) if count else math.inf


def fitted_input(model: Pnlss, run: Run, process: np.ndarray | None = None) -> np.ndarray:
    """The model's input on ``run`` before its own input offset: u + the measured channels of
    ``model.input_channels`` times their gains (+ process noise; a channel the run lacks refused,
    or zero: :func:`nlsid.simulate.channels.weighted_sum`); checks the sample rate."""
    if abs(run.fs - model.fs) > 1e-9 * model.fs:
        raise InputError("model.fs", f"the PNLSS model is discrete at {model.fs:g} Hz; run {run.run_id} is sampled "
                                     f"at {run.fs:g} Hz")
    u = np.array(run.u, dtype=float)
    u += weighted_sum(dict(model.input_channels), frozenset(model.zero_if_absent), run, "model.input_channels")
    if process is not None:
        u += process
    return u


def simulate_measured(model: Pnlss, run: Run, steady: bool, process: np.ndarray | None = None) -> np.ndarray:
    """The model's noise-free output on ``run`` (output offset included). ``steady`` (the run as
    it was measured): a periodic run without transient periods in periodic steady state (every
    period, after :func:`lead_periods` periods ahead); an arbitrary run with a measured y from the
    initial state fitted to it (:func:`estimate_x0`). Otherwise from rest. Raises InputError if the
    simulation diverges."""
    u = fitted_input(model, run, process)
    if steady and run.period is not None and not run.transient_periods and run.n_samples >= run.period:
        count = lead_periods(model, run.period)
        y, t = model.try_simulate(np.concatenate([np.tile(u[:run.period], count), u]), None, DIVERGED)
        y = y[count * run.period:]
    elif steady and run.period is None and run.y is not None:
        record = Record(run.run_id, u, np.asarray(run.y, dtype=float), None)
        x0 = estimate_x0(model, record, DIVERGED)
        y, t = model.try_simulate(u, x0, DIVERGED)
    else:
        y, t = model.try_simulate(u, None, DIVERGED)
    if t >= 0:
        raise InputError("model", f"run {run.run_id}: the PNLSS simulation diverged at sample {t}")
    return y


def simulate_pnlss(model: Pnlss, run: Run, substeps: int | None, noise, steady: bool) -> Run:
    """``run`` through the model (:func:`simulate_measured`), with the measurement noise ``noise``
    (:class:`nlsid.simulate.noise.Noise`) added to u and y, its process noise to the input. One
    step per sample: ``substeps`` must be None or 1."""
    if substeps not in (None, 1):
        raise InputError("simulation.substeps", "a discrete-time model runs one step per sample; remove substeps")
    y = simulate_measured(model, run, steady, noise.process) + noise.y
    return dataclasses.replace(run, u=run.u + noise.u, y=y, r=None)
