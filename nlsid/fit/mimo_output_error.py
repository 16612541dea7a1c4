"""Free parameters of a ``mimo_state_space`` model fitted by output error on every output at once.

A model of n_u inputs and n_y outputs (:class:`nlsid.models.lti.MimoStateSpace`) with free matrix
entries and numbers of its static blocks per signal named by key paths (``model.A[0][1]``,
``model.B[1][0]``, ``model.output_nonlinearity.y2.upper``: :mod:`nlsid.models.key_paths`) is
fitted to measured runs by

    theta_hat = argmin_theta  sum_{runs r in E} sum_{i = 1..n_y} sum_n ((y_sim,ri(n; theta) - y_ri(n)) / sigma_i)^2

over the estimation runs E: the simulation errors of all outputs stacked, output i weighted by
1 / sigma_i, its noise level. Without the weights the output of the largest numbers would decide
the fit alone; with them each output's error counts in units of its own noise, which is the
maximum-likelihood weighting for independent white output noise (Pintelon and Schoukens 2012,
Section 9.4: the output-error cost with the inverse noise variance per output).

sigma_i is, in this order of preference (:func:`output_noise`, its ``source`` said in the result):

* ``periods``: where the estimation runs hold P >= 2 steady periods, the period-to-period standard
  deviation of output i pooled over those runs (the noise alone);
* ``rms``: otherwise the rms of output i over the estimation runs (its size: each output's error then
  counts relative to its signal, as in a normalised fit).

A periodic run of P >= 2 steady periods is fitted on its mean period with the weight sqrt(P)
(the same reduction as :mod:`nlsid.fit.simulation_cost`: the period-to-period scatter does not depend
on theta), simulated in its periodic steady state exactly (:func:`nlsid.simulate.mimo.simulate_mimo`
with ``steady``); an arbitrary run is simulated whole from the initial state fitted to its first
samples. The minimisation is :func:`scipy.optimize.least_squares` (trust-region reflective within
the bounds, forward differences) in coordinates normalised by the start values, and the covariance
is the sandwich of :func:`nlsid.fit.uncertainty.sandwich_covariance` with one segment per run and
output. The validation runs are never used by the optimiser: their rms error per output is reported
beside its noise level.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.extension_result import ExtensionFit, RunError
from nlsid.fit.free_parameters import FreeParameter, value_at
from nlsid.fit.simulation_cost import steady
from nlsid.fit.uncertainty import sandwich_covariance
from nlsid.io.model_config import validate_simulate_config
from nlsid.io.ranges import record
from nlsid.io.run import Run
from nlsid.models.key_paths import deep_copy, set_value
from nlsid.models.lti import MimoStateSpace


def output_noise(runs: Sequence[Run], outputs: Sequence[str]) -> tuple[np.ndarray, str]:
    """The noise level sigma_i of each output and where it comes from (module docstring):
    ``periods`` (pooled period-to-period std over the runs of P >= 2 steady periods) or ``rms``
    (the rms of each output over the runs, where none is periodic so)."""
    periodic = [run for run in runs if run.period is not None and run.n_periods >= 2]
    out = np.empty(len(outputs))
    if periodic:
        for i, name in enumerate(outputs):
            dof = sum(run.period * (run.n_periods - 1) for run in periodic)
            ss = sum(float(np.sum(np.var(steady_periods(run, name), axis=0, ddof=1)) * (run.n_periods - 1))
                     for run in periodic)
            out[i] = math.sqrt(ss / dof)
        if np.all(out > 0):
            return out, "periods"
    for i, name in enumerate(outputs):
        parts = [steady(run, run.named_signal(name)) for run in runs]
        out[i] = math.sqrt(sum(float(np.sum(p * p)) for p in parts) / sum(p.size for p in parts))
    if not np.all(out > 0):
        zero = outputs[int(np.flatnonzero(out <= 0)[0])]
        raise InputError(zero, "the output is zero on every estimation run: no error to weigh it by")
    return out, "rms"


def steady_periods(run: Run, name: str) -> np.ndarray:
    """The steady periods of signal or channel ``name`` as a (P, N) array."""
    x = steady(run, run.named_signal(name))
    return x.reshape(run.n_periods, run.period)


def mean_period_run(run: Run, names: Sequence[str]) -> Run:
    """A periodic run of P >= 2 steady periods as one period: each of ``names`` (signals or
    channels) averaged over its steady periods, no transient period (simulated in steady state)."""
    means = {name: steady_periods(run, name).mean(axis=0) for name in names}
    channels = {name: value for name, value in means.items() if name not in ("u", "y", "r")}
    return dataclasses.replace(run, u=means["u"], y=means.get("y"), r=None, transient_periods=0,
                               channels=channels)


@dataclass
class MimoProblem:
    """The config, its free entries and how one parameter vector simulates the runs."""

    base: dict
    names: list[str]
    start: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    source: str = "model"
    lines: dict = field(default_factory=dict)

    @classmethod
    def of(cls, config_data: dict, free: dict[str, FreeParameter], source: str, lines: dict | None) -> "MimoProblem":
        base = {k: deep_copy(v) for k, v in config_data.items() if k not in ("free", "disturbances")}
        names, starts = list(free), []
        if not names:
            raise InputError(source, "free: no free parameters to fit; mark them under a top-level free: key")
        for name, p in free.items():
            line = (lines or {}).get(("free", name))
            where = f"{source}:{line}" if line is not None else source
            try:
                start = p.start if p.start is not None else value_at(base, name)
            except InputError as exc:  # named by the free: key the user wrote, at its line
                raise InputError(where, f"{exc.where}: {exc.what}") from None
            if isinstance(start, bool) or not isinstance(start, (int, float)) or not math.isfinite(start):
                raise InputError(where, f"free.{name}: no number at this key path of the config; give a start "
                                        "value (a matrix entry is model.A[row][column])")
            if not p.lower <= start <= p.upper:
                raise InputError(where, f"free.{name}: start {start:g} outside [{p.lower:g}, {p.upper:g}]")
            starts.append(float(start))
        problem = cls(base, names, np.array(starts), np.array([free[n].lower for n in names]),
                      np.array([free[n].upper for n in names]), source, lines or {})
        problem.model(problem.start)  # the start must give a valid model
        return problem

    def config(self, theta: np.ndarray) -> dict:
        """The config dict with ``theta`` written at the free key paths."""
        data = deep_copy(self.base)
        for name, value in zip(self.names, theta):
            set_value(data, name, float(value), key=f"free.{name}")
        return data

    def model(self, theta: np.ndarray) -> MimoStateSpace:
        from nlsid.models.from_config import model as build

        config = validate_simulate_config(self.config(theta), self.source, self.lines)
        return build(config)

    def outputs(self, theta: np.ndarray, runs: Sequence[Run]) -> list[np.ndarray]:
        """Per run, the simulated outputs (n_y, samples) over the steady part :func:`steady` measures."""
        from nlsid.simulate.mimo import simulate_mimo

        model = self.model(theta)
        return [steady_columns(run, simulate_mimo(model, record(run), steady=True).output_matrix()) for run in runs]


def measured_outputs(runs: Sequence[Run], outputs: Sequence[str]) -> list[np.ndarray]:
    """Per run, the measured outputs (n_y, samples) over the steady part :func:`steady` measures."""
    return [steady_columns(run, np.stack([run.named_signal(name) for name in outputs])) for run in runs]


def steady_columns(run: Run, X: np.ndarray) -> np.ndarray:
    """:func:`nlsid.fit.simulation_cost.steady` of each row of X (signals x samples)."""
    return np.stack([steady(run, row) for row in X])


def compact_runs(runs: Sequence[Run], names: Sequence[str]) -> tuple[list[Run], np.ndarray]:
    """The runs as the optimiser sees them (module docstring) and their weights sqrt(P) (1 for a
    run fitted whole)."""
    from nlsid.io.ranges import RangeRun

    out, weights = [], []
    for run in runs:
        if run.period is not None and run.n_periods >= 2 and not isinstance(run, RangeRun):
            out.append(mean_period_run(run, names))
            weights.append(math.sqrt(run.n_periods))
        else:
            out.append(run)
            weights.append(1.0)
    return out, np.array(weights)


@dataclass
class MimoExtensionFit(ExtensionFit):
    """An :class:`~nlsid.fit.extension.ExtensionFit` of a model of several outputs: its rms numbers
    are of the weighted error (e_i / sigma_i pooled over outputs, so 1 at the noise where sigma
    comes from the periods), and ``outputs`` gives each output's own (:func:`fit_mimo_free_parameters`)."""

    outputs: list[dict] = field(default_factory=list)
    noise_source: str = "periods"

    def output_lines(self) -> list[str]:
        """One line per output: its rms error at the fitted and start values on the estimation and
        validation runs, and its noise level sigma_i (the weight's)."""
        def weight(sigma: float) -> str:
            if self.noise_source == "periods":
                return f"noise level {sigma:.4g} (period-to-period)"
            return f"weighted by its rms {sigma:.4g} (no two periods per run: noise unknown)"

        return [f"output {o['name']}: rms error estimation {o['estimation_rms']:.4g} (start "
                f"{o['start_estimation_rms']:.4g}), validation {o['validation_rms']:.4g} (start "
                f"{o['start_validation_rms']:.4g}); {weight(o['noise'])}" for o in self.outputs]

    def summary(self) -> dict:
        return {**super().summary(), "outputs": [dict(o) for o in self.outputs], "noise_source": self.noise_source,
                "weighted": True}


