"""Free parameters of a model config estimated by minimising the simulation error on measured runs.

Given a model config (the loaded YAML as a dict), a set of *free* parameters named by dotted key
paths into it (``model.nonlinearities[0].fc``, ``closed_loop.feedforward.coulomb``), and measured
runs, the estimate is

    theta_hat = argmin_theta  sum_{runs r in E} sum_{n in steady state of r} (y_sim,r(n; theta) - y_r(n))^2

over the estimation runs E: each run's recorded input (open loop: ``u``; closed loop: the
reference ``r``) is simulated through the noise-free model with the parameters written into the
config (the ``sweep`` mechanism: :func:`nlsid.simulate.sweep._set`, then the full config
validation), and compared with the recorded ``y`` over the steady-state periods
(``run.periods("y")``; the whole record for a run without periods). In closed loop this is the
error of y with the loop closed in the simulation.

The minimisation is :func:`scipy.optimize.least_squares` (trust-region reflective, bounds) in
normalised coordinates x_i = theta_i / s_i (s_i the start value's magnitude), with a forward
finite-difference Jacobian whose step is ``diff_step`` relative to each parameter. Simulations of
the runs of one evaluation run in parallel threads (:func:`nlsid.simulate.batch.simulate_all`).

Uncertainty (Gauss-Newton at the optimum, the output error taken as white with variance
sigma^2 = 2 V / (n - p), n samples, p parameters):

    cov(theta_hat) = sigma^2 S (J^T J)^{-1} S,     S = diag(s),

with J the Jacobian of the residuals in x. This is the Cramér-Rao form for white Gaussian output
noise and a correct model; coloured noise or model errors make it optimistic.

Identifiability: a warning names a parameter that has no effect (zero Jacobian column), a nearly
singular J^T J (a combination of parameters the data cannot tell apart: singular value ratio
below 1e-6), a pair with correlation above 0.99 in magnitude, a relative standard deviation above
50 %, or an estimate at a bound.

The validation runs are never used by the optimiser: their rms errors, and each run's noise level
(the period-to-period standard deviation of y, a lower limit no model can beat), tell how well the
fitted model predicts data it has not seen.
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
from nlsid.simulate.sweep import SweepPoint, _deep_copy, _keys, _set

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
    """Simulation error of one run: rms of y_sim - y over the steady state, the rms of y itself and
    the noise level (period-to-period std of y, NaN with fewer than two periods)."""

    run_id: str
    role: str            # "estimation" or "validation"
    rms: float
    y_rms: float
    noise_rms: float
    start_rms: float     # the same error with the start values
    samples: int


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
            "runs": [dataclasses.asdict(r) for r in self.runs],
            "samples": self.samples,
            "evaluations": self.evaluations,
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
    """The value at a dotted key path of a config dict (None when a mapping key along it is absent)."""
    keys = _keys(path)
    if keys is None:
        raise InputError(f"free.{path}", "expected a dotted key path such as model.nonlinearities[0].fc")
    node = data
    for key in keys:
        if isinstance(key, int):
            if not isinstance(node, list) or key >= len(node):
                raise InputError(f"free.{path}", f"no item [{key}] in the config")
            node = node[key]
        elif isinstance(node, dict):
            if key not in node:
                return None
            node = node[key]
        else:
            raise InputError(f"free.{path}", f"{key!r} is not a key of a mapping in the config")
    return node


def split_runs(runs: Sequence[Run], validation_ids: Sequence[str] | None = None) -> tuple[list[Run], list[Run]]:
    """Estimation and validation runs.

    With ``validation_ids``: those runs are held out. Default: when the runs carry two or more
    realization indices, the highest realization of every level is held out (each level stays in
    the estimation set); otherwise the last run is held out. One run alone cannot be split.
    """
    runs = list(runs)
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
    validation = [r for r in runs if r.run_id in held]
    if not estimation:
        raise InputError("validation runs", "every run is held out for validation: none is left to fit")
    return estimation, validation


def _steady(run: Run, x: np.ndarray) -> np.ndarray:
    """The samples of ``x`` (a signal of ``run``) that the error is measured on."""
    if run.period is None:
        return x
    return x[run.transient_periods * run.period:]


def noise_rms(run: Run) -> float:
    """Period-to-period standard deviation of y (pooled over the samples of a period), NaN if P < 2."""
    if run.period is None or run.n_periods < 2:
        return math.nan
    return float(np.sqrt(np.mean(np.var(run.periods("y"), axis=0, ddof=1))))


class _Problem:
    """The config, the free keys and the runs; evaluates simulation errors for parameter values."""

    def __init__(self, config_data: dict, free: dict[str, FreeParameter], source: str, lines: dict,
                 workers: int | None):
        if "sweep" in config_data:
            raise InputError(_where(source, lines, ("sweep",)), "sweep: a config with free parameters cannot sweep; remove sweep")
        base = {k: _deep_copy(v) for k, v in config_data.items() if k not in ("free", "disturbances")}
        self.base, self.source, self.lines, self.workers = base, source, lines or {}, workers
        self.names = list(free)
        if not self.names:
            raise InputError(source or "free", "no free parameters: mark at least one under free:")
        starts = []
        for name, p in free.items():
            where = _where(source, self.lines, ("free", name))
            start = p.start if p.start is not None else value_at(base, name)
            if isinstance(start, bool) or not isinstance(start, (int, float)) or not math.isfinite(start):
                raise InputError(where, f"free.{name}: no number at this key path of the config; give a start value")
            if not p.lower <= start <= p.upper:
                raise InputError(where, f"free.{name}: start {start:g} outside [{p.lower:g}, {p.upper:g}]")
            starts.append(float(start))
        self.start = np.array(starts)
        self.lower = np.array([free[n].lower for n in self.names])
        self.upper = np.array([free[n].upper for n in self.names])
        self.closed = "closed_loop" in base
        self.point(self.start)  # the start must give a valid config

    def data(self, theta: np.ndarray) -> dict:
        data = _deep_copy(self.base)
        for name, value in zip(self.names, theta):
            try:
                _set(data, name, float(value), key=f"free.{name}")
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
            out.append(dataclasses.replace(run, u=run.r if self.closed else run.u, y=None, r=None))
        return out

    def errors(self, theta: np.ndarray, runs: Sequence[Run], excitations: Sequence[Run]) -> list[np.ndarray]:
        """Per run, y_sim - y over the steady state."""
        from nlsid.simulate.batch import simulate_all

        simulated = simulate_all([self.point(theta)], list(excitations), workers=self.workers)
        return [_steady(run, sim.y) - _steady(run, run.y) for run, sim in zip(runs, simulated)]


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
        out[i] = width if math.isfinite(width) else (bigger if math.isfinite(bigger) and bigger > 0 else 1.0)
    return out


def _uncertainty(jac: np.ndarray, residual: np.ndarray, scale: np.ndarray, names: list[str], values: np.ndarray,
                 lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Covariance of theta (module docstring) and the identifiability warnings."""
    n, p = jac.shape
    warnings = []
    sigma2 = float(residual @ residual) / max(n - p, 1)
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
        cov_x = (vt.T / np.maximum(sv, IDENTIFIABLE_RATIO * sv[0]) ** 2) @ vt
        cov = sigma2 * cov_x * np.outer(scale, scale)
        std = np.sqrt(np.abs(np.diag(cov)))
        spread = np.sqrt(np.diag(cov_x))  # > 0: every singular value is clamped above 0
        corr = cov_x / np.outer(spread, spread)
    for i in range(p):
        for j in range(i + 1, p):
            if abs(corr[i, j]) > CORRELATION_LIMIT:
                warnings.append(f"{names[i]} and {names[j]}: correlation {corr[i, j]:+.3f} (nearly interchangeable)")
        if values[i] != 0 and std[i] > RELATIVE_STD_LIMIT * abs(values[i]):
            warnings.append(f"{names[i]}: poorly determined (std {std[i]:.3g} is {100 * std[i] / abs(values[i]):.0f} % of its value)")
        if values[i] <= lower[i] or values[i] >= upper[i]:
            warnings.append(f"{names[i]}: estimate {values[i]:.6g} is at its bound; widen the bounds or check the model")
    return cov, corr, warnings


