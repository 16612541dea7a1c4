"""The simulation error of a model config on measured runs, as a function of its free parameters.

Given a model config (the loaded YAML as a dict), a set of *free* parameters named by dotted key
paths into it (:mod:`nlsid.fit.free_parameters`), and measured runs, the estimate of
:func:`nlsid.fit.extension.fit_free_parameters` is

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
input channels (not periodic) are fitted whole. The sandwich covariance (:mod:`nlsid.fit.uncertainty`) is the same in this form: its
noise is divided by P and multiplied by P again. The errors reported are those of the whole runs.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.free_parameters import FreeParameter, value_at
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.ranges import record
from nlsid.io.run import Run
from nlsid.models.key_paths import deep_copy, set_value
from nlsid.simulate.sweep import SweepPoint
from nlsid.simulate.loop_state import loop_excitation


def steady(run: Run, x: np.ndarray) -> np.ndarray:
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
        return None if x is None else steady(run, x).reshape(run.n_periods, run.period).mean(axis=0)

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


class Problem:
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
            # freed initial values of equations are the start of every run: none fitted per record
            written = keep_r and any(name.startswith("model.states.") for name in self.names)
            if self.closed:  # the recorded command kept to fit the loop's initial state (nlsid.simulate.loop_state)
                out.append(loop_excitation(record(run)))
            else:
                whole = record(run)
                out.append(dataclasses.replace(whole, r=run.r if keep_r else None, y=None if written else whole.y))
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
        return [{s: [steady(run, getattr(simulated[i * count + j], s)) - steady(run, getattr(run, s))
                     for i, run in enumerate(runs)] for s in self.signals} for j in range(count)]


@dataclass
class Cost:
    """The runs as the optimiser sees them (:func:`_compact`): measured runs, excitations, weights."""

    runs: list[Run]
    inputs: list[Run]
    weights: np.ndarray

    @classmethod
    def of(cls, problem: "Problem", runs: Sequence[Run], inputs: Sequence[Run]) -> "Cost":
        point = problem.point(problem.start)
        out = cls([], [], np.ones(len(runs)))
        for i, (run, excitation) in enumerate(zip(runs, inputs)):
            compact = _compact(run, excitation, point)
            measured, short, weight = compact if compact is not None else (run, excitation, 1.0)
            out.runs.append(measured)
            out.inputs.append(short)
            out.weights[i] = weight
        return out

    def residuals(self, problem: "Problem", thetas: Sequence[np.ndarray], signal: str) -> list[np.ndarray]:
        """The weighted residual vector of each parameter vector (module docstring)."""
        return [np.concatenate([w * e for w, e in zip(self.weights, errors[signal])])
                for errors in problem.errors_many(thetas, self.runs, self.inputs)]

    def whole(self, runs: Sequence[Run]) -> bool:
        """Every one of ``runs`` (the estimation runs) fitted as it is (none :func:`_compact`)."""
        return all(fitted is run for fitted, run in zip(self.runs, runs))

    def split(self, residual: np.ndarray, signal: str) -> dict[str, list[np.ndarray]]:
        """The residual vector of :meth:`residuals` as the per-run errors of ``signal``
        (:meth:`Problem.errors`), for runs fitted :meth:`whole` (weight 1)."""
        return {signal: np.split(residual, np.cumsum(self.segments())[:-1])}

    def segments(self) -> list[int]:
        """Samples of each run's residual (:func:`steady`'s)."""
        return [run.n_samples if run.period is None else run.n_periods * run.period for run in self.runs]

    @property
    def fits_initial_states(self) -> bool:
        """Some run is an arbitrary record simulated from the initial state fitted to its measured
        output (:mod:`nlsid.simulate.initial_state`), which depends on the parameters too."""
        return any(run.period is None and run.y is not None for run in self.inputs)

    def sensitivities(self, problem: "Problem", theta: np.ndarray, signal: str) -> np.ndarray | None:
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
        return np.concatenate([w * np.stack([steady(run, d[lead:]) for d in out[column]], axis=1)
                               for w, run, lead, out in zip(self.weights, self.runs, leads, simulated)])

    def offset_column(self, problem: "Problem", signal: str) -> tuple[int, np.ndarray] | None:
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


def floor_cost(cost: "Cost", runs: Sequence[Run], signal: str) -> float:
    """The cost expected at the noise floor of ``runs`` (the estimation runs ``cost`` was made of):
    the sum over runs of (residual samples) x (noise variance per sample, :func:`noise_rms`). A
    compact run's residual is sqrt(P) times the error of the mean of P periods, whose noise
    variance is sigma^2 / P, so each of its samples contributes sigma^2 as a whole run's does. NaN
    where a run has no noise level (fewer than two periods)."""
    return float(sum(size * noise_rms(run, signal) ** 2 for size, run in zip(cost.segments(), runs)))