def check_measured(model: MimoStateSpace, run: Run, where: str) -> None:
    """Refuse a run that lacks an input or a measured output of ``model`` (one message at ``where``,
    the run)."""
    from nlsid.simulate.mimo import check_run

    check_run(model.inputs, model.outputs, run, where)
    for name in model.outputs:
        if run.y is None or (name != "y" and name not in run.channels):
            have = ", ".join(sorted(run.channels)) or "none"
            raise InputError(where, f"has no measured output {name!r} (the model's outputs: "
                                         f"{', '.join(model.outputs)}; the run's channels: {have})")


def _rms(parts: Sequence[np.ndarray]) -> float:
    size = sum(p.size for p in parts)
    return math.sqrt(sum(float(np.sum(p * p)) for p in parts) / size) if size else math.nan


def fit_mimo_free_parameters(config_data: dict, free: dict[str, FreeParameter], estimation: Sequence[Run],
                             validation: Sequence[Run], *, source: str = "model", lines: dict | None = None,
                             where: str = "",
                             diff_step: float = 1e-3, max_evaluations: int = 100,
                             tolerance: float = 1e-8) -> MimoExtensionFit:
    """Fit the free entries (matrix entries, block numbers) of a ``mimo_state_space`` config by the
    weighted output error of every output (module docstring).

    Parameters
    ----------
    config_data : dict
        The model config as loaded YAML, of ``model.type: mimo_state_space``.
    free : dict
        Key path (``model.A[0][1]``, ``model.output_nonlinearity.y2.upper``) ->
        :class:`~nlsid.fit.free_parameters.FreeParameter`. A trial value the config refuses (a
        saturation's lower level above its upper) is a rejected step.
    estimation, validation : sequence of Run
        Runs with every output of the model measured; the optimiser sees the estimation runs only.
    source, lines, where : str, dict, str
        The config's name and line map, and the recording's name (runs named ``WHERE:/runs/ID``),
        for messages.
    diff_step, max_evaluations, tolerance
        Forward-difference step relative to each parameter, the simulation budget and the
        tolerances of :func:`scipy.optimize.least_squares`.

    Returns
    -------
    MimoExtensionFit
        ``estimation_rms`` and ``validation_rms`` are of the weighted error e_i / sigma_i (pooled
        over outputs); ``outputs`` has, for each output, its name, sigma_i, and the rms error (in
        its own unit) at the start and fitted values on the estimation and validation runs.
    """
    from scipy.optimize import least_squares

    problem = MimoProblem.of(config_data, free, source, lines)
    names = list(problem.model(problem.start).outputs)
    inputs = list(problem.model(problem.start).inputs)
    for run in [*estimation, *validation]:
        check_measured(problem.model(problem.start), run, f"{where}:/runs/{run.run_id}" if where else run.run_id)
    sigma, noise_source = output_noise(estimation, names)
    compact, weights = compact_runs(estimation, [*inputs, *names])
    measured = measured_outputs(compact, names)

    def residual_of(theta: np.ndarray) -> np.ndarray:
        simulated = problem.outputs(theta, compact)
        return np.concatenate([(w * (s - m) / sigma[:, None]).ravel()
                               for w, s, m in zip(weights, simulated, measured)])

    scale = np.where(problem.start != 0, np.abs(problem.start), 1.0)
    start_residual = residual_of(problem.start)
    penalty = np.full(start_residual.size, 10 * max(_rms([start_residual]), 1e-300))
    evaluations, refused = 0, []

    def residual(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        try:
            return residual_of(x * scale)
        except InputError as exc:  # an unstable trial: a rejected step (nlsid.fit.extension's docstring)
            refused.append(exc)
            return penalty

    result = least_squares(residual, problem.start / scale, bounds=(problem.lower / scale, problem.upper / scale),
                           method="trf", diff_step=diff_step, max_nfev=max_evaluations, xtol=tolerance,
                           ftol=tolerance, gtol=tolerance)
    values = result.x * scale
    warnings = [] if result.status > 0 else [f"optimiser stopped after {evaluations} simulations without "
                                             f"converging: {result.message}"]
    if refused:
        warnings.append(f"{len(refused)} trial value(s) refused by the model were rejected steps (first: {refused[0]})")
    segments = [m.shape[1] for m in measured for _ in names]  # one per run and output, in the residual's order
    cov, corr, ident = sandwich_covariance(result.jac, result.fun, scale, problem.names, values, problem.lower,
                                           problem.upper, segments)
    warnings += ident

    def errors(theta: np.ndarray, runs: Sequence[Run]) -> list[np.ndarray]:
        return [s - m for s, m in zip(problem.outputs(theta, runs), measured_outputs(runs, names))]

    fitted = {"estimation": errors(values, estimation), "validation": errors(values, validation)}
    started = {"estimation": errors(problem.start, estimation), "validation": errors(problem.start, validation)}
    outputs = []
    for i, name in enumerate(names):
        outputs.append({"name": name, "noise": float(sigma[i]), **{
            f"{role}_rms": _rms([e[i] for e in fitted[role]]) for role in fitted}, **{
            f"start_{role}_rms": _rms([e[i] for e in started[role]]) for role in started}})

    def weighted(parts: list[np.ndarray]) -> list[np.ndarray]:
        return [e / sigma[:, None] for e in parts]

    runs = []
    for role, rs in (("estimation", estimation), ("validation", validation)):
        for run, e, e0 in zip(rs, fitted[role], started[role]):
            y = steady(run, run.y)
            noise = (float(np.sqrt(np.mean(np.var(steady_periods(run, "y"), axis=0, ddof=1))))
                     if run.period is not None and run.n_periods >= 2 else math.nan)
            runs.append(RunError(run.run_id, role, _rms([e[0]]), float(np.sqrt(np.mean(y * y))), noise,
                                 _rms([e0[0]]), int(e.shape[1]), _rms([e[0]])))
    sizes = [m.shape[1] for m in measured_outputs(estimation, names)]
    unit = 1.0 if noise_source == "periods" else math.nan  # the weighted error's noise level
    completed = {k: deep_copy(v) for k, v in config_data.items() if k != "free"}
    for name, value in zip(problem.names, values):
        set_value(completed, name, float(value))
    return MimoExtensionFit(
        names=problem.names, start=problem.start, values=values, std=np.sqrt(np.abs(np.diag(cov))),
        covariance=cov, correlation=corr,
        estimation_rms=_rms(weighted(fitted["estimation"])), validation_rms=_rms(weighted(fitted["validation"])),
        start_estimation_rms=_rms(weighted(started["estimation"])),
        start_validation_rms=_rms(weighted(started["validation"])),
        noise_rms_estimation=unit, noise_rms_validation=unit if validation else math.nan,
        runs=runs, warnings=warnings, config=completed, evaluations=evaluations, message=str(result.message),
        samples=sum(sizes), bounds=[(float(lo), float(hi)) for lo, hi in zip(problem.lower, problem.upper)],
        fit_on="y", outputs=outputs, noise_source=noise_source)