def fit_free_parameters(config_data: dict, free: dict[str, FreeParameter], estimation: Sequence[Run],
                        validation: Sequence[Run], *, source: str = "", lines: dict | None = None,
                        workers: int | None = None, diff_step: float = 1e-3, max_evaluations: int = 100,
                        tolerance: float = 1e-8) -> ExtensionFit:
    """Estimate the free parameters of a model config by minimising the simulation error.

    ``config_data``: the model config as loaded YAML (a dict, e.g. from
    :func:`nlsid.io.config.load_yaml`); its ``free``, ``disturbances`` (the simulation is
    noise-free) are ignored and ``sweep`` is refused. ``free``: dotted key path -> start and bounds
    (:func:`free_from_config` converts a config's ``free:`` section). ``estimation``: runs with a
    measured ``y`` the optimiser sees; ``validation``: runs it does not (may be empty).
    ``source`` and ``lines`` (from ``load_yaml``) let errors name the config file and line.

    Returns an :class:`ExtensionFit`: values, std, covariance and correlation, rms errors (with
    the fitted and the start values) on the estimation and validation runs and per run, the
    noise levels, warnings (identifiability, bounds, convergence), and the completed config dict
    (fitted values written in, ``free`` removed) that ``nlsid simulate`` runs unchanged.
    Raises :class:`~nlsid.errors.InputError` for a bad key path, start, bound or run.
    """
    from scipy.optimize import least_squares

    problem = _Problem(config_data, free, source, lines or {}, workers)
    est_inputs, val_inputs = problem.inputs(estimation), problem.inputs(validation)
    scale = _scales(problem.start, problem.lower, problem.upper)
    evaluations = 0

    def residual(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        return np.concatenate(problem.errors(x * scale, estimation, est_inputs))

    x0 = problem.start / scale
    result = least_squares(residual, x0, bounds=(problem.lower / scale, problem.upper / scale), method="trf",
                           diff_step=diff_step, x_scale=1.0, max_nfev=max_evaluations, xtol=tolerance,
                           ftol=tolerance, gtol=tolerance)
    values = result.x * scale
    warnings = [] if result.status > 0 else [f"optimiser stopped after {evaluations} simulations without converging: {result.message}"]
    cov, corr, ident = _uncertainty(result.jac, result.fun, scale, problem.names, values, problem.lower, problem.upper)
    warnings += ident

    est_errors = problem.errors(values, estimation, est_inputs)
    est_start = problem.errors(problem.start, estimation, est_inputs)
    val_errors = problem.errors(values, validation, val_inputs) if validation else []
    val_start = problem.errors(problem.start, validation, val_inputs) if validation else []
    runs = []
    for role, rs, errs, starts in (("estimation", estimation, est_errors, est_start),
                                   ("validation", validation, val_errors, val_start)):
        for run, e, e0 in zip(rs, errs, starts):
            y = _steady(run, run.y)
            runs.append(RunError(run.run_id, role, _rms([e]), float(np.sqrt(np.mean(y * y))), noise_rms(run),
                                 _rms([e0]), int(e.size)))
    noise = {role: _pooled([r.noise_rms for r in runs if r.role == role], [r.samples for r in runs if r.role == role])
             for role in ("estimation", "validation")}
    completed = {k: _deep_copy(v) for k, v in config_data.items() if k != "free"}
    for name, value in zip(problem.names, values):
        _set(completed, name, float(value))
    return ExtensionFit(
        names=problem.names, start=problem.start, values=values, std=np.sqrt(np.abs(np.diag(cov))),
        covariance=cov, correlation=corr,
        estimation_rms=_rms(est_errors), validation_rms=_rms(val_errors),
        start_estimation_rms=_rms(est_start), start_validation_rms=_rms(val_start),
        noise_rms_estimation=noise["estimation"], noise_rms_validation=noise["validation"],
        runs=runs, warnings=warnings, config=completed, evaluations=evaluations, message=str(result.message),
        samples=int(result.fun.size), bounds=[(float(lo), float(hi)) for lo, hi in zip(problem.lower, problem.upper)],
    )


def fit_config_file(model_path: str, runs: Sequence[Run], validation_ids: Sequence[str] | None = None,
                    workers: int | None = None, estimate_start: bool = False) -> ExtensionFit:
    """``nlsid fit --model``: the free parameters of a model config file fitted to recorded runs.

    ``estimate_start``: free parameters without a ``start`` begin at the force regression of
    :func:`nlsid.fit.start.force_regression` on the estimation runs (clipped into the bounds)
    instead of the value written in the config.
    """
    from nlsid.io.config import load_yaml

    data, lines = load_yaml(model_path)
    config = validate_simulate_config(data, model_path, lines)
    if not config.free:
        raise InputError(str(model_path), "free: no free parameters to fit; mark them under a top-level free: key")
    estimation, validation = split_runs(runs, validation_ids)
    free = free_from_config(config.free)
    if estimate_start:
        from nlsid.fit.start import force_regression

        open_keys = [key for key, p in free.items() if p.start is None]
        estimates = force_regression(data, estimation, open_keys) if open_keys else {}
        free = {key: dataclasses.replace(p, start=float(np.clip(estimates[key], p.lower, p.upper)))
                if key in estimates else p for key, p in free.items()}
    return fit_free_parameters(data, free, estimation, validation, source=str(model_path), lines=lines,
                               workers=workers)
