"""Free parameters of a model config estimated by minimising the simulation error on measured runs.

Given a model config (the loaded YAML as a dict), a set of *free* parameters named by dotted key
paths into it (``model.nonlinearities[0].fc``, ``closed_loop.feedforward.coulomb``, or any number
of a list: ``model.num[0]``, ``model.A[1][0]``, ``model.nonlinear.coefficients[3]``), and measured
runs, the estimate is

    theta_hat = argmin_theta  sum_{runs r in E} sum_{n in steady state of r} (s_sim,r(n; theta) - s_r(n))^2

over the estimation runs E, for the fitted signal s: the output ``y`` (default), or in closed loop
the plant input ``u`` (``fit_on="u"``: the controller's output, the criterion of closed-loop
benchmarks such as EMPS, where the position error is kept small by the loop itself). Each run's
recorded excitation (open loop: ``u``; closed loop: the reference ``r``) is simulated through the
noise-free model with the parameters written into the config (the ``sweep`` mechanism:
:func:`nlsid.models.key_paths.set_value`, then the full config validation), and compared with the
recorded signal over the steady-state periods (the last ``n_periods`` periods; a run without
transient periods with the model in periodic steady state: :func:`nlsid.simulate.engine.lead_periods`; the whole record
of an arbitrary run; the range of a part cut by :mod:`nlsid.io.ranges`). In closed loop the
simulated ``u`` is the plant input as the simulated controller computed it, with the loop closed
in the simulation. The rms errors of y and (closed loop) u are both reported, whichever is fitted.

A trial value the model refuses (the config validation, building the model or simulating it
raises :class:`~nlsid.errors.InputError`: an unstable denominator, an unstable loop, a diverged
simulation) is a rejected step: the evaluation returns the residual vector with every element
equal to ``c = 10 rms(e_start)`` (1 for a zero start error), whose cost ``n c^2 / 2`` is 100 times
the start's. The trust-region method accepts a step only when it lowers the cost, and every
accepted point costs at most the start's (the cost never rises from there), so such a step is
never accepted: the actual reduction is negative, the ratio to the predicted one below 1/4, and
the trust radius shrinks to a quarter of the step, so the next try is a shorter step from the last
accepted (valid) point.
The start itself must be valid (it is evaluated first; its error stops the fit).

The minimisation is :func:`scipy.optimize.least_squares` (trust-region reflective, bounds) in
normalised coordinates x_i = theta_i / s_i (s_i the start value's magnitude), with a forward
finite-difference Jacobian whose step is ``diff_step`` relative to each parameter (scipy's own
rule, :func:`forward_steps`); the output offset's column, where the offset is added after
everything else (open loop, no initial state fitted: :meth:`_Cost.offset_column`), is exact and
costs no simulation. Simulations of the runs of one evaluation run in parallel threads
(:func:`nlsid.simulate.batch.simulate_all`), those of all the Jacobian's columns in one pool.

Uncertainty: the sandwich estimator (Huber 1967, White 1980), which does not assume white
residuals (coloured noise, and the correlated residual a model error leaves, make the white-noise
form sigma^2 (J^T J)^{-1} optimistic by up to the ratio of the residual's spectrum at the
frequencies that matter to its mean):

    cov(theta_hat) = S A^{-1} B A^{-1} S,   A = J^T J,   B = J^T Sigma J n / (n - p),   S = diag(s),

with J the Jacobian of the residuals in x and Sigma the residuals' covariance. Each run's residual
is taken as stationary, so its covariance is diagonalised by the DFT and

    J^T Sigma J = sum_runs (1/N) sum_k Phi(k) G(k)^H G(k),

G(k) the DFT of the run's Jacobian rows (N samples, k over all N lines; the real-signal DFT's
lines 1 .. N/2 - 1 count twice), Phi(k) the residual's spectrum, estimated by its periodogram
|E(k)|^2 / N averaged over SPECTRUM_LINES neighbouring lines. For white residuals Phi = sigma^2 and
Parseval gives back sigma^2 J^T J. The factor n / (n - p) (n samples, p parameters) is the usual
degrees-of-freedom correction. docs/fit_covariance.md derives it; tests/fit/test_fit_covariance.py
checks it by Monte Carlo.

Identifiability: a warning names a parameter that has no effect (zero Jacobian column: its
standard error is infinite, its covariances NaN), a nearly
singular J^T J (a combination of parameters the data cannot tell apart: singular value ratio
below 1e-6), a pair with correlation above 0.99 in magnitude, a relative standard deviation above
50 %, or an estimate at a bound.

Periodic runs are fitted on their mean period. With P steady-state periods of a periodic model
response s_sim, sum_p ||s_sim - s_p||^2 = P ||s_sim - mean_p s_p||^2 + sum_p ||s_p - mean_p s_p||^2,
and the last term does not depend on theta; so the optimiser's residual of such a run is
sqrt(P) (s_sim - mean_p s_p) over one period. The run is simulated as that one period, driven
by the mean period of the recorded excitation (its measurement noise averaged like the output's,
where the whole run would carry each period's own), from rest a lead ahead of it: the samples in
which the model's linear dynamics (forces aside) decay to the engine's STEADY_TOLERANCE
(:func:`nlsid.simulate.engine.lead_samples`), the same excitation continued backwards. That is
the periodic steady state to the tolerance the engine simulates it to with whole lead periods,
and fewer samples than whole periods (the battery's 32 Hz plant with damping ratio 0.03: 2290
samples ahead of its 4096 instead of a transient period of 4096). A model with friction or
backlash keeps a memory its decay does not erase (:func:`nlsid.simulate.engine.hysteretic`): its
lead is a whole period at least, whose extremes wipe that memory out. A run whose model does not
settle within its recorded transient periods (its measured periods are then not in steady state
either), a model without a steady state (an integrator), a range part and a run with measured
input channels (not periodic) are fitted whole. The sandwich below is the same in this form: its
noise is divided by P and multiplied by P again. The errors reported are those of the whole runs.

The validation runs are never used by the optimiser: their rms errors, and each run's noise level
(the period-to-period standard deviation of the fitted signal, a lower limit no model can beat),
tell how well the fitted model predicts data it has not seen.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.io.feeds import check_run_count
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.run import Run
from nlsid.io.ranges import SampleRange, check_sources, check_unique, cut, record
from nlsid.models.key_paths import check_step, deep_copy, parse, set_value
from nlsid.simulate.sweep import SweepPoint
from nlsid.simulate.threads import blas_in_one_thread

IDENTIFIABLE_RATIO = 1e-6   # singular value ratio of J below which a parameter combination is not identifiable
CORRELATION_LIMIT = 0.99
RELATIVE_STD_LIMIT = 0.5


@dataclass(frozen=True)
class FreeParameter:
    """A free parameter: start value (None: the value written in the config) and bounds."""

    start: float | None = None
    lower: float = -math.inf
    upper: float = math.inf


@dataclass(frozen=True)
class RunError:
    """Simulation error of one run: rms of s_sim - s (the fitted signal s) over the steady state, the
    rms of y itself and the noise level (period-to-period std of s, NaN with fewer than two
    periods); the rms errors of y and u (NaN in open loop, where u is the recorded input)."""

    run_id: str
    role: str            # "estimation" or "validation"
    rms: float
    y_rms: float
    noise_rms: float
    start_rms: float     # the same error with the start values
    samples: int
    y_error_rms: float = math.nan
    u_error_rms: float = math.nan


@dataclass
class ExtensionFit:
    """Result of :func:`fit_free_parameters` (arrays ordered like ``names``)."""

    names: list[str]
    start: np.ndarray
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    estimation_rms: float
    validation_rms: float
    start_estimation_rms: float
    start_validation_rms: float
    noise_rms_estimation: float
    noise_rms_validation: float
    runs: list[RunError]
    warnings: list[str]
    config: dict              # the config with the fitted values written in, without ``free``
    evaluations: int
    message: str
    samples: int = 0
    bounds: list[tuple[float, float]] = field(default_factory=list)
    fit_on: str = "y"
    signal_rms: dict = field(default_factory=dict)  # "y"/"u" -> {"estimation": rms, "validation": rms}
    jacobians: dict = field(default_factory=dict)  # "differences"/"sensitivities" -> Jacobians formed so

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def summary(self) -> dict:
        """Plain numbers for JSON and the fit report."""
        return {
            "parameters": {
                n: {"value": float(v), "std": float(s), "start": float(s0), "lower": lo, "upper": hi}
                for n, v, s, s0, (lo, hi) in zip(self.names, self.values, self.std, self.start, self.bounds)
            },
            "correlation": self.correlation.tolist(),
            "covariance": self.covariance.tolist(),
            "estimation_rms": self.estimation_rms,
            "validation_rms": self.validation_rms,
            "start_estimation_rms": self.start_estimation_rms,
            "start_validation_rms": self.start_validation_rms,
            "noise_rms_estimation": self.noise_rms_estimation,
            "noise_rms_validation": self.noise_rms_validation,
            "fit_on": self.fit_on,
            **{f"{signal}_{role}_rms": self.signal_rms.get(signal, {}).get(role, math.nan)
               for signal in ("y", "u") for role in ("estimation", "validation")},
            "runs": [dataclasses.asdict(r) for r in self.runs],
            "samples": self.samples,
            "evaluations": self.evaluations,
            "jacobians": dict(self.jacobians),
            "message": self.message,
            "warnings": list(self.warnings),
        }


def free_from_config(free_config: dict) -> dict[str, FreeParameter]:
    """The ``free:`` section of a validated config as :class:`FreeParameter` objects."""
    return {
        key: FreeParameter(p.start, -math.inf if p.lower is None else p.lower, math.inf if p.upper is None else p.upper)
        for key, p in free_config.items()
    }


def value_at(data: dict, path: str):
    """The value at a dotted key path of a config dict, list elements included (``model.den[2]``);
    None when a mapping key along it is absent. An index beyond a list, or into something that is
    not a list, is an error naming the path (:func:`nlsid.models.key_paths.check_step`)."""
    keys = parse(path)
    if keys is None:
        raise InputError(f"free.{path}", "expected a dotted key path such as model.nonlinearities[0].fc")
    node = data
    for depth, key in enumerate(keys):
        check_step(node, key, keys[:depth], lambda what: InputError(f"free.{path}", what))
        if not isinstance(key, int) and key not in node:
            return None
        node = node[key]
    return node


def split_runs(runs: Sequence[Run], validation_ids: Sequence[str] | None = None, validate_on: Sequence[Run] = (),
               estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
               where: str = "") -> tuple[list[Run], list[Run]]:
    """Estimation and validation runs (or parts of runs) of the recording ``where``.

    With ``validation_ids``: those runs are held out. With ranges (:mod:`nlsid.io.ranges`): every
    run is cut into its estimation and validation part (no run is held out whole). Otherwise,
    without ``validate_on`` (the runs of further recordings, validation only), the default: when
    the runs carry two or more realization indices, the highest realization of every level is held
    out (each level stays in the estimation set); otherwise the last run is held out. One run alone
    cannot be split. The runs of ``validate_on`` are added to the validation runs.
    """
    runs = list(runs)
    check_sources(estimation_range, validation_range, bool(validate_on))
    if estimation_range is not None:
        if validation_ids:
            raise InputError("--validation", "holds out whole runs, --estimation-range cuts every run: give one of them")
        estimation, validation = cut(runs, estimation_range, validation_range, where)
        validation += validate_on
        check_unique(estimation + validation)
        return estimation, validation
    if validate_on and not validation_ids:
        check_unique(runs + list(validate_on))
        return runs, list(validate_on)
    if validation_ids:
        known = {r.run_id for r in runs}
        missing = [i for i in validation_ids if i not in known]
        if missing:
            raise InputError("validation runs", f"no run {missing[0]!r} in the recording (runs: {', '.join(sorted(known))})")
        held = set(validation_ids)
    else:
        check_run_count(len(runs))
        realizations = {r.realization for r in runs if r.realization is not None}
        if len(realizations) >= 2:
            last = {}
            for r in runs:
                if r.realization is not None:
                    last[r.level] = max(last.get(r.level, r.realization), r.realization)
            held = {r.run_id for r in runs if r.realization is not None and r.realization == last[r.level]}
        else:
            held = {runs[-1].run_id}
    estimation = [r for r in runs if r.run_id not in held]
    validation = [r for r in runs if r.run_id in held] + list(validate_on)
    if not estimation:
        raise InputError("validation runs", "every run is held out for validation: none is left to fit")
    check_unique(estimation + validation)
    return estimation, validation


def _steady(run: Run, x: np.ndarray) -> np.ndarray:
    """The samples of ``x`` (a signal of ``run``, or its simulation with a lead ahead of it) that
    the error is measured on: the last ``n_periods`` whole periods (the steady state; a range
    part's range), an arbitrary run's whole record."""
    if run.period is None:
        return x
    return x[x.size - run.n_periods * run.period:]


def _compact(run: Run, excitation: Run, point) -> tuple[Run, Run, float] | None:
    """(measured, excitation, weight) of ``run`` fitted on its mean period (module docstring): the
    measured signals' mean over the steady-state periods; the excitation's mean period with the
    lead in which the model settles ahead of it (:func:`nlsid.simulate.engine.lead_samples`, the
    mean period continued backwards), an arbitrary record simulated from rest; the weight sqrt(P).
    None where the run is fitted whole: a range part, fewer than two periods, measured channels, a
    model without a periodic steady state, or one that does not settle within the run's
    transient periods (the measured periods after them are then not in steady state either)."""
    from nlsid.io.ranges import RangeRun
    from nlsid.simulate.batch import build
    from nlsid.simulate.engine import hysteretic, lead_samples

    if run.period is None or isinstance(run, RangeRun) or run.n_periods < 2 or run.channels:
        return None
    model, loop = build(point)
    lead = lead_samples(model, loop, dataclasses.replace(excitation, transient_periods=0))
    if lead == 0 or (run.transient_periods and lead > run.transient_periods * run.period):
        return None
    if hysteretic(model):  # a whole period ahead wipes its memory out (engine.hysteretic)
        lead = max(lead, run.period)

    def mean_period(x: np.ndarray | None) -> np.ndarray | None:
        return None if x is None else _steady(run, x).reshape(run.n_periods, run.period).mean(axis=0)

    measured = dataclasses.replace(run, transient_periods=0, **{name: mean_period(getattr(run, name))
                                                                for name in ("u", "y", "r")})
    one = mean_period(excitation.u)
    ahead = np.tile(one, -(-lead // run.period))[-lead:]
    short = dataclasses.replace(excitation, u=np.concatenate([ahead, one]), y=None, period=None, transient_periods=0)
    return measured, short, math.sqrt(run.n_periods)


def noise_rms(run: Run, signal: str = "y") -> float:
    """Period-to-period standard deviation of a signal (pooled over the samples of a period), NaN if P < 2."""
    if run.period is None or run.n_periods < 2:
        return math.nan
    return float(np.sqrt(np.mean(np.var(run.periods(signal), axis=0, ddof=1))))


class _Problem:
    """The config, the free keys and the runs; evaluates simulation errors for parameter values."""

    def __init__(self, config_data: dict, free: dict[str, FreeParameter], source: str, lines: dict,
                 workers: int | None, fit_on: str = "y"):
        if "sweep" in config_data:
            raise InputError(_where(source, lines, ("sweep",)), "sweep: a config with free parameters cannot sweep; remove sweep")
        base = {k: deep_copy(v) for k, v in config_data.items() if k not in ("free", "disturbances")}
        self.base, self.source, self.lines, self.workers = base, source, lines or {}, workers
        self.names = list(free)
        if not self.names:
            raise InputError(source or "free", "no free parameters: mark at least one under free:")
        starts = []
        for name, p in free.items():
            where = _where(source, self.lines, ("free", name))
            try:
                start = p.start if p.start is not None else value_at(base, name)
            except InputError as exc:  # named by the free: key the user wrote, at its line
                raise InputError(where, f"{exc.where}: {exc.what}") from None
            if isinstance(start, bool) or not isinstance(start, (int, float)) or not math.isfinite(start):
                raise InputError(where, f"free.{name}: no number at this key path of the config; give a start value")
            if not p.lower <= start <= p.upper:
                raise InputError(where, f"free.{name}: start {start:g} outside [{p.lower:g}, {p.upper:g}]")
            starts.append(float(start))
        self.start = np.array(starts)
        self.lower = np.array([free[n].lower for n in self.names])
        self.upper = np.array([free[n].upper for n in self.names])
        self.closed = "closed_loop" in base
        if fit_on not in ("y", "u"):
            raise InputError("--fit-on", f"expected y or u, got {fit_on!r}")
        if fit_on == "u" and not self.closed:
            raise InputError("--fit-on", "u is fitted only in closed loop (the model has no closed_loop): in open "
                                         "loop the recorded u is the input the simulation is driven by")
        self.signals = ("y", "u") if self.closed else ("y",)  # the errors reported
        self.point(self.start)  # the start must give a valid config

    def data(self, theta: np.ndarray) -> dict:
        data = deep_copy(self.base)
        for name, value in zip(self.names, theta):
            try:
                set_value(data, name, float(value), key=f"free.{name}")
            except InputError as exc:  # named by the free: key the user wrote, at its line
                raise InputError(_where(self.source, self.lines, ("free", name)), f"{exc.where}: {exc.what}") from None
        return data

    def point(self, theta: np.ndarray) -> SweepPoint:
        data = self.data(theta)
        try:
            config = validate_simulate_config(data, self.source, self.lines)
        except InputError as exc:
            values = ", ".join(f"{n} = {v:g}" for n, v in zip(self.names, theta))
            raise InputError(exc.where, f"{exc.what} (with {values}; narrow the bounds under free:)") from None
        return SweepPoint({}, config, self.source, self.lines)

    def inputs(self, runs: Sequence[Run]) -> list[Run]:
        """The runs as the simulator's excitations: the reference in closed loop, else u."""
        out = []
        for run in runs:
            if run.y is None:
                raise InputError(run.run_id, "run has no measured y to fit to")
            if self.closed and run.r is None:
                raise InputError(run.run_id, "the model has a closed_loop but the run has no reference r")
            # y stays: an arbitrary record starts from the initial state fitted to it (nlsid.simulate.initial_state);
            # r stays for a model written as equations, whose expressions may read it
            model = self.base.get("model")
            keep_r = not self.closed and isinstance(model, dict) and model.get("type") == "equations"
            out.append(dataclasses.replace(record(run), u=run.r if self.closed else run.u, r=run.r if keep_r else None))
        return out

    def errors(self, theta: np.ndarray, runs: Sequence[Run], excitations: Sequence[Run]) -> dict[str, list[np.ndarray]]:
        """Per reported signal s (y, and u in closed loop) and run, s_sim - s over the steady state."""
        return self.errors_many([theta], runs, excitations)[0]

    def errors_many(self, thetas: Sequence[np.ndarray], runs: Sequence[Run],
                    excitations: Sequence[Run]) -> list[dict[str, list[np.ndarray]]]:
        """:meth:`errors` for several parameter vectors, simulated in one pool of threads (every
        run of every vector a job, :func:`nlsid.simulate.batch.simulate_all`): the columns of a
        finite-difference Jacobian keep both cores busy to the end, where one vector's runs leave
        a core idle while the last run finishes."""
        from nlsid.simulate.batch import simulate_all

        points = [self.point(theta) for theta in thetas]
        simulated = simulate_all(points, list(excitations), workers=self.workers, steady=True)
        count = len(points)
        return [{s: [_steady(run, getattr(simulated[i * count + j], s)) - _steady(run, getattr(run, s))
                     for i, run in enumerate(runs)] for s in self.signals} for j in range(count)]


@dataclass
class _Cost:
    """The runs as the optimiser sees them (:func:`_compact`): measured runs, excitations, weights."""

    runs: list[Run]
    inputs: list[Run]
    weights: np.ndarray

    @classmethod
    def of(cls, problem: "_Problem", runs: Sequence[Run], inputs: Sequence[Run]) -> "_Cost":
        point = problem.point(problem.start)
        out = cls([], [], np.ones(len(runs)))
        for i, (run, excitation) in enumerate(zip(runs, inputs)):
            compact = _compact(run, excitation, point)
            measured, short, weight = compact if compact is not None else (run, excitation, 1.0)
            out.runs.append(measured)
            out.inputs.append(short)
            out.weights[i] = weight
        return out

    def residuals(self, problem: "_Problem", thetas: Sequence[np.ndarray], signal: str) -> list[np.ndarray]:
        """The weighted residual vector of each parameter vector (module docstring)."""
        return [np.concatenate([w * e for w, e in zip(self.weights, errors[signal])])
                for errors in problem.errors_many(thetas, self.runs, self.inputs)]

    def whole(self, runs: Sequence[Run]) -> bool:
        """Every one of ``runs`` (the estimation runs) fitted as it is (none :func:`_compact`)."""
        return all(fitted is run for fitted, run in zip(self.runs, runs))

    def split(self, residual: np.ndarray, signal: str) -> dict[str, list[np.ndarray]]:
        """The residual vector of :meth:`residuals` as the per-run errors of ``signal``
        (:meth:`_Problem.errors`), for runs fitted :meth:`whole` (weight 1)."""
        return {signal: np.split(residual, np.cumsum(self.segments())[:-1])}

    def segments(self) -> list[int]:
        """Samples of each run's residual (:func:`_steady`'s)."""
        return [run.n_samples if run.period is None else run.n_periods * run.period for run in self.runs]

    @property
    def fits_initial_states(self) -> bool:
        """Some run is an arbitrary record simulated from the initial state fitted to its measured
        output (:mod:`nlsid.simulate.initial_state`), which depends on the parameters too."""
        return any(run.period is None and run.y is not None for run in self.inputs)

    def sensitivities(self, problem: "_Problem", theta: np.ndarray, signal: str) -> np.ndarray | None:
        """The Jacobian of the weighted residual in theta by forward sensitivities
        (:mod:`nlsid.simulate.tangent`), the runs in parallel threads, where the model is a plant
        whose simulation is smooth in the parameters and no run starts from an initial state
        fitted to it; a periodic run in steady state with the lead the simulation gives it
        (:func:`nlsid.simulate.engine.lead_periods`, at theta). None otherwise (finite differences)."""
        from nlsid.models.from_config import Plant
        from nlsid.simulate import tangent
        from nlsid.simulate.batch import build
        from nlsid.simulate.engine import lead_periods, with_lead
        from nlsid.simulate.threads import in_threads

        model, loop = build(problem.point(theta))
        if not isinstance(model, Plant) or self.fits_initial_states:
            return None
        counts = [lead_periods(model, loop, run) for run in self.inputs]
        led = [with_lead(run, count) if count else run for run, count in zip(self.inputs, counts)]
        leads = [count * (run.period or 0) for run, count in zip(self.inputs, counts)]

        def arguments_at(values: np.ndarray) -> list[tuple]:
            point = problem.point(values)
            return tangent.run_arguments(*build(point), led, point.config.simulation.substeps)

        found = tangent.derivatives(arguments_at, theta)
        if found is None:
            return None
        simulated = in_threads(lambda pair: tangent.simulate(*pair), found, problem.workers)
        column = {"u": 2, "y": 3}[signal]
        return np.concatenate([w * np.stack([_steady(run, d[lead:]) for d in out[column]], axis=1)
                               for w, run, lead, out in zip(self.weights, self.runs, leads, simulated)])

    def offset_column(self, problem: "_Problem", signal: str) -> tuple[int, np.ndarray] | None:
        """(index, column) of the output offset c among the free parameters where its Jacobian
        column is known without a simulation: the engine adds c to the simulated output after
        everything else, so in open loop d e_r / d c = 1 at every sample and the column of the
        weighted residual is the run's weight w_r on each of its samples. Not where the output is
        fed back (a closed loop: the controller reads c too), not for the fitted u, and not where
        an arbitrary record starts from an initial state fitted to its measured output (the fit
        takes part of c)."""
        name = "model.output_offset"
        if name not in problem.names or problem.closed or signal != "y" or self.fits_initial_states:
            return None
        return problem.names.index(name), np.concatenate(
            [np.full(size, w) for w, size in zip(self.weights, self.segments())])


def _where(source: str, lines: dict, key_path: tuple) -> str:
    line = (lines or {}).get(key_path)
    if not source:
        return ".".join(str(k) for k in key_path)
    return f"{source}:{line}" if line is not None else source


def _rms(parts: list[np.ndarray]) -> float:
    if not parts:
        return math.nan
    total = sum(float(np.sum(p * p)) for p in parts)
    return math.sqrt(total / sum(p.size for p in parts))


def _pooled(values: list[float], sizes: list[int]) -> float:
    good = [(v, n) for v, n in zip(values, sizes) if math.isfinite(v)]
    if not good:
        return math.nan
    return math.sqrt(sum(v * v * n for v, n in good) / sum(n for _, n in good))


def _scales(start: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Normalisation s_i: the start's magnitude, else the bound width or the larger bound, else 1."""
    out = np.abs(start).astype(float)
    for i in np.flatnonzero(out == 0):
        width = upper[i] - lower[i]
        bigger = max(abs(lower[i]), abs(upper[i]))
        out[i] = (width if math.isfinite(width) and width > 0
                  else (bigger if math.isfinite(bigger) and bigger > 0 else 1.0))
    return out


def forward_steps(x: np.ndarray, rel_step: float, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The forward-difference steps of :func:`scipy.optimize.least_squares` ("2-point" with
    ``diff_step``, scipy's ``_numdiff`` rule, so the Jacobian is the one scipy would form):
    h_i = rel_step sign(x_i) |x_i| (sqrt(eps) sign(x_i) max(1, |x_i|) where that step vanishes);
    a step that leaves the bounds is reversed where the other side has room, else it goes to the
    farther bound."""
    sign = np.where(x >= 0, 1.0, -1.0)
    h = rel_step * sign * np.abs(x)
    h = np.where((x + h) - x == 0, np.sqrt(np.finfo(float).eps) * sign * np.maximum(1.0, np.abs(x)), h)
    if np.all(np.isneginf(lower) & np.isposinf(upper)):
        return h
    below, above = x - lower, upper - x
    violated = (x + h < lower) | (x + h > upper)
    fitting = np.abs(h) <= np.maximum(below, above)
    h = np.where(violated & fitting, -h, h)
    h = np.where(~fitting & (above >= below), above, h)
    return np.where(~fitting & (above < below), -below, h)


SPECTRUM_LINES = 17  # neighbouring DFT lines averaged into the residual spectrum of the sandwich
STALL_STEPS = 4      # accepted steps over which a stall (fit_free_parameters' stall_db) is judged


def _recent_gain_db(costs: list[float]) -> float:
    """10 log10 of the cost STALL_STEPS accepted points ago over the last one (inf before there are
    that many, or at a zero cost)."""
    if len(costs) <= STALL_STEPS or costs[-1] <= 0:
        return math.inf
    return 10 * math.log10(costs[-1 - STALL_STEPS] / costs[-1])


def _floor_cost(cost: "_Cost", runs: Sequence[Run], signal: str) -> float:
    """The cost expected at the noise floor of ``runs`` (the estimation runs ``cost`` was made of):
    the sum over runs of (residual samples) x (noise variance per sample, :func:`noise_rms`). A
    compact run's residual is sqrt(P) times the error of the mean of P periods, whose noise
    variance is sigma^2 / P, so each of its samples contributes sigma^2 as a whole run's does. NaN
    where a run has no noise level (fewer than two periods)."""
    return float(sum(size * noise_rms(run, signal) ** 2 for size, run in zip(cost.segments(), runs)))


def _stall_threshold(stall_db: float, share: float | None, current: float, floor: float) -> float:
    """``stall_db``, or ``share`` of the current cost's dB above ``floor`` where that is larger."""
    if share is None or not (floor > 0 and current > floor):
        return stall_db
    return max(stall_db, share * 10 * math.log10(current / floor))


class _Stalled(Exception):
    """Raised from the Jacobian to stop the optimiser at a stall; carries what its result would
    (``x``, ``fun``, ``jac``, ``message``; ``status`` 1: a stop that counts as converged)."""

    def __init__(self, x: np.ndarray, fun: np.ndarray, jac: np.ndarray, message: str):
        super().__init__(message)
        self.x, self.fun, self.jac, self.message, self.status = x, fun, jac, message, 1


def _meat_factor(jac: np.ndarray, residual: np.ndarray, segments: Sequence[int]) -> np.ndarray:
    """R with Re(R^H R) = J^T Sigma J for residuals stationary within each run of ``segments``
    samples (module docstring): the rows sqrt(w_k Phi(k) / N) G(k) of every run, stacked. In this
    factored form the sandwich is Re(K^H K), K = R A^{-1}, positive semi-definite by construction,
    so no correlation exceeds 1 in magnitude however ill-conditioned A is."""
    rows = []
    start = 0
    for size in segments:
        e, J = residual[start:start + size], jac[start:start + size]
        start += size
        E, G = np.fft.rfft(e), np.fft.rfft(J, axis=0)
        periodogram = np.abs(E) ** 2 / size
        half = min(SPECTRUM_LINES // 2, E.size - 1)  # a short run averages fewer lines
        spectrum = np.convolve(np.pad(periodogram, half, mode="reflect"), np.ones(2 * half + 1) / (2 * half + 1),
                               mode="valid")
        weights = np.full(E.size, 2.0)
        weights[0] = 1.0
        if size % 2 == 0:
            weights[-1] = 1.0
        rows.append(np.sqrt(weights * spectrum / size)[:, None] * G)
    return np.vstack(rows)


def _uncertainty(jac: np.ndarray, residual: np.ndarray, scale: np.ndarray, names: list[str], values: np.ndarray,
                 lower: np.ndarray, upper: np.ndarray, segments: Sequence[int]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Covariance of theta (the sandwich of the module docstring) and the identifiability warnings."""
    n, p = jac.shape
    warnings = []
    norms = np.linalg.norm(jac, axis=0)
    for i in np.flatnonzero(norms == 0):
        warnings.append(f"{names[i]}: has no effect on the simulated output (not identifiable from these runs)")
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    if sv[0] > 0 and sv[-1] < IDENTIFIABLE_RATIO * sv[0] and not np.any(norms == 0):
        parts = " and ".join(names[i] for i in np.argsort(-np.abs(vt[-1]))[:2])
        warnings.append(f"{parts}: the data cannot tell these apart (singular value ratio {sv[-1] / sv[0]:.1e})")
    if sv[0] == 0:
        # J = 0: no parameter has an effect, nothing is determined (infinite variances, no correlations).
        std = np.full(p, math.inf)
        cov = np.diag(std)
        corr = np.full((p, p), math.nan)
        np.fill_diagonal(corr, 1.0)
    else:
        # (J^T J)^{-1} = V diag(1/sv^2) V^T; a singular value clamped at IDENTIFIABLE_RATIO sv[0]
        # leaves a huge (not an infinite) variance along a direction the data do not determine.
        inverse = (vt.T / np.maximum(sv, IDENTIFIABLE_RATIO * sv[0]) ** 2) @ vt
        K = _meat_factor(jac, residual, segments) @ inverse
        cov_x = (K.conj().T @ K).real * (n / max(n - p, 1))
        cov = cov_x * np.outer(scale, scale)
        inert = norms == 0  # no effect: undetermined, whatever the clamp left in the sandwich
        cov[inert, :] = cov[:, inert] = math.nan
        cov[inert, inert] = math.inf
        std = np.sqrt(np.abs(np.diag(cov)))
        spread = np.outer(*2 * [np.sqrt(np.maximum(np.diag(cov_x), 0.0))])  # zero for a zero residual
        corr = np.divide(cov_x, spread, out=np.zeros_like(cov_x), where=spread > 0)
        np.fill_diagonal(corr, 1.0)
    for i in range(p):
        for j in range(i + 1, p):
            if abs(corr[i, j]) > CORRELATION_LIMIT:
                warnings.append(f"{names[i]} and {names[j]}: correlation {corr[i, j]:+.3f} (nearly interchangeable)")
        if values[i] != 0 and std[i] > RELATIVE_STD_LIMIT * abs(values[i]):
            warnings.append(f"{names[i]}: poorly determined (std {std[i]:.3g} is {100 * std[i] / abs(values[i]):.0f} % of its value)")
        if values[i] <= lower[i] or values[i] >= upper[i]:
            warnings.append(f"{names[i]}: estimate {values[i]:.6g} is at its bound; widen the bounds or check the model")
    return cov, corr, warnings


JACOBIANS = ("differences", "sensitivities")


@blas_in_one_thread
def fit_free_parameters(config_data: dict, free: dict[str, FreeParameter], estimation: Sequence[Run],
                        validation: Sequence[Run], *, source: str = "", lines: dict | None = None,
                        workers: int | None = None, diff_step: float = 1e-3, max_evaluations: int = 100,
                        tolerance: float = 1e-8, fit_on: str = "y", stall_db: float | None = None,
                        stall_share: float | None = None,
                        jacobian: str = "differences") -> ExtensionFit:
    """Estimate the free parameters of a model config by minimising the simulation error.

    ``config_data``: the model config as loaded YAML (a dict, e.g. from
    :func:`nlsid.io.config.load_yaml`); its ``free``, ``disturbances`` (the simulation is
    noise-free) are ignored and ``sweep`` is refused. ``free``: dotted key path -> start and bounds
    (:func:`free_from_config` converts a config's ``free:`` section). ``estimation``: runs with a
    measured ``y`` the optimiser sees; ``validation``: runs it does not (may be empty).
    ``source`` and ``lines`` (from ``load_yaml``) let errors name the config file and line.
    ``fit_on``: the signal whose simulation error is minimised, ``y`` or (closed loop) ``u``.
    ``stall_db``: the fit also stops, as converged, where the last STALL_STEPS accepted steps
    lowered the cost by less than ``stall_db`` dB together (a search creeping along a valley:
    its error can no longer change by more than about that). ``stall_share``: the threshold is
    at least this share of the cost's distance in dB above the noise floor of the estimation runs
    (where they measure it: P >= 2 steady periods each; :func:`_floor_cost`): at that pace the
    search would need STALL_STEPS / stall_share more steps to reach the floor.
    ``jacobian``: ``"differences"``, forward finite differences (:func:`forward_steps`);
    ``"sensitivities"``, the exact derivatives of the simulation by forward sensitivities where the
    model's simulation is smooth in the parameters (:meth:`_Cost.sensitivities`), finite
    differences where it is not (a warning says so). Measured: the same estimates, and finite
    differences faster on 2 cores (docs/commands.md, "The refinement's Jacobian").

    Returns an :class:`ExtensionFit`: values, std, covariance and correlation, rms errors (with
    the fitted and the start values) on the estimation and validation runs and per run, the
    noise levels, warnings (identifiability, bounds, convergence, refused trial values), and the
    completed config dict (fitted values written in, ``free`` removed) that ``nlsid simulate``
    runs unchanged. Raises :class:`~nlsid.errors.InputError` for a bad key path, start, bound or
    run, and when the model refuses the start values.
    """
    from scipy.optimize import least_squares

    problem = _Problem(config_data, free, source, lines or {}, workers, fit_on)
    est_inputs, val_inputs = problem.inputs(estimation), problem.inputs(validation)
    scale = _scales(problem.start, problem.lower, problem.upper)
    est_start = problem.errors(problem.start, estimation, est_inputs)  # the start must run: its error stops the fit
    cost = _Cost.of(problem, estimation, est_inputs)
    # every run fitted whole: the cost's residual is the start's error already simulated (not again)
    start_residual = (np.concatenate(est_start[fit_on]) if cost.whole(estimation)
                      else cost.residuals(problem, [problem.start], fit_on)[0])
    cost_rms = _rms([start_residual])
    penalty = np.full(start_residual.size, 10.0 * cost_rms if cost_rms > 0 else 1.0)
    x0 = problem.start / scale
    evaluations, refused = 0, []

    last = [x0, start_residual]  # the last point evaluated and its residual: the Jacobian's base

    def residual(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        if np.array_equal(x, x0):  # the start, simulated already
            out = start_residual.copy()
        else:
            try:
                out = cost.residuals(problem, [x * scale], fit_on)[0]
            except InputError as exc:  # a value the model refuses: a rejected step (module docstring)
                refused.append(exc)
                out = penalty
        last[:] = [x.copy(), out]
        return out

    def columns(xs: list[np.ndarray]) -> list[np.ndarray]:
        """The residuals at the Jacobian's perturbed points, simulated together."""
        nonlocal evaluations
        evaluations += len(xs)
        try:
            return cost.residuals(problem, [x * scale for x in xs], fit_on)
        except InputError:  # one of them refused: each on its own, the refused ones rejected steps
            evaluations -= len(xs)
            return [residual(x) for x in xs]

    lower_x, upper_x = problem.lower / scale, problem.upper / scale

    if jacobian not in JACOBIANS:
        raise ValueError(f"jacobian must be one of {JACOBIANS}, not {jacobian!r}")
    formed = {name: 0 for name in JACOBIANS}  # how many Jacobians each way
    exact = cost.offset_column(problem, fit_on)  # (index, column) of the output offset, or None
    floor = _floor_cost(cost, estimation, fit_on)
    accepted = []  # the cost at each Jacobian's point: the points scipy accepted

    def jacobian_at(x: np.ndarray) -> np.ndarray:
        """The Jacobian at x: by forward sensitivities where asked for and they apply, else forward
        differences (:func:`forward_steps`) from the residual already evaluated there, the output
        offset's column exact where it is known (:meth:`_Cost.offset_column`)."""
        f0 = last[1] if np.array_equal(x, last[0]) else residual(x)
        jac = cost.sensitivities(problem, x * scale, fit_on) if jacobian == "sensitivities" else None
        formed["sensitivities" if jac is not None else "differences"] += 1
        if jac is not None:
            jac = jac * scale
        else:
            jac = np.empty((f0.size, x.size))
            h = forward_steps(x, diff_step, lower_x, upper_x)
            differenced = [i for i in range(x.size) if exact is None or i != exact[0]]
            shifted = [x + np.diag(h)[i] for i in differenced]  # x + h_i e_i
            for i, xi, f in zip(differenced, shifted, columns(shifted) if shifted else []):
                jac[:, i] = (f - f0) / (xi[i] - x[i])
            if exact is not None:
                jac[:, exact[0]] = exact[1] * scale[exact[0]]
        accepted.append(float(f0 @ f0))
        gained = _recent_gain_db(accepted)
        if stall_db is not None and gained < _stall_threshold(stall_db, stall_share, accepted[-1], floor):
            raise _Stalled(x.copy(), f0, jac, f"stalled: the last {STALL_STEPS} steps lowered the cost by {gained:.3g} dB")
        return jac

    try:
        result = least_squares(residual, x0, jac=jacobian_at, bounds=(lower_x, upper_x), method="trf", x_scale=1.0,
                               max_nfev=max_evaluations, xtol=tolerance, ftol=tolerance, gtol=tolerance)
    except _Stalled as stalled:
        result = stalled
    values = result.x * scale
    warnings = [] if result.status > 0 else [f"optimiser stopped after {evaluations} simulations without converging: {result.message}"]
    if jacobian == "sensitivities" and formed["differences"]:
        warnings.append(f"{formed['differences']} of {sum(formed.values())} Jacobians by finite differences: forward "
                        "sensitivities need a plant whose simulation is smooth in the parameters (no friction, "
                        "saturation, deadzone, backlash or piecewise-linear curve; no initial state fitted)")
    if refused:
        warnings.append(f"{len(refused)} trial value(s) refused by the model were rejected steps (first: {refused[0]})")
    cov, corr, ident = _uncertainty(result.jac, result.fun, scale, problem.names, values, problem.lower, problem.upper,
                                    cost.segments())
    warnings += ident

    est_errors = (cost.split(result.fun, fit_on) if cost.whole(estimation) and problem.signals == (fit_on,)
                  else problem.errors(values, estimation, est_inputs))
    val_errors = problem.errors(values, validation, val_inputs) if validation else {s: [] for s in problem.signals}
    val_start = problem.errors(problem.start, validation, val_inputs) if validation else {s: [] for s in problem.signals}
    runs = []
    for role, rs, errs, starts in (("estimation", estimation, est_errors, est_start),
                                   ("validation", validation, val_errors, val_start)):
        for i, run in enumerate(rs):
            e = errs[fit_on][i]
            y = _steady(run, run.y)
            runs.append(RunError(run.run_id, role, _rms([e]), float(np.sqrt(np.mean(y * y))), noise_rms(run, fit_on),
                                 _rms([starts[fit_on][i]]), int(e.size), _rms([errs["y"][i]]),
                                 _rms([errs["u"][i]]) if "u" in errs else math.nan))
    noise = {role: _pooled([r.noise_rms for r in runs if r.role == role], [r.samples for r in runs if r.role == role])
             for role in ("estimation", "validation")}
    completed = {k: deep_copy(v) for k, v in config_data.items() if k != "free"}
    for name, value in zip(problem.names, values):
        set_value(completed, name, float(value))
    return ExtensionFit(
        names=problem.names, start=problem.start, values=values, std=np.sqrt(np.abs(np.diag(cov))),
        covariance=cov, correlation=corr,
        estimation_rms=_rms(est_errors[fit_on]), validation_rms=_rms(val_errors[fit_on]),
        start_estimation_rms=_rms(est_start[fit_on]), start_validation_rms=_rms(val_start[fit_on]),
        noise_rms_estimation=noise["estimation"], noise_rms_validation=noise["validation"],
        runs=runs, warnings=warnings, config=completed, evaluations=evaluations, message=str(result.message),
        samples=sum(int(e.size) for e in est_errors[fit_on]), bounds=[(float(lo), float(hi)) for lo, hi in zip(problem.lower, problem.upper)],
        fit_on=fit_on, signal_rms={s: {"estimation": _rms(est_errors[s]), "validation": _rms(val_errors[s])}
                                   for s in problem.signals},
        jacobians=formed,
    )


def fit_config_file(model_path: str, runs: Sequence[Run], validation_ids: Sequence[str] | None = None,
                    workers: int | None = None, estimate_start: bool = False, *, validate_on: Sequence[Run] = (),
                    estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
                    fit_on: str = "y", where: str = "", jacobian: str = "differences") -> ExtensionFit:
    """``nlsid fit --model``: the free parameters of a model config file fitted to recorded runs.

    ``estimate_start``: free parameters without a ``start`` begin at the force regression of
    :func:`nlsid.fit.start.force_regression` on the estimation runs (clipped into the bounds)
    instead of the value written in the config. ``validate_on``, the ranges and ``where`` (the
    recording, for messages): :func:`split_runs`; ``fit_on``, ``jacobian``: :func:`fit_free_parameters`.
    """
    from nlsid.io.config import load_yaml

    data, lines = load_yaml(model_path)
    return fit_config(data, runs, validation_ids, workers, estimate_start, validate_on=validate_on,
                      estimation_range=estimation_range, validation_range=validation_range, fit_on=fit_on,
                      where=where, jacobian=jacobian, source=str(model_path), lines=lines)


def fit_config(data: dict, runs: Sequence[Run], validation_ids: Sequence[str] | None = None,
               workers: int | None = None, estimate_start: bool = False, *, validate_on: Sequence[Run] = (),
               estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
               fit_on: str = "y", where: str = "", jacobian: str = "differences", source: str = "model",
               lines: dict | None = None) -> ExtensionFit:
    """:func:`fit_config_file` of a config already loaded (a dict as :func:`nlsid.io.config.load_yaml`
    gives it); ``source`` and ``lines`` name its origin in messages."""
    model_path = source
    config = validate_simulate_config(data, model_path, lines or {})
    if not config.free:
        raise InputError(str(model_path), "free: no free parameters to fit; mark them under a top-level free: key")
    estimation, validation = split_runs(runs, validation_ids, validate_on, estimation_range, validation_range, where)
    free = free_from_config(config.free)
    if estimate_start:
        from nlsid.fit.start import force_regression

        open_keys = [key for key, p in free.items() if p.start is None]
        estimates = force_regression(data, estimation, open_keys) if open_keys else {}
        free = {key: dataclasses.replace(p, start=float(np.clip(estimates[key], p.lower, p.upper)))
                if key in estimates else p for key, p in free.items()}
    return fit_free_parameters(data, free, estimation, validation, source=str(model_path), lines=lines,
                               workers=workers, fit_on=fit_on, jacobian=jacobian)
