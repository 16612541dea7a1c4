"""What every hypothesis of the library is made of: its estimate, its definition, the context it is
estimated in, and the regression and search tools the estimates share."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.io.run import Run


@dataclass
class Context:
    """What the estimates need: the nominal model, the estimation runs, their residual periods, the
    model's internal signals on them (full length), the BLA levels (measured, model) and the
    final estimates of the hypotheses before this one in :data:`LIBRARY`, by name, with their
    extended configs (every fitted value written in, nuisances too) in ``extended`` and, in
    ``improves``, whether each one's gain over the model on the validation runs is at least
    suggestive (:func:`nlsid.diagnose.verdict.suggestive`), and in ``errors`` its validation error:
    a costly richer member of a family that starts from a simpler one's fit need not be sought
    where the simpler one does not lead (:meth:`leads`).

    ``signal`` is the judged signal, the output ``y`` or in closed loop the command ``u``
    (``diagnose --fit-on``): the residuals, :meth:`simulation_rss` and :meth:`response` are of
    it, so a signature regresses what the model misses of that signal on that signal's response."""

    runner: ModelRunner
    runs: list[Run]
    residuals: list[np.ndarray]
    internal: list[dict[str, np.ndarray]]
    bla_levels: tuple = ()
    fitted: dict = field(default_factory=dict)
    extended: dict = field(default_factory=dict)
    signal: str = "y"
    improves: dict = field(default_factory=dict)  # name -> whether its validation gain on the model is suggestive
    errors: dict = field(default_factory=dict)  # name -> its validation error (rms)

    def leads(self, name: str) -> bool:
        """Whether hypothesis ``name`` is fitted, lowers the validation error at least suggestively,
        and has the lowest validation error of the hypotheses fitted so far."""
        return bool(self.improves.get(name)) and self.errors[name] <= min(self.errors.values())


    def target(self) -> np.ndarray:
        return np.concatenate(self.residuals)

    def measured(self, run: Run) -> np.ndarray:
        """The recorded judged signal of ``run`` (full length)."""
        return getattr(run, self.signal)

    def simulated(self, runner: ModelRunner | None = None) -> list[np.ndarray]:
        """The judged signal as ``runner`` (default: the nominal model) simulates it on every run."""
        return (runner or self.runner).simulate_each(self.runs, self.signal)

    def simulation_rss(self, data: dict) -> float:
        """Sum of squares of measured minus simulated mean steady-state periods of the judged
        signal of the model ``data``."""
        simulated = self.simulated(self.runner.with_changes(data))
        return float(sum(np.sum((steady_mean(run, self.measured(run)) - steady_mean(run, x)) ** 2)
                         for run, x in zip(self.runs, simulated)))

    def response(self, signals: list[np.ndarray], where: str) -> np.ndarray:
        """Stacked mean steady-state response of the judged signal of every run to its
        disturbance (``process`` or ``output``), the runs in parallel threads."""
        from nlsid.simulate.threads import in_threads

        def one(pair: tuple[Run, np.ndarray]) -> np.ndarray:
            return steady_mean(pair[0], self.runner.response(pair[0], **{where: pair[1]}, signal=self.signal))
        return np.concatenate(in_threads(one, list(zip(self.runs, signals))))

@dataclass(frozen=True)
class Estimate:
    """Parameter values and standard errors; ``explained_db`` is the drop of the estimation
    residual's sum of squares the signature predicts (10 log10 of before over after; NaN when
    either is zero: :func:`explained_db`); ``paths`` (parameter -> key path for the fit engine)
    replaces the hypothesis' own where the parameters depend on the estimate (a structure whose
    size the estimate chooses); ``lti`` (an LTI config: ``type``, coefficients, ``domain``)
    replaces the LTI part of the model before it is extended (a discrete model extended as its
    continuous equivalent, :mod:`nlsid.diagnose.hypotheses.feedback`; :data:`LTI_KEYS`);
    ``starts`` (model key -> value) starts the linear mechanics refined with a force or block
    (:func:`nlsid.diagnose.hypotheses.mechanics.linear_paths`) and the nuisances re-fitted with it
    elsewhere than at the model's values (a richer friction law at the simpler one's fit).
    ``alternatives`` are other starts the estimate cannot tell from this one (each an Estimate
    without alternatives of its own): :func:`nlsid.diagnose.diagnosis.refine` refines each in turn
    and keeps the fit of the lowest estimation error (the refinement keeps each parameter's sign,
    so a start on the wrong side of zero cannot cross over)."""

    values: dict[str, float]
    std: dict[str, float]
    explained_db: float
    note: str = ""
    paths: dict[str, str] | None = None
    lti: dict | None = None
    starts: dict[str, float] | None = None
    alternatives: tuple["Estimate", ...] = ()


