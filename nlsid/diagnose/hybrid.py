"""The third model of a diagnosis: the physical extension with a black-box term for what remains
(:mod:`nlsid.models.hybrid`, ``type: hybrid``).

Where the yardstick (:mod:`nlsid.diagnose.yardstick`) is significantly better than the final
extended model (the F rule of :mod:`nlsid.diagnose.verdict`: an effect outside the library
remains), neither model alone is what a user wants: the extended model is readable but misses the
rest, the yardstick reaches it but names nothing. The hybrid keeps the extended model as it was
fitted (its parameters, nuisances and simulation settings unchanged: the readable part stays) and
adds a PNLSS term in parallel, fitted to what the extended model leaves of the measured output,
r = y - y_p, on the same estimation parts (:func:`nlsid.diagnose.split.budgeted`) the yardstick saw:

* its start is made from both models (:func:`black_box_start`): r is the system's output, which
  the yardstick reaches, less the physical model's, which a PNLSS copy of the physical model
  (fitted to its own noise-free output) reaches, so the start is the yardstick minus that copy,
  side by side (:func:`nlsid.fit.hybrid.difference`); its output equation is then fitted to r by
  linear least squares along its state trajectory (:func:`nlsid.fit.hybrid.output_equation`),
  exact where r is what the start's states can express (the derivation in ``docs/pnlss.md``);
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

import dataclasses
import math
from dataclasses import dataclass

from nlsid.diagnose.gain import model_residuals, score
from nlsid.diagnose.simulation import ModelRunner
from nlsid.diagnose.yardstick import BlackBoxFit
from nlsid.errors import InputError
from nlsid.io.run import Run

FILE = "hybrid_model.yaml"
COPY_ITERATIONS = 30  # accepted iterations of the PNLSS copy of the physical model at most (black_box_start)


@dataclass
class HybridFit(BlackBoxFit):
    """The hybrid model's fit (``config``: ``model: {type: hybrid, ...}``; ``fit``: its black-box
    term's) and validation score, or why it was not fitted (``reason``)."""

    def summary(self) -> dict:
        """``summary.json`` ``hybrid`` (docs/formats.md)."""
        if not self.fitted:
            return {"fitted": False, "reason": self.reason, "file": None}
        return {"fitted": True, "reason": "", "file": FILE, "kind": "hybrid", "early_stopping": self.early_stopping,
                "black_box": self.fit_summary(("start_estimation_rms",)), "validation": self.score.summary()}

    def header(self, source: str, causes: str) -> list[str]:
        """Header comment of :data:`FILE`."""
        model = self.fit.model
        return [f"Hybrid model of nlsid diagnose: the extended model ({causes} added to {source}) as fitted, "
                "under physical, with a black-box PNLSS term in parallel for what it leaves, under black_box",
                f"black box: {model.order} states, monomials of degrees {list(model.state_degrees)}"
                + model.form_text
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


def with_outputs(runs: list[Run], outputs: list) -> list[Run]:
    """Each run with ``outputs`` (one array per run, as long as its y) as its measured y: the
    physical model's own output, which its PNLSS copy is fitted to (:func:`black_box_start`)."""
    return [dataclasses.replace(run, y=y) for run, y in zip(runs, outputs)]


def black_box_start(yardstick, runner: ModelRunner, own: list[Run], early: list[Run], iterations: int = 0):
    """The black-box term's start, and how it was made (a sentence), from both models: the
    yardstick's PNLSS model (:class:`nlsid.models.pnlss.Pnlss`) minus a PNLSS copy of the physical
    model, side by side (:func:`nlsid.fit.hybrid.difference`). The copy starts from the physical
    model's linear part (its linear dynamics from u to y, :func:`nlsid.diagnose.yardstick.linear_start`,
    ZOH-discretised and balanced) in the LFR form with one combination (the Wiener-like start of
    :func:`nlsid.models.pnlss.lfr_start_rows`) and the yardstick's degrees, and is fitted to the
    physical model's own noise-free output on the runs ``own`` (early stopping on ``early``: both
    with y the physical model's output) by :func:`nlsid.fit.pnlss.fit_pnlss`, ``iterations`` at most
    in its linear and in its nonlinear stage (0: :data:`COPY_ITERATIONS`). The residual y - y_p is
    then the start's output but for the yardstick's and the copy's errors. Where the physical
    model has no linear part of one domain, the yardstick alone; where the term would cost more
    than the yardstick's limit per iteration (:data:`nlsid.diagnose.yardstick.WORK`), the
    yardstick minus the linear part alone (:func:`nlsid.fit.hybrid.minus_linear`) or the yardstick."""
    from nlsid.diagnose.yardstick import WORK, linear_start
    from nlsid.fit.hybrid import difference, minus_linear
    from nlsid.fit.pnlss import fit_pnlss
    from nlsid.models.pnlss import balanced, discretised, from_linear

    linear = linear_start(runner)
    if isinstance(linear, str):
        return yardstick, f"black-box term started from the yardstick alone: {linear}"
    samples = sum(run.n_samples for run in own)
    fits = lambda model: samples * model.n_parameters ** 2 <= WORK  # noqa: E731
    copy, _ = from_linear(linear, yardstick.fs, yardstick.state_degrees, yardstick.output_degrees, True,
                          lfr_inputs=1, lfr_where="physical")
    wide = difference(yardstick, copy)
    if fits(wide):
        budget = iterations or COPY_ITERATIONS
        fit = fit_pnlss(copy, own, early, max_iterations=budget, linear_iterations=budget, patience=budget)
        if fit.status != "failed":
            wide = difference(yardstick, fit.model)
            error = fit.validation_rms if fit.validation_rms is not None else fit.estimation_rms
            return wide, (f"black-box term started as the yardstick minus a PNLSS copy of the physical model "
                          f"({yardstick.order} + {fit.model.order} states side by side, LFR form over both models' "
                          f"variables, {wide.n_parameters} parameters; the copy's rms error on the physical "
                          f"model's output {error:.4g}, {fit.status})")
    linear, _ = balanced(discretised(linear, yardstick.fs, "physical"))
    wider = minus_linear(yardstick, linear)
    if fits(wider):
        return wider, (f"black-box term started as the yardstick minus the physical model's linear part "
                       f"({yardstick.order} + {linear.order} states side by side, its monomials those of the "
                       f"yardstick's {wider.lfr_inputs} variables: LFR form, {wider.n_parameters} parameters)")
    return yardstick, (f"black-box term started from the yardstick alone: with the physical model's {linear.order} "
                       f"linear states beside its {yardstick.order} it would cost {samples} x {wider.n_parameters}^2 "
                       f"samples x parameters^2 per iteration, above {WORK:.0e}")


def fit_hybrid(extended: dict, source: str, yardstick, fit_runs: list[Run], val_runs: list[Run],
               val: list, max_iterations: int | None = None) -> HybridFit:
    """Fit and score the hybrid model (module docstring). ``extended``: the final extended model's
    config; ``yardstick``: the fitted :class:`nlsid.diagnose.yardstick.Yardstick`; ``fit_runs``:
    the estimation parts it was fitted on; ``val_runs`` and ``val``: the validation runs and the
    user's model's residuals on them (:func:`nlsid.diagnose.gain.score`); ``max_iterations``: of
    the term's fit (None: the yardstick's budget, :func:`nlsid.diagnose.yardstick.iterations`), and
    of the physical model's copy's where fewer than :data:`COPY_ITERATIONS`."""
    from nlsid.diagnose.yardstick import PATIENCE, _holdout, as_recorded, iterations
    from nlsid.fit.hybrid import fit_black_box, residual_run
    from nlsid.models.pnlss import to_config

    try:
        runner = ModelRunner.from_data(extended, source)
        own, early, rule = _holdout(fit_runs, val_runs)
        y_own, y_early = runner.simulate_each(own), runner.simulate_each(early)  # y_p, as the diagnosis simulates
        start, how = black_box_start(yardstick.fit.model, runner, as_recorded(with_outputs(own, y_own)),
                                     as_recorded(with_outputs(early, y_early)),
                                     min(COPY_ITERATIONS, max_iterations or COPY_ITERATIONS))
        own = as_recorded([residual_run(run, y) for run, y in zip(own, y_own)])
        early = as_recorded([residual_run(run, y) for run, y in zip(early, y_early)])
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
