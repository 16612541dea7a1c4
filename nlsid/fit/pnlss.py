"""Fitting a PNLSS model (:mod:`nlsid.models.pnlss`) to measured runs by minimising the simulation
error (Paduart et al., Automatica 46, 2010, Sec. 4):

    theta_hat = argmin_theta sum_runs sum_t (y_sim(t; theta) - y(t))^2,

theta = the coefficients of A, B, C, D, E, F (Cz, Dz of the LFR form), the output offset (a constant
is not a monomial; ``fit_offset``) and the initial state of each arbitrary run.

* Start: a linear model (:func:`nlsid.models.pnlss.from_linear`: the BLA's fit, balanced), E = F = 0.
  Stage "linear": A, B, C, D (and the initial states) first, E and F held at zero; stage
  "nonlinear_states" (monomials with the input in them: the start's linear part, E and F of the
  monomials of the states alone free), then "nonlinear": all coefficients. The LFR form (monomials
  of z = Cz x + Dz u) has no states-only stage: after the linear stage its combinations start as
  the linear output (:func:`lfr_combinations`), then all coefficients, Cz and Dz included, are free. A start whose nonlinear terms make the simulation diverge has them
  shrunk tenfold until it does not (stated in the notes).
* Levenberg-Marquardt with the exact Jacobian (:mod:`nlsid.simulate.pnlss_kernels`, forward
  sensitivities). The columns are normalised to unit length (parameter scaling); the normal matrix
  H = J'J of the normalised Jacobian is decomposed once per iteration, H = V diag(s) V', so that
  every damping tried costs one simulation: step = -V diag(1 / (s + lambda)) V' J'e, directions
  with s below S_FLOOR s_max left out (the n^2 directions of a state transformation, along which
  the output does not change, and numerically void ones). lambda = mu s_max; an accepted step
  divides mu by 3, a rejected one multiplies it by 10. A trial whose simulation leaves the bound
  (:data:`BOUND_FACTOR` times the largest state of the start) or is not finite is rejected.
* Periodic runs: their mean steady period, weighted by the periods averaged (the same cost,
  Jacobian and rms as over every period, at a fraction of the work:
  :mod:`nlsid.simulate.pnlss_runs`), simulated in periodic steady state (the period repeated
  ahead as a lead-in: as many periods as the linear part needs to decay to 1e-6, at least 1, at
  most 20, the lead samples discarded); arbitrary runs: from their initial state, a parameter of
  the fit.
* Early stopping (the number of iterations, hence how far the nonlinear terms are fitted, chosen
  on validation data): every accepted iterate is simulated on the validation runs (their initial
  states fitted to their output, arbitrary ones; periodic ones in steady state) and the iterate
  with the lowest validation rms is the result, the linear iterates and the start included; the
  fit stops after ``patience`` iterates without a lower one in which the estimation error fell by
  less than PROGRESS (overfitting, not a plateau: :func:`_overfitting`). Without validation runs the result is the
  last iterate (the lowest estimation error).
* At the noise floor: where every validation run is periodic with two periods or more, their
  noise is known (the spread of the periods about their mean: :meth:`Record.floor`), and so is
  the validation rms a model without error would have, sigma. The fit stops, with every later
  stage, at the first iterate whose validation rms is within AT_FLOOR_DB of it: later iterates
  could lower it by less than that, and only by fitting the validation noise.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.pnlss import Pnlss
from nlsid.simulate.pnlss_runs import Record, driven_input, estimate_x0, jacobian_blocks, records, rms_on, simulate_record

S_FLOOR = 1e-12          # eigenvalues of the normalised J'J below this share of the largest are left out
JACOBIAN_DIVERGED = "jacobian diverged"  # a status: no step could be formed at the last iterate
BOUND_FACTOR = 1e3       # a simulated state beyond this times the start's largest |x| counts as diverged
MU_START = 1e-3
MU_MAX = 1e12
MAX_REJECTED = 14        # rejected trials per iteration before the fit stops (mu grows 10x per trial)
CONVERGED = 1e-10        # relative cost decrease below which an accepted step ends the stage
WORSE = 1.25            # a validation rms this much above the lowest is overfitting, whatever the estimation error does
PROGRESS = 0.01          # early stopping needs the estimation rms to fall less than this over the patience
AT_FLOOR_DB = 0.1        # a validation rms this close to the validation runs' noise ends the fit
AT_FLOOR = "at the noise floor"


@dataclass
class Iteration:
    """One accepted iterate: its stage (``start``, ``linear``, ``nonlinear``), its number within
    the stage, the rms simulation errors on the estimation and validation runs (None without
    validation runs; inf where the simulation diverged) and the damping mu that produced it."""

    stage: str
    number: int
    estimation_rms: float
    validation_rms: float | None
    mu: float

    def as_dict(self) -> dict:
        return {"stage": self.stage, "iteration": self.number, "estimation_rms": self.estimation_rms,
                "validation_rms": self.validation_rms, "mu": self.mu}


@dataclass
class PnlssFit:
    """The result of :func:`fit_pnlss`.

    Attributes
    ----------
    model : the chosen model (:attr:`chosen`).
    start : the start model (after any shrinking of its nonlinear terms).
    linear : the best linear iterate (E = F = 0; the start if no linear stage ran).
    iterations : every accepted iterate, in order (:class:`Iteration`).
    chosen : index into ``iterations`` of the model returned.
    reason : why it was chosen (a sentence).
    status : how the fit ended: ``converged``, ``stopped early`` (validation error no longer
        falling), ``iteration limit``, ``no decrease`` (no trial step lowered the cost), or
        ``failed`` (the start diverges even without nonlinear terms: model is the start, errors inf),
        or ``jacobian diverged`` (the sensitivity simulation of an iterate whose cost was finite left
        the state bound, so no further step could be formed: the iterates before it stand).
    notes : further statements (shrunk start, realisation, lead-in periods).
    initial_states : the fitted initial state of each estimation run (None for a periodic run).
    seconds : the wall time of the fit; jacobian_rate : samples x parameters per second of the
        Jacobian computations (kernel and normal matrix).
    """

    model: Pnlss
    start: Pnlss
    linear: Pnlss
    iterations: list[Iteration]
    chosen: int
    reason: str
    status: str
    notes: list[str] = field(default_factory=list)
    initial_states: list = field(default_factory=list)
    seconds: float = 0.0
    jacobian_rate: float = 0.0

    @property
    def estimation_rms(self) -> float:
        return self.iterations[self.chosen].estimation_rms

    @property
    def validation_rms(self) -> float | None:
        return self.iterations[self.chosen].validation_rms

    def best_of(self, stage: str) -> Iteration | None:
        """The iterate of ``stage`` with the lowest validation rms (estimation rms without validation)."""
        items = [it for it in self.iterations if it.stage == stage]
        if not items:
            return None
        key = (lambda it: it.validation_rms) if items[0].validation_rms is not None else (lambda it: it.estimation_rms)
        return min(items, key=key)

    def summary(self) -> dict:
        """The numbers of the fit as a JSON-ready dict (documented in docs/formats.md)."""
        chosen = self.iterations[self.chosen]
        lin = self.best_of("linear") or self.iterations[0]
        return {"status": self.status, "reason": self.reason, "chosen": chosen.as_dict(),
                "estimation_rms": chosen.estimation_rms, "validation_rms": chosen.validation_rms,
                "linear_estimation_rms": lin.estimation_rms, "linear_validation_rms": lin.validation_rms,
                "start_estimation_rms": self.iterations[0].estimation_rms,
                "start_validation_rms": self.iterations[0].validation_rms,
                "states": self.model.order, "state_degrees": list(self.model.state_degrees),
                "output_degrees": list(self.model.output_degrees), "with_input": self.model.with_input,
                "form": "lfr" if self.model.lfr else "full", "lfr_inputs": self.model.lfr_inputs,
                "parameters": self.model.n_parameters, "notes": list(self.notes),
                "seconds": self.seconds, "jacobian_rate": self.jacobian_rate,
                "iterations": [it.as_dict() for it in self.iterations]}


# --------------------------------------------------------------------------------------------------
# parameters


def global_vector(model: Pnlss) -> np.ndarray:
    """theta in the kernel's column order after x0: A (row-major), B, E (row-major), [Cz
    (row-major), Dz of the LFR form], C, D, F."""
    mixing = [model.Cz.ravel(), model.Dz] if model.lfr else []
    return np.concatenate([model.A.ravel(), model.B, model.E.ravel(), *mixing, model.C, [model.D], model.F])


def with_vector(model: Pnlss, theta: np.ndarray) -> Pnlss:
    """``model`` with the coefficients of :func:`global_vector` set to ``theta``."""
    n, nz, nh, nv = model.order, model.E.shape[1], model.F.size, model.lfr_inputs
    cuts = np.cumsum([n * n, n, n * nz, nv * n, nv, n, 1, nh])
    A, B, E, Cz, Dz, C, D, F, _ = np.split(np.asarray(theta, dtype=float), cuts)
    mixing = {"Cz": Cz.reshape(nv, n).copy(), "Dz": Dz.copy()} if model.lfr else {}
    return model.replace(A=A.reshape(n, n).copy(), B=B.copy(), E=E.reshape(n, nz).copy(), C=C.copy(),
                         D=float(D[0]), F=F.copy(), **mixing)


def linear_indices(model: Pnlss) -> np.ndarray:
    """Positions of A, B, C, D in :func:`global_vector`."""
    n, nz = model.order, model.E.shape[1]
    ab = np.arange(n * n + n)
    cd = n * n + n + n * nz + model.lfr_inputs * (n + 1) + np.arange(n + 1)
    return np.concatenate([ab, cd])


def state_term_indices(model: Pnlss) -> np.ndarray:
    """Positions in :func:`global_vector` of A, B, C, D and of the coefficients of E and F whose
    monomials hold no power of the input (all of them with ``with_input`` False)."""
    n, nz = model.order, model.E.shape[1]
    if not model.with_input:
        return np.arange(global_vector(model).size)
    free_z = model.state_exponents[:, -1] == 0
    free_h = model.output_exponents[:, -1] == 0
    e_cols = n * n + n + (np.arange(n)[:, None] * nz + np.flatnonzero(free_z)[None, :]).ravel()
    f_cols = n * n + n + n * nz + n + 1 + np.flatnonzero(free_h)
    return np.sort(np.concatenate([linear_indices(model), e_cols, f_cols]))


# --------------------------------------------------------------------------------------------------
# Levenberg-Marquardt


class _Problem:
    """The cost and normal equations of one stage over the estimation records. LM parameter order:
    the ``active`` coefficients of :func:`global_vector`, the output offset (with ``offset``), then
    the initial state of each arbitrary record."""

    def __init__(self, records_: list[Record], active: np.ndarray, bound: float, offset: bool = False):
        self.records = records_
        self.active = active
        self.bound = bound
        self.offset = bool(offset)
        self.globals = active.size + (1 if offset else 0)
        self.arbitrary = [i for i, r in enumerate(records_) if r.arbitrary]
        self.jacobian_seconds = 0.0
        self.jacobian_work = 0.0

    def size(self, model: Pnlss) -> int:
        return self.globals + model.order * len(self.arbitrary)

    def unpack(self, base: Pnlss, theta0: np.ndarray, x0s: list, delta: np.ndarray) -> tuple[Pnlss, list]:
        n = base.order
        theta = theta0.copy()
        theta[self.active] += delta[:self.active.size]
        x0s = [None if x is None else x.copy() for x in x0s]
        for k, i in enumerate(self.arbitrary):
            x0s[i] = x0s[i] + delta[self.globals + k * n:self.globals + (k + 1) * n]
        model = with_vector(base, theta)
        if self.offset:
            model = model.replace(output_offset=base.output_offset + float(delta[self.active.size]))
        return model, x0s

    def cost(self, model: Pnlss, x0s: list) -> float:
        """Sum of squared simulation errors over the records (inf if one diverges)."""
        def one(item) -> float:
            rec, x0 = item
            y = simulate_record(model, rec, x0, self.bound)
            if y is None:
                return math.inf
            return rec.squared_error(y - rec.y)

        total = sum(in_threads(one, list(zip(self.records, x0s))))
        return total if math.isfinite(total) else math.inf

    def _columns(self, model: Pnlss, i: int) -> tuple:
        """The kernel columns taken from record i's Jacobian (None: all, in kernel order) and their
        places in the LM parameter vector (x0 of an arbitrary record after the global ones)."""
        n = model.order
        every = self.active.size == global_vector(model).size
        if self.records[i].arbitrary:
            k = self.arbitrary.index(i)
            x_cols = self.globals + k * n + np.arange(n)
            columns = None if every else np.concatenate([np.arange(n), n + self.active])
            return columns, np.concatenate([x_cols, np.arange(self.active.size)])
        return (slice(n, None) if every else n + self.active), np.arange(self.active.size)

    def normal_equations(self, model: Pnlss, x0s: list) -> tuple[np.ndarray, np.ndarray, float]:
        """H = J'J, g = J'e and the cost e'e over the records (one thread per record), J in the LM
        parameter order."""
        from scipy.linalg.blas import dsyrk

        clock = time.perf_counter()

        def one(i: int):
            columns, index = self._columns(model, i)
            block, gb, cost, work = np.zeros((index.size, index.size)), np.zeros(index.size), 0.0, 0
            sums, e_sum, rows = np.zeros(index.size), 0.0, 0   # the offset's column of ones: its products
            record = self.records[i]
            for e, J in jacobian_blocks(model, record, x0s[i], self.bound):
                Jc = J if columns is None else np.ascontiguousarray(J[:, columns])
                block += dsyrk(1.0, Jc.T, trans=0, lower=0)  # J'J, upper triangle; Jc.T is Fortran-ordered
                gb += Jc.T @ e
                cost += float(e @ e)
                work += Jc.shape[0] * Jc.shape[1]
                if self.offset:
                    sums += Jc.sum(axis=0)
                    e_sum += float(e.sum())
                    rows += e.size
            w = record.weight  # a mean period stands for its P periods (nlsid.simulate.pnlss_runs)
            block = np.triu(block) + np.triu(block, 1).T
            return index, w * block, w * gb, w * cost + record.within, work, w * sums, w * e_sum, w * rows

        p = self.size(model)
        o = self.active.size  # the offset's place (with ``offset``)
        H, g, cost = np.zeros((p, p)), np.zeros(p), 0.0
        for index, block, gb, part, work, sums, e_sum, rows in in_threads(one, range(len(self.records))):
            H[np.ix_(index, index)] += block
            g[index] += gb
            cost += part
            self.jacobian_work += work
            if self.offset:
                H[o, index] += sums
                H[index, o] += sums
                H[o, o] += rows
                g[o] += e_sum
        self.jacobian_seconds += time.perf_counter() - clock
        return H, g, cost


def in_threads(function, items) -> list:
    """[function(item) for item in items], in :func:`nlsid.simulate.threads.thread_count` threads
    when there are several items (the kernels release the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    from nlsid.simulate.threads import thread_count

    items = list(items)
    workers = min(thread_count(), len(items))
    if workers <= 1:
        return [function(item) for item in items]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(function, items))


