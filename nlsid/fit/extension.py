"""Free parameters of a model config estimated by minimising the simulation error on measured runs.

Given a model config (the loaded YAML as a dict), free parameters named by dotted key paths into
it (:mod:`nlsid.fit.free_parameters`) and measured runs, the estimate is

    theta_hat = argmin_theta  sum_{runs r in E} sum_{n in steady state of r} (s_sim,r(n; theta) - s_r(n))^2

over the estimation runs E (:mod:`nlsid.fit.run_split`), for the fitted signal s, ``y`` or in
closed loop ``u``: the simulation error of :mod:`nlsid.fit.simulation_cost`, where periodic runs
are fitted on their mean period. Its uncertainty and the identifiability warnings:
:mod:`nlsid.fit.uncertainty`.

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
everything else (open loop, no initial state fitted: :meth:`nlsid.fit.simulation_cost.Cost.offset_column`), is exact and
costs no simulation. Simulations of the runs of one evaluation run in parallel threads
(:func:`nlsid.simulate.batch.simulate_all`), those of all the Jacobian's columns in one pool.

The validation runs are never used by the optimiser: their rms errors, and each run's noise level
(the period-to-period standard deviation of the fitted signal, a lower limit no model can beat),
tell how well the fitted model predicts data it has not seen.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.extension_result import ExtensionFit, RunError
from nlsid.fit.free_parameters import FreeParameter, free_from_config
from nlsid.fit.run_split import split_runs
from nlsid.fit.simulation_cost import Cost, Problem, floor_cost, noise_rms, steady
from nlsid.fit.uncertainty import sandwich_covariance
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.ranges import SampleRange
from nlsid.io.run import Run
from nlsid.models.key_paths import deep_copy, set_value
from nlsid.simulate.channels import absent_notes
from nlsid.simulate.threads import blas_in_one_thread


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


STALL_STEPS = 4      # accepted steps over which a stall (fit_free_parameters' stall_db) is judged


def _recent_gain_db(costs: list[float]) -> float:
    """10 log10 of the cost STALL_STEPS accepted points ago over the last one (inf before there are
    that many, or at a zero cost)."""
    if len(costs) <= STALL_STEPS or costs[-1] <= 0:
        return math.inf
    return 10 * math.log10(costs[-1 - STALL_STEPS] / costs[-1])


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


JACOBIANS = ("differences", "sensitivities")


@blas_in_one_thread
def fit_free_parameters(config_data: dict, free: dict[str, FreeParameter], estimation: Sequence[Run],
                        validation: Sequence[Run], *, source: str = "", lines: dict | None = None,
                        workers: int | None = None, diff_step: float = 1e-3, max_evaluations: int = 100,
                        tolerance: float = 1e-8, fit_on: str = "y", stall_db: float | None = None,
                        stall_share: float | None = None,
                        jacobian: str = "differences", run_errors: bool = True) -> ExtensionFit:
    """Estimate the free parameters of a model config by minimising the simulation error.

    ``config_data``: the model config as loaded YAML (a dict, e.g. from
    :func:`nlsid.io.config.load_yaml`); its ``free``, ``disturbances`` (the simulation is
    noise-free) are ignored and ``sweep`` is refused. ``free``: dotted key path -> start and bounds
    (:func:`nlsid.fit.free_parameters.free_from_config` converts a config's ``free:`` section).
    ``estimation``: runs with a measured ``y`` the optimiser sees; ``validation``: runs it does not
    (may be empty).
    ``source`` and ``lines`` (from ``load_yaml``) let errors name the config file and line.
    ``fit_on``: the signal whose simulation error is minimised, ``y`` or (closed loop) ``u``.
    ``stall_db``: the fit also stops, as converged, where the last STALL_STEPS accepted steps
    lowered the cost by less than ``stall_db`` dB together (a search creeping along a valley:
    its error can no longer change by more than about that). ``stall_share``: the threshold is
    at least this share of the cost's distance in dB above the noise floor of the estimation runs
    (where they measure it: P >= 2 steady periods each; :func:`nlsid.fit.simulation_cost.floor_cost`): at that pace the
    search would need STALL_STEPS / stall_share more steps to reach the floor.
    ``jacobian``: ``"differences"``, forward finite differences (:func:`forward_steps`);
    ``"sensitivities"``, the exact derivatives of the simulation by forward sensitivities where the
    model's simulation is smooth in the parameters (:meth:`nlsid.fit.simulation_cost.Cost.sensitivities`), finite
    differences where it is not (a warning says so). Measured: the same estimates, and finite
    differences faster on 2 cores (docs/commands.md, "The refinement's Jacobian").
    ``run_errors``: False leaves out what only the report needs, the errors of every run as
    measured (not on its mean period) at the start and at the fitted values and the initial
    states fitted to arbitrary records: two simulations of every run fitted on its mean period
    (about 5 % of a diagnosis's simulation time on the battery). The start must still run (its
    residual is evaluated first), and the estimates are the same; ``start_estimation_rms`` is NaN,
    ``estimation_rms`` and the ``y``/``u`` errors too where the runs are fitted on their mean
    periods, and ``runs`` holds no estimation run (for callers that take the parameters alone:
    ``diagnose``'s refinements).

    Returns an :class:`ExtensionFit`: values, std, covariance and correlation, rms errors (with
    the fitted and the start values) on the estimation and validation runs and per run, the
    noise levels, warnings (identifiability, bounds, convergence, refused trial values), and the
    completed config dict (fitted values written in, ``free`` removed) that ``nlsid simulate``
    runs unchanged. Raises :class:`~nlsid.errors.InputError` for a bad key path, start, bound or
    run, and when the model refuses the start values.
    """
    from scipy.optimize import least_squares

    problem = Problem(config_data, free, source, lines or {}, workers, fit_on)
    est_inputs, val_inputs = problem.inputs(estimation), problem.inputs(validation)
    scale = _scales(problem.start, problem.lower, problem.upper)
    # the start must run: its error stops the fit
    est_start = problem.errors(problem.start, estimation, est_inputs) if run_errors else None
    cost = Cost.of(problem, estimation, est_inputs)
    # every run fitted whole: the cost's residual is the start's error already simulated (not again)
    start_residual = (np.concatenate(est_start[fit_on]) if est_start is not None and cost.whole(estimation)
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
    floor = floor_cost(cost, estimation, fit_on)
    accepted = []  # the cost at each Jacobian's point: the points scipy accepted

    def jacobian_at(x: np.ndarray) -> np.ndarray:
        """The Jacobian at x: by forward sensitivities where asked for and they apply, else forward
        differences (:func:`forward_steps`) from the residual already evaluated there, the output
        offset's column exact where it is known (:meth:`nlsid.fit.simulation_cost.Cost.offset_column`)."""
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
    cov, corr, ident = sandwich_covariance(result.jac, result.fun, scale, problem.names, values, problem.lower, problem.upper,
                                    cost.segments())
    warnings += ident
    warnings += absent_notes(problem.point(problem.start).config, [*estimation, *validation])

    none = {signal: [] for signal in problem.signals}
    est_errors = (cost.split(result.fun, fit_on) if cost.whole(estimation) and problem.signals == (fit_on,)
                  else problem.errors(values, estimation, est_inputs) if run_errors else None)
    val_errors = problem.errors(values, validation, val_inputs) if validation else none
    val_start = problem.errors(problem.start, validation, val_inputs) if validation else none
    runs = []
    states = initial_states(problem, values, (list(est_inputs) if run_errors else []) + list(val_inputs))
    for role, rs, errs, starts in (("estimation", estimation, est_errors, est_start),
                                   ("validation", validation, val_errors, val_start)):
        for i, run in enumerate(rs if errs is not None and starts is not None else []):
            e = errs[fit_on][i]
            y = steady(run, run.y)
            runs.append(RunError(run.run_id, role, _rms([e]), float(np.sqrt(np.mean(y * y))), noise_rms(run, fit_on),
                                 _rms([starts[fit_on][i]]), int(e.size), _rms([errs["y"][i]]),
                                 _rms([errs["u"][i]]) if "u" in errs else math.nan,
                                 states.get(run.run_id)))
    sizes = [run.n_samples if run.period is None else run.n_periods * run.period for run in estimation]
    noise = {role: _pooled([r.noise_rms for r in runs if r.role == role], [r.samples for r in runs if r.role == role])
             for role in ("estimation", "validation")}
    if not any(r.role == "estimation" for r in runs):  # the per-run errors left out (run_errors): from the data
        noise["estimation"] = _pooled([noise_rms(run, fit_on) for run in estimation], sizes)
    est_errors, est_start = est_errors or none, est_start or none
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
        samples=sum(sizes), bounds=[(float(lo), float(hi)) for lo, hi in zip(problem.lower, problem.upper)],
        fit_on=fit_on, signal_rms={s: {"estimation": _rms(est_errors[s]), "validation": _rms(val_errors[s])}
                                   for s in problem.signals},
        jacobians=formed,
    )


def initial_states(problem: Problem, values: np.ndarray, inputs: Sequence[Run]) -> dict[str, dict]:
    """Run id -> the summary of the initial state the fitted model starts each arbitrary record
    from (:func:`nlsid.simulate.runs.fitted_initial_state`), for the runs where one is fitted."""
    from nlsid.simulate.batch import build
    from nlsid.simulate.runs import fitted_initial_state

    point = problem.point(values)
    model, loop = build(point)
    out = {}
    for run in inputs:
        state = fitted_initial_state(model, loop, run, point.config.simulation.substeps)
        if state is not None:
            out[run.run_id] = state.summary()
    return out


def fit_config_file(model_path: str, runs: Sequence[Run], validation_ids: Sequence[str] | None = None,
                    workers: int | None = None, estimate_start: bool = False, *, validate_on: Sequence[Run] = (),
                    estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
                    fit_on: str = "y", where: str = "", jacobian: str = "differences") -> ExtensionFit:
    """``nlsid fit --model``: the free parameters of a model config file fitted to recorded runs.

    ``estimate_start``: free parameters without a ``start`` begin at the force regression of
    :func:`nlsid.fit.start.force_regression` on the estimation runs (clipped into the bounds)
    instead of the value written in the config. ``validate_on``, the ranges and ``where`` (the
    recording, for messages): :func:`nlsid.fit.run_split.split_runs`; ``fit_on``, ``jacobian``:
    :func:`fit_free_parameters`.
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
    if config.model.type == "mimo_state_space":  # every output at once (nlsid.fit.mimo_output_error)
        from nlsid.fit.mimo_output_error import fit_mimo_free_parameters

        for flag, refused, why in (("--fit-on", fit_on != "y", "fitted on its outputs y (there is no closed loop)"),
                                   ("--start-estimate", estimate_start, "started from the values written in its "
                                                                        "config (the start estimate is of forces)"),
                                   ("--jacobian", jacobian != "differences", "fitted with a Jacobian by finite "
                                                                             "differences")):
            if refused:
                raise InputError(flag, f"a mimo_state_space model ({model_path}) is {why}")
        return fit_mimo_free_parameters(data, free, estimation, validation, source=str(model_path), lines=lines,
                                        where=where)
    if estimate_start:
        from nlsid.fit.start import force_regression

        open_keys = [key for key, p in free.items() if p.start is None]
        estimates = force_regression(data, estimation, open_keys) if open_keys else {}
        free = {key: dataclasses.replace(p, start=float(np.clip(estimates[key], p.lower, p.upper)))
                if key in estimates else p for key, p in free.items()}
    return fit_free_parameters(data, free, estimation, validation, source=str(model_path), lines=lines,
                               workers=workers, fit_on=fit_on, jacobian=jacobian)
