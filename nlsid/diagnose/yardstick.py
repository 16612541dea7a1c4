"""The yardstick: a black-box nonlinear model fitted to the same estimation data as the named causes,
showing how much of the error is reachable at all.

The flexible model is a polynomial nonlinear state-space model (PNLSS, Paduart et al., Automatica
46, 2010; :mod:`nlsid.models.pnlss`, fitted by :func:`nlsid.fit.pnlss.fit_pnlss`),

    x[t+1] = A x + B u + E zeta(x, u),    y = C x + D u + F eta(x, u),

zeta and eta all monomials of the states and the input of total degrees 2 and 3 (:data:`DEGREES`).
Its linear part starts from the user's model (the linear dynamics from u to y of an LTI or
mechanical model, forces and blocks left out; of a block structure its filters in series), ZOH-
discretised at the runs' rate and balanced; its sensor offset is the one the nuisances found. The
fit sees the estimation parts the hypotheses were fitted on (:func:`nlsid.diagnose.split.budgeted`).

Overfitting is held back by early stopping on data the score never sees: with two or more
estimation runs the last one (in the split's order) is held out of the fit and picks the iterate
with the lowest error on it (:func:`nlsid.fit.pnlss.fit_pnlss`); with one, the fit runs to
convergence or its iteration limit (stated). The yardstick is then scored on the validation runs
exactly as the hypotheses are (:mod:`nlsid.diagnose.gain`), so its error is comparable with the
named cause's: where the final extended model's error power exceeds the yardstick's by more than
the verdict's F* (:mod:`nlsid.diagnose.verdict`), an effect outside the library remains.

Not fitted (the reason stated) in closed loop (the yardstick models the plant from the recorded
u, while the diagnosis simulates the loop from r: their errors would not compare), for a model
without a linear part to start from (an ``equations`` model), and for noise-free data that the
user's model matches exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.diagnose.gain import Score, model_residuals, score
from nlsid.diagnose.simulation import ModelRunner
from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.lti import StateSpace

DEGREES = (2, 3)       # total degrees of the monomials in the state and the output equation
MAX_ITERATIONS = 60    # accepted iterations of the nonlinear stage at most
LINEAR_ITERATIONS = 20
FILE = "black_box_model.yaml"


@dataclass
class Yardstick:
    """The black-box model's fit and validation score, or why it was not fitted (``reason``)."""

    reason: str = ""
    config: dict | None = None          # the model config (``model: {type: pnlss, ...}``)
    fit: object | None = None           # nlsid.fit.pnlss.PnlssFit
    score: Score | None = None
    residuals: list = field(default_factory=list)
    early_stopping: str = ""

    @property
    def fitted(self) -> bool:
        return self.score is not None

    def summary(self) -> dict:
        """``summary.json`` ``yardstick`` (docs/formats.md)."""
        if not self.fitted:
            return {"fitted": False, "reason": self.reason, "file": None}
        fit = self.fit.summary()
        keep = ("status", "reason", "states", "state_degrees", "output_degrees", "parameters", "notes", "estimation_rms", "validation_rms", "linear_estimation_rms")
        return {"fitted": True, "reason": "", "file": FILE, "kind": "pnlss", "early_stopping": self.early_stopping,
                "fit": {key: fit[key] for key in keep}, "validation": self.score.summary()}

    def header(self, source: str) -> list[str]:
        """Header comment of :data:`FILE`."""
        s = self.score
        return [f"Black-box yardstick of nlsid diagnose (a PNLSS model, not a physical cause) fitted to the "
                f"estimation data of {source}",
                f"{self.fit.model.order} states, monomials of degrees {list(DEGREES)}, {self.fit.model.n_parameters} "
                f"parameters; {self.fit.reason}",
                f"Validation error {s.error_rms:.4g} rms"]


def _series(stages: list[StateSpace]) -> StateSpace:
    """Continuous LTI stages in series (the first applied first): one SISO state space."""
    A, B, C, D = stages[0].A, stages[0].B, stages[0].C, float(stages[0].D)
    delay = stages[0].delay
    for s in stages[1:]:
        n1, n2 = A.shape[0], s.A.shape[0]
        A = np.block([[A, np.zeros((n1, n2))], [np.outer(s.B, C), s.A]])
        B = np.concatenate([B, s.B * D])
        C = np.concatenate([s.D * C, s.C])
        D = float(s.D) * D
        delay += s.delay
    return StateSpace(A, B, C, D, discrete=stages[0].discrete, delay=delay)


def linear_start(runner: ModelRunner) -> StateSpace | str:
    """The linear dynamics from u to y of the user's model (module docstring), or why there are none."""
    from nlsid.models.from_config import Plant, Structure

    model = runner.plant
    if isinstance(model, Plant):
        return model.ss
    if isinstance(model, Structure):
        stages = [s for s in model.branches[0] if isinstance(s, StateSpace)]
        if not stages or len({s.discrete for s in stages}) > 1:
            return "its block structure has no linear filters of one domain to start from"
        return _series(stages)
    return f"a {runner.kind} model has no linear part to start a black-box model from"


def _holdout(fit_runs: list[Run]) -> tuple[list[Run], list[Run], str]:
    """(fit runs, early-stopping runs, the rule in words): one estimation run held out, of a group
    (kind and level, :func:`nlsid.io.feeds.excitation_key`) that keeps another run in the fit where
    there is one (the fit then sees every level), else the last."""
    from nlsid.io.feeds import excitation_key

    if len(fit_runs) < 2:
        return fit_runs, [], "no early stopping (one estimation run): fitted to convergence or its iteration limit"
    keys = [excitation_key(run) for run in fit_runs]
    shared = [i for i, key in enumerate(keys) if keys.count(key) > 1]
    held = shared[-1] if shared else len(fit_runs) - 1
    rest = [run for i, run in enumerate(fit_runs) if i != held]
    return rest, [fit_runs[held]], f"early stopping on estimation run {fit_runs[held].run_id}, held out of the fit"


def fit_yardstick(runner: ModelRunner, fit_runs: list[Run], val_runs: list[Run], val: list,
                  output_offset: float = 0.0) -> Yardstick:
    """Fit and score the yardstick (module docstring). ``fit_runs``: the estimation parts the
    hypotheses were fitted on; ``val_runs`` and ``val``: the validation runs and the user's
    model's residuals on them (:func:`nlsid.diagnose.gain.score`)."""
    from nlsid.fit.pnlss import fit_pnlss
    from nlsid.models.pnlss import from_linear, to_config

    if runner.closed:
        return Yardstick("not fitted: in closed loop the diagnosis simulates the loop from r, a black-box plant "
                         "model from the recorded u would not be compared on equal terms")
    start = linear_start(runner)
    if isinstance(start, str):
        return Yardstick(f"not fitted: {start}")
    try:
        model, _ = from_linear(start, fit_runs[0].fs, DEGREES, DEGREES, True, output_offset=output_offset)
        own, early, rule = _holdout(fit_runs)
        fit = fit_pnlss(model, own, early, max_iterations=MAX_ITERATIONS, linear_iterations=LINEAR_ITERATIONS)
    except InputError as exc:
        return Yardstick(f"not fitted: {exc}")
    if fit.status == "failed" or not math.isfinite(fit.estimation_rms):
        return Yardstick(f"not fitted: {fit.reason}")
    config = {"model": to_config(fit.model)}
    try:
        residuals = model_residuals(ModelRunner.from_data(config, FILE), val_runs, val)
    except InputError as exc:
        return Yardstick(f"fitted, but it does not run on the validation runs: {exc.what}")
    return Yardstick("", config, fit, score(val, residuals), residuals, rule)