@dataclass
class _Decomposed:
    scale: np.ndarray
    values: np.ndarray
    vectors: np.ndarray
    projected: np.ndarray   # V' (g / scale)

    @classmethod
    def of(cls, H: np.ndarray, g: np.ndarray) -> "_Decomposed":
        scale = np.sqrt(np.diag(H))
        scale[~(scale > 0)] = 1.0
        Hn = H / np.outer(scale, scale)
        values, vectors = np.linalg.eigh(Hn)
        keep = values > S_FLOOR * max(values[-1], 0.0)
        values, vectors = values[keep], vectors[:, keep]
        return cls(scale, values, vectors, vectors.T @ (g / scale))

    def step(self, mu: float) -> np.ndarray:
        lam = mu * self.values[-1] if self.values.size else mu
        return -(self.vectors @ (self.projected / (self.values + lam))) / self.scale


class _IterateCount:
    """The accepted iterates of a fit against its budget, told to ``progress(count, budget)`` at
    each accepted iterate and once at the end.

    The budget is the iterations the fit may take: at the start the maxima of the stages it will
    run; a stage that ends before its maximum (converged, stopped early, at the noise floor) gives
    back the iterations it did not take, and the end sets it to the count. So ``count <= budget``
    always, the budget never rises, and ``count / budget`` reaches 1 exactly at the last call."""

    def __init__(self, progress: Callable[[int, int], None] | None, budget: int):
        self.progress, self.count, self.budget = progress, 0, budget

    def accepted(self) -> None:
        self.count += 1
        self._tell()

    def give_back(self, iterations: int) -> None:
        """The iterations a stage that ended did not take (a stage skipped later, at the noise
        floor, is settled by :meth:`done`)."""
        self.budget -= iterations

    def done(self) -> None:
        self.budget = self.count
        self._tell()

    def _tell(self) -> None:
        if self.progress is not None:
            self.progress(self.count, self.budget)


