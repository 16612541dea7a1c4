"""The third model of a diagnosis: the physical extension with a black-box term for what remains
(:mod:`nlsid.models.hybrid`, ``type: hybrid``).

Where the yardstick (:mod:`nlsid.diagnose.yardstick`) is significantly better than the final
extended model (the F rule of :mod:`nlsid.diagnose.verdict`: an effect outside the library
remains), neither model alone is what a user wants: the extended model is readable but misses the
rest, the yardstick reaches it but names nothing. The hybrid keeps the extended model as it was
fitted (its parameters, nuisances and simulation settings unchanged: the readable part stays) and
adds a PNLSS term in parallel, fitted to what the extended model leaves of the measured output,
r = y - y_p, on the same estimation parts (:func:`nlsid.diagnose.split.budgeted`) the yardstick saw:

* its start is the yardstick itself, whose state equation (A, B, E) already holds dynamics that
  reach the whole output; its output equation is fitted to r by linear least squares along that
  state trajectory (:func:`nlsid.fit.hybrid.output_equation`), which is exact where the residual
  is what the yardstick's states can express (the derivation in ``docs/pnlss.md``);
* then every coefficient of the term is refined on r by :func:`nlsid.fit.pnlss.fit_pnlss`, with
  the yardstick's early-stopping rule (an estimation run held out where a level has two, else the
  validation runs: :mod:`nlsid.diagnose.yardstick`) and its iteration budget.

The hybrid is then scored on the validation runs exactly as the other models
(:mod:`nlsid.diagnose.gain`), written as :data:`FILE`, and listed in ``summary.json`` ``models``
(kind ``hybrid``), so that ``best_model`` can name it. Otherwise (no named cause, no yardstick, or
a yardstick not significantly better than the extended model) it is not fitted, and
``summary.json`` ``hybrid`` says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from nlsid.diagnose.gain import Score, model_residuals, score
from nlsid.diagnose.simulation import ModelRunner
from nlsid.errors import InputError
from nlsid.io.run import Run

FILE = "hybrid_model.yaml"


@dataclass
class HybridFit:
    """The hybrid model's fit and validation score, or why it was not fitted (``reason``)."""

    reason: str = ""
    config: dict | None = None          # the model config (``model: {type: hybrid, ...}``)
    fit: object | None = None           # nlsid.fit.pnlss.PnlssFit of the black-box term
    score: Score | None = None
    residuals: list = field(default_factory=list)
    early_stopping: str = ""

    @property
    def fitted(self) -> bool:
        return self.score is not None

    def summary(self) -> dict:
        """``summary.json`` ``hybrid`` (docs/formats.md)."""
        if not self.fitted:
            return {"fitted": False, "reason": self.reason, "file": None}
        fit = self.fit.summary()
        keep = ("status", "reason", "states", "state_degrees", "output_degrees", "form", "lfr_inputs", "parameters",
                "notes", "estimation_rms", "validation_rms", "start_estimation_rms")
        return {"fitted": True, "reason": "", "file": FILE, "kind": "hybrid", "early_stopping": self.early_stopping,
                "black_box": {key: fit[key] for key in keep}, "validation": self.score.summary()}

    def header(self, source: str, causes: str) -> list[str]:
        """Header comment of :data:`FILE`."""
        model = self.fit.model
        return [f"Hybrid model of nlsid diagnose: the extended model ({causes} added to {source}) as fitted, "
                "under physical, with a black-box PNLSS term in parallel for what it leaves, under black_box",
                f"black box: {model.order} states, monomials of degrees {list(model.state_degrees)}"
                + (f" of {model.lfr_inputs} combination(s) z = Cz x + Dz u (LFR form)" if model.lfr else "")
                + f", {model.n_parameters} parameters; {self.fit.reason}",
                f"Validation error {self.score.error_rms:.4g} rms"]


def hybrid_config(extended: dict, black_box: dict) -> dict:
    """The hybrid model config of the ``extended`` model config (its ``model`` the physical part,
    its ``simulation`` settings kept; ``free`` left out: nothing is left to fit) and the black-box
    term's ``model:`` section (``type: pnlss``)."""
    out = {"model": {"type": "hybrid", "physical": extended["model"], "black_box": black_box}}
    if "simulation" in extended:
        out["simulation"] = extended["simulation"]
    return out