LTI_KEYS = ("type", "domain", "num", "den", "zeros", "poles", "gain", "A", "B", "C", "D")


def with_lti(data: dict, lti: dict) -> dict:
    """A copy of the config ``data`` whose model has the LTI part ``lti`` in place of its own (the
    nuisances, blocks and dead time kept)."""
    model = {k: v for k, v in data["model"].items() if k not in LTI_KEYS}
    return {**data, "model": {**model, **lti}}

LINEAR_WITH = ("delay",)  # linear families refined with the model's linear part (Hypothesis.refits_linear)
NONLINEAR_FAMILIES = ("friction", "stiffness", "input", "output", "structure")


@dataclass(frozen=True)
class Hypothesis:
    name: str
    title: str
    family: str
    main: str
    unit: str
    signature: str
    applies: Callable[[ModelRunner], str | None]
    estimate: Callable[[Context], Estimate | str]
    extend: Callable[[dict, dict], dict]
    parameters: tuple[str, ...] = field(default=())
    paths: Callable[[dict], dict[str, str]] | None = None  # parameter -> key path, for the fit engine
    reading: Callable[[dict], str] | None = None  # what the final values mean physically, for the note
    qualifier: Callable[[dict], str] | None = None  # the same in a word or two, for the headline ("hardening")
    holds: tuple[str, ...] = ()  # nuisance keys its fit does not re-fit (a parameter of it moves the model the same way)
    generalizes: tuple[str, ...] = ()  # families whose models are special cases of this one's (verdict ties)
    derive: Callable[[dict, dict, dict], dict] | None = None  # (fitted, start values, model) -> values computed from them

    @property
    def distorts(self) -> bool:
        """A nonlinearity: it leaves distortion at the detection lines, so it is not fitted where
        they show none (:func:`nlsid.diagnose.diagnosis._round`)."""
        return self.family in NONLINEAR_FAMILIES

    @property
    def refits_linear(self) -> bool:
        """Refined together with the model's linear part (:func:`nlsid.diagnose.diagnosis.refine`):
        a nonlinearity, whose BLA the user's linear part may be, and a dead time, which in a
        second difference from reality (a mass 5 % off, an input block that lowers the gain) is
        otherwise out-fitted by a missing resonance with a gain of its own, which mimics the dead
        time's phase lag in the band and takes the gain error besides (measured on the battery:
        a 2.7-sample delay with the mass 5 % off was named a coupled mode, 40 dB above the floor)."""
        return self.distorts or self.family in LINEAR_WITH

def spring(k3: float) -> str:
    """The kind of a cubic spring F = k3 p^3 against the motion: hardening for k3 > 0."""
    return "hardening" if k3 > 0 else "softening"


def explained_db(before: float, after: float) -> float:
    """10 log10(before / after), the drop of a residual sum of squares; NaN when it has no finite
    value (a zero residual to begin with, or one explained exactly, as on noise-free data)."""
    return 10 * math.log10(before / after) if before > 0 and after > 0 else float("nan")

def regress(y: np.ndarray, columns: list[np.ndarray], names: list[str]) -> Estimate:
    X = np.column_stack(columns)
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    rss = float(np.sum((y - X @ theta) ** 2))
    dof = max(y.size - len(names), 1)
    cov = np.linalg.pinv(X.T @ X) * rss / dof
    before = float(np.sum(y**2))
    return Estimate({n: float(v) for n, v in zip(names, theta)},
                    {n: float(math.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(names)},
                    explained_db(before, rss))

def scan(cost: Callable[[float], float], lower: float, upper: float) -> float:
    """The shape parameter in [lower, upper] that minimises ``cost`` (bounded Brent search)."""
    from scipy.optimize import minimize_scalar

    result = minimize_scalar(cost, bounds=(lower, upper), method="bounded",
                             options={"xatol": 1e-4 * (upper - lower)})
    return float(result.x)

def always(runner: ModelRunner) -> str | None:
    return None

def quantile(q: float) -> Callable[[np.ndarray], float]:
    return lambda x: float(np.quantile(x, q))