def _stage(problem: _Problem, model: Pnlss, x0s: list, stage: str, max_iterations: int, validate,
           history: list, kept: list, patience: int, floor: float | None = None,
           iterates: _IterateCount | None = None) -> tuple[Pnlss, list, str]:
    """Levenberg-Marquardt iterations of one stage from ``model``; appends each accepted iterate to
    ``history`` and its (model, initial states) to ``kept``. Returns the last model, its initial
    states and how the stage ended. ``floor``: the validation rms of a model without error
    (:func:`validation_floor`), where known; ``iterates``: told each accepted iterate and, at the
    end, the iterations of ``max_iterations`` not taken."""
    iterates = iterates or _IterateCount(None, max_iterations)
    taken = len(history)
    try:
        return _iterate(problem, model, x0s, stage, max_iterations, validate, history, kept, patience, floor,
                        iterates)
    finally:
        iterates.give_back(max_iterations - (len(history) - taken))


def _iterate(problem: _Problem, model: Pnlss, x0s: list, stage: str, max_iterations: int, validate,
             history: list, kept: list, patience: int, floor: float | None, iterates: _IterateCount
             ) -> tuple[Pnlss, list, str]:
    """The iterations of :func:`_stage`."""
    mu = MU_START
    stage_start = len(history)
    theta0 = global_vector(model)
    try:
        H, g, cost = problem.normal_equations(model, x0s)
    except FloatingPointError:
        return model, x0s, JACOBIAN_DIVERGED
    n_samples = sum(r.samples for r in problem.records)
    for number in range(1, max_iterations + 1):
        decomposed = _Decomposed.of(H, g)
        trial_cost = math.inf
        while mu <= MU_MAX:
            trial, trial_x0s = problem.unpack(model, theta0, x0s, decomposed.step(mu))
            trial_cost = problem.cost(trial, trial_x0s)
            if trial_cost < cost:
                break
            mu *= 10.0
        if not trial_cost < cost:
            return model, x0s, "no decrease"
        decrease = (cost - trial_cost) / cost if cost > 0 else 0.0
        model, x0s, theta0 = trial, trial_x0s, global_vector(trial)
        mu = max(mu / 3.0, 1e-15)
        history.append(Iteration(stage, number, math.sqrt(trial_cost / n_samples), validate(model), mu))
        kept.append((model, x0s))
        iterates.accepted()
        if decrease < CONVERGED:
            return model, x0s, "converged"
        if at_floor(history[-1], floor):
            return model, x0s, AT_FLOOR
        if _overfitting(history, patience, stage_start):
            return model, x0s, "stopped early"
        try:
            H, g, cost = problem.normal_equations(model, x0s)
        except FloatingPointError:
            # The state and its sensitivities are bounded together (jacobian_blocks): a model on
            # the edge of stability can pass the cost's simulation and fail this one.
            return model, x0s, JACOBIAN_DIVERGED
    return model, x0s, "iteration limit"