def residual_runs(runner: ModelRunner, runs: list[Run]) -> list[Run]:
    """Each run with its measured y replaced by what ``runner``'s model leaves of it, y - y_p
    (:func:`nlsid.fit.hybrid.residual_run`; y_p simulated as the diagnosis simulates: periodic
    runs in steady state, arbitrary records from their fitted initial state)."""
    from nlsid.fit.hybrid import residual_run

    return [residual_run(run, y) for run, y in zip(runs, runner.simulate_each(runs))]


def black_box_start(yardstick, runner: ModelRunner, samples: int):
    """The black-box term's start, and how it was made (a sentence): the yardstick's PNLSS model
    (:class:`nlsid.models.pnlss.Pnlss`) minus the linear part of the physical model (its linear
    dynamics from u to y, :func:`nlsid.diagnose.yardstick.linear_start`, ZOH-discretised at the
    yardstick's rate and balanced), side by side (:func:`nlsid.fit.hybrid.minus_linear`). The
    residual y - y_p holds the system's output, which the yardstick's states reach, less the
    physical model's, whose linear part its own states reach: the hybrid starts at the yardstick
    plus the physical model's nonlinear part, which the fit then removes from the term. Where the
    physical model has no linear part of one domain, or the wider term's iteration would cost more
    than the yardstick's limit (:data:`nlsid.diagnose.yardstick.WORK`), the yardstick alone."""
    from nlsid.diagnose.yardstick import WORK, linear_start
    from nlsid.fit.hybrid import minus_linear
    from nlsid.models.pnlss import balanced, discretised

    linear = linear_start(runner)
    if isinstance(linear, str):
        return yardstick, f"black-box term started from the yardstick alone: {linear}"
    linear, _ = balanced(discretised(linear, yardstick.fs, "physical"))
    wider = minus_linear(yardstick, linear)
    count = wider.n_parameters
    if samples * count ** 2 > WORK:
        return yardstick, (f"black-box term started from the yardstick alone: with the physical model's {linear.order} "
                           f"linear states beside its {yardstick.order} it would cost {samples} x {count}^2 samples x "
                           f"parameters^2 per iteration, above {WORK:.0e}")
    return wider, (f"black-box term started as the yardstick minus the physical model's linear part "
                   f"({yardstick.order} + {linear.order} states side by side, its monomials those of the yardstick's "
                   f"{wider.lfr_inputs} variables: LFR form, {count} parameters)")


def fit_hybrid(extended: dict, source: str, yardstick, fit_runs: list[Run], val_runs: list[Run],
               val: list, max_iterations: int | None = None) -> HybridFit:
    """Fit and score the hybrid model (module docstring). ``extended``: the final extended model's
    config; ``yardstick``: the fitted :class:`nlsid.diagnose.yardstick.Yardstick`; ``fit_runs``:
    the estimation parts it was fitted on; ``val_runs`` and ``val``: the validation runs and the
    user's model's residuals on them (:func:`nlsid.diagnose.gain.score`); ``max_iterations``: of
    the term's fit (None: the yardstick's budget, :func:`nlsid.diagnose.yardstick.iterations`)."""
    from nlsid.diagnose.yardstick import PATIENCE, _holdout, as_recorded, iterations
    from nlsid.fit.hybrid import fit_black_box
    from nlsid.models.pnlss import to_config

    try:
        runner = ModelRunner.from_data(extended, source)
        own, early, rule = _holdout(fit_runs, val_runs)
        own, early = as_recorded(residual_runs(runner, own)), as_recorded(residual_runs(runner, early))
        start, how = black_box_start(yardstick.fit.model, runner, sum(run.n_samples for run in own))
        budget = iterations(start, own + early) if max_iterations is None else max_iterations
        fit = fit_black_box(start, own, early, max_iterations=budget, patience=PATIENCE)
        fit.notes.insert(0, how)
    except InputError as exc:
        return HybridFit(f"not fitted: {exc}")
    if fit.status == "failed" or not math.isfinite(fit.estimation_rms):
        return HybridFit(f"not fitted: {fit.reason}")
    config = hybrid_config(extended, to_config(fit.model))
    try:
        residuals = model_residuals(ModelRunner.from_data(config, FILE), val_runs, val)
    except InputError as exc:
        return HybridFit(f"fitted, but it does not run on the validation runs: {exc.what}")
    return HybridFit("", config, fit, score(val, residuals), residuals, rule)