def _overfitting(history: list[Iteration], patience: int, stage_start: int) -> bool:
    """Early stopping: no lower validation rms in the last ``patience`` iterates of this stage
    (from index ``stage_start`` of ``history``), and either the estimation rms fell by less than
    PROGRESS over them or the validation rms is WORSE times the lowest. A fit still learning (the
    estimation error falling faster, the validation error near its lowest) crosses a plateau
    rather than stopping on it: a PNLSS fit often stalls for tens of iterations before its
    nonlinear terms find the system."""
    current = history[-1]
    best = history[_best(history)]
    if current.validation_rms is None or len(history) - 1 - max(_best(history), stage_start - 1) < patience:
        return False
    stalled = current.estimation_rms > (1 - PROGRESS) * history[-1 - patience].estimation_rms
    return stalled or current.validation_rms > WORSE * best.validation_rms


def validation_floor(val: Sequence[Record]) -> float | None:
    """The validation rms of a model without error: sqrt of the records' noise variances averaged
    over the samples they stand for (:meth:`Record.floor`); None unless every record has one."""
    floors = [rec.floor() for rec in val]
    if not floors or any(f is None for f in floors):
        return None
    return math.sqrt(sum(f * rec.samples for f, rec in zip(floors, val)) / sum(rec.samples for rec in val))


def at_floor(iterate: Iteration, floor: float | None) -> bool:
    """The iterate's validation rms is within AT_FLOOR_DB of ``floor`` (module docstring)."""
    return (floor is not None and iterate.validation_rms is not None
            and iterate.validation_rms <= floor * 10 ** (AT_FLOOR_DB / 20))


def _floor_note(floor: float) -> str:
    return (f"the validation error reached the validation runs' noise ({floor:.6g} rms) within {AT_FLOOR_DB:g} dB: "
            "the fit stopped there")


def _best(history: list[Iteration], stage: str | None = None) -> int:
    """Index of the iterate (of ``stage``, or any) with the lowest validation rms (the first of
    equals), or without validation runs the last one (the lowest estimation rms)."""
    indices = [i for i, it in enumerate(history) if stage is None or it.stage == stage]
    if history[indices[0]].validation_rms is None:
        return indices[-1]
    return min(indices, key=lambda i: (history[i].validation_rms, i))


def _bound(linear: Pnlss, recs: list[Record]) -> float:
    """BOUND_FACTOR times the largest |state| of the linear part on the estimation inputs (from
    rest; periodic ones in steady state), at least BOUND_FACTOR times the largest |u| and |y|."""
    from nlsid.simulate.pnlss_kernels import states

    peak = 0.0
    for rec in recs:
        u, _ = driven_input(linear, rec)
        x = np.zeros((u.size, linear.order))
        states(*linear.replace(input_offset=0.0).kernel_matrices(), u, np.zeros(linear.order), x)
        peak = max(peak, float(np.max(np.abs(x), initial=0.0)), float(np.max(np.abs(rec.u))), float(np.max(np.abs(rec.y))))
    if not math.isfinite(peak) or peak == 0.0:
        peak = 1.0
    return BOUND_FACTOR * peak


def lfr_combinations(model: Pnlss, recs: list[Record], x0s: list) -> Pnlss:
    """``model`` (LFR form) with its combinations z = Cz x + Dz u set to the start rows of
    :func:`nlsid.models.pnlss.lfr_start_rows` for its current linear part (z_1 = C x + D u, its
    output: a Wiener-like start; z_2 = u; z_k = x_(k-2)), each scaled to unit rms over the
    records (lead-in left out) so that the monomials of z are of order one."""
    from nlsid.models.pnlss import lfr_start_rows
    from nlsid.simulate.pnlss_kernels import states

    Cz, Dz = lfr_start_rows(model.C, model.D, model.lfr_inputs)
    power, count = np.zeros(Dz.size), 0
    matrices = model.kernel_matrices()
    for rec, x0 in zip(recs, x0s):
        u, lead = driven_input(model, rec)
        x = np.zeros((u.size, model.order))
        states(*matrices, u, np.zeros(model.order) if x0 is None else np.asarray(x0, dtype=float), x)
        z = x[lead:] @ Cz.T + u[lead:, None] * Dz
        power += np.sum(z * z, axis=0)
        count += z.shape[0]
    rms = np.sqrt(power / max(count, 1))
    rms[~((rms > 0) & np.isfinite(rms))] = 1.0
    return model.replace(Cz=Cz / rms[:, None], Dz=Dz / rms)


def _tamed(start: Pnlss, recs: list[Record], bound: float) -> tuple[Pnlss | None, str | None]:
    """The start, or, if its simulation diverges on the estimation runs, the start with its
    nonlinear coefficients shrunk tenfold until it does not (zero at last); None if even the linear
    part diverges. The second value states what was done (None: nothing)."""
    zero = [np.zeros(start.order) if r.arbitrary else None for r in recs]

    def diverges(m: Pnlss) -> bool:
        return any(simulate_record(m, r, x, bound) is None for r, x in zip(recs, zero))

    if not diverges(start):
        return start, None
    for k in range(1, 7):
        factor = 10.0 ** -k
        trial = start.replace(E=start.E * factor, F=start.F * factor)
        if not diverges(trial):
            return trial, (f"the start diverged on the estimation runs; its nonlinear coefficients E, F were "
                           f"scaled by {factor:g} to start from a point that does not")
    linear = start.replace(E=np.zeros_like(start.E), F=np.zeros_like(start.F))
    if not diverges(linear):
        return linear, ("the start diverged on the estimation runs even with its nonlinear coefficients scaled "
                        "by 1e-6; they were set to zero")
    return None, "the start diverges on the estimation runs even without nonlinear terms"


def fit_pnlss(start: Pnlss, estimation: Sequence[Run], validation: Sequence[Run] = (), max_iterations: int = 100,
              linear_iterations: int | None = None, patience: int = 15, fit_offset: bool = True,
              progress: Callable[[int, int], None] | None = None) -> PnlssFit:
    """Fit a PNLSS model to the estimation runs from ``start`` (module docstring).

    Parameters
    ----------
    start : the start model (typically :func:`nlsid.models.pnlss.from_linear` of the BLA's fit).
    estimation, validation : measured runs (each with u and y; periodic or arbitrary).
    max_iterations : accepted iterations of the nonlinear stage at most (0: none).
    linear_iterations : of the linear stage (E = F = 0); default 20 when the start has no nonlinear
        coefficients, else 0 (a nonlinear start is refined as a whole).
    patience : the fit stops after this many accepted iterates without a lower validation error
        during which the estimation error fell by less than 1 % (:func:`_overfitting`).
    fit_offset : the output offset is a parameter of every stage, from the start's value (else it is
        held): a constant in y that the start's offset misses (the mean that even monomials add,
        a sensor offset) is otherwise fitted by a slow pole of the linear stage.
    progress : called as ``progress(count, budget)`` at each accepted iterate and once at the end
        (:class:`_IterateCount`): the iterates accepted so far and the iterations the fit may take
        in all, ``linear_iterations`` and ``max_iterations`` per nonlinear stage it runs, less those
        of stages that ended or were skipped early; at the end ``count == budget``.

    Returns
    -------
    PnlssFit : a start that diverges does not raise (``status`` and ``notes`` say what happened).
    """
    clock = time.perf_counter()
    est = records(estimation, "estimation")
    val = records(validation, "validation")
    if not est:
        raise InputError("estimation", "no estimation runs")
    for rec in est + val:
        if rec.u.size == 0:
            raise InputError(f"run {rec.run_id}", "is empty")
    notes: list[str] = []
    nonlinear_start = bool(np.any(start.E) or np.any(start.F))
    if linear_iterations is None:
        linear_iterations = 0 if nonlinear_start else 20

    bound = _bound(start.replace(E=np.zeros_like(start.E), F=np.zeros_like(start.F)), est)
    model, shrunk = _tamed(start, est, bound)
    if shrunk:
        notes.append(shrunk)
    if model is None:
        history = [Iteration("start", 0, math.inf, math.inf if val else None, MU_START)]
        _IterateCount(progress, 0).done()
        return PnlssFit(start, start, start, history, 0, "nothing was fitted: " + shrunk, "failed", notes,
                        [None] * len(est), time.perf_counter() - clock, 0.0)
    nonlinear_start = bool(np.any(model.E) or np.any(model.F))

    validation_x0s: dict = {}

    def validate(m: Pnlss) -> float | None:
        return rms_on(m, val, bound, validation_x0s) if val else None

    x0s = [estimate_x0(model, rec, bound) if rec.arbitrary else None for rec in est]
    x0s = [np.zeros(model.order) if rec.arbitrary and x is None else x for rec, x in zip(est, x0s)]
    n_samples = sum(r.samples for r in est)
    full = _Problem(est, np.arange(global_vector(model).size), bound, fit_offset)
    history = [Iteration("start", 0, math.sqrt(full.cost(model, x0s) / n_samples), validate(model), MU_START)]
    kept = [(model, x0s)]
    floor = validation_floor(val)
    tamed_start, status = model, AT_FLOOR if at_floor(history[0], floor) else "converged"
    seconds, work = 0.0, 0.0
    linear_stage = linear_iterations > 0 and not nonlinear_start and status != AT_FLOOR
    states_stage = max_iterations > 0 and model.with_input and not model.lfr and not nonlinear_start
    full_stage = max_iterations > 0 and model.E.size + model.F.size > 0
    iterates = _IterateCount(progress, (linear_iterations if linear_stage else 0)
                            + max_iterations * (int(states_stage) + int(full_stage)))
    if linear_stage:
        problem = _Problem(est, linear_indices(model), bound, fit_offset)
        model, x0s, status = _stage(problem, model, x0s, "linear", linear_iterations, validate, history, kept, patience,
                                    floor, iterates)
        seconds, work = seconds + problem.jacobian_seconds, work + problem.jacobian_work
    linear_model = kept[_best(history, "linear" if history[-1].stage == "linear" else "start")][0]
    if status == AT_FLOOR:
        max_iterations = 0  # nothing left to reach (module docstring)
        notes.append(_floor_note(floor))
    if max_iterations > 0 and model.lfr and not nonlinear_start:
        model = lfr_combinations(model, est, x0s)
        notes.append(f"LFR form: the {model.lfr_inputs} combination(s) z = Cz x + Dz u started as the linear model's "
                     "output C x + D u (Wiener-like)" + (", the input, then single states" if model.lfr_inputs > 1 else "")
                     + ", each scaled to unit rms on the estimation runs")
    if states_stage and max_iterations > 0:
        states = _Problem(est, state_term_indices(model), bound, fit_offset)
        model, x0s, status = _stage(states, model, x0s, "nonlinear_states", max_iterations, validate, history, kept,
                                    patience, floor, iterates)
        seconds, work = seconds + states.jacobian_seconds, work + states.jacobian_work
    if full_stage and max_iterations > 0 and status != AT_FLOOR:
        model, x0s, status = _stage(full, model, x0s, "nonlinear", max_iterations, validate, history, kept, patience,
                                    floor, iterates)
        seconds, work = seconds + full.jacobian_seconds, work + full.jacobian_work
    if status == AT_FLOOR and max_iterations > 0:
        notes.append(_floor_note(floor))
    iterates.done()
    chosen = _best(history)
    item = history[chosen]
    if val:
        reason = (f"the lowest validation rms, {item.validation_rms:.6g}, of {len(history)} iterates "
                  f"({item.stage} iteration {item.number}; the fit {status})")
    else:
        reason = (f"no validation runs: the last iterate ({item.stage} iteration {item.number}, "
                  f"the lowest estimation rms; the fit {status})")
    return PnlssFit(kept[chosen][0], tamed_start, linear_model, history, chosen, reason, status, notes,
                    kept[chosen][1], time.perf_counter() - clock, work / seconds if seconds > 0 else 0.0)
