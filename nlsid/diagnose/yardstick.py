"""The yardstick: a black-box nonlinear model fitted to the same estimation data as the named causes,
showing how much of the error is reachable at all.

The flexible model is a polynomial nonlinear state-space model (PNLSS, Paduart et al., Automatica
46, 2010; :mod:`nlsid.models.pnlss`, fitted by :func:`nlsid.fit.pnlss.fit_pnlss`),

    x[t+1] = A x + B u + E zeta(x, u),    y = C x + D u + F eta(x, u),

zeta and eta all monomials of the states and the input of total degrees 2 and 3 (:data:`DEGREES`).
Its linear part starts from the user's model (the linear dynamics from u to y of an LTI or
mechanical model, forces and blocks left out; of a block structure its filters in series), ZOH-
discretised at the runs' rate and balanced, with EXTRA_STATES more states (:func:`with_delay_states`)
so that it can hold dynamics the user's model lacks (an input filter before a second-order
model); its sensor offset is the one the nuisances found. The
fit sees the estimation parts the hypotheses were fitted on (:func:`nlsid.diagnose.split.budgeted`).

Overfitting is held back by early stopping (:func:`nlsid.fit.pnlss.fit_pnlss`: the iterate with
the lowest error on held-out runs), on an estimation run held out of the fit where a level has two
(:func:`_holdout`), else on the validation runs (stated: a mild optimism). The yardstick is then scored on the validation runs
exactly as the hypotheses are (:mod:`nlsid.diagnose.gain`), so its error is comparable with the
named cause's: where the final extended model's error power exceeds the yardstick's by more than
the verdict's F* (:mod:`nlsid.diagnose.verdict`), an effect outside the library remains.

Its size is held to what an iteration can afford (:func:`affordable`, :data:`WORK`): the extra
state and then the quadratic terms are left out for larger models or records, and a model too
large even then is not fitted (stated).

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
MAX_ITERATIONS = 200   # accepted iterations of the nonlinear stage at most
EXTRA_STATES = 1       # states beyond the user's model's, each started as a delay of the input
WORK = 3e9             # samples x parameters^2 of an iteration's normal matrix at most (about 1 s here)
SENSITIVITY_WORK = 3e8  # simulated samples (lead-in included) x parameters over the whole fit (about 30 s)
MIN_ITERATIONS = 20     # accepted iterations of the nonlinear stage granted whatever SENSITIVITY_WORK says
SHAPES = ((EXTRA_STATES, DEGREES), (0, DEGREES), (0, (3,)))  # (extra states, degrees), tried in this order
LINEAR_ITERATIONS = 20
PATIENCE = 40          # iterates without a lower early-stopping error before the fit stops
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


def with_delay_states(model, count: int):
    """``model`` (:class:`nlsid.models.pnlss.Pnlss`) with ``count`` states appended, each the
    previous one delayed by a sample, the first fed by the input: x_e1[t+1] = u[t],
    x_e2[t+1] = x_e1[t], ...; they do not reach the output (C = 0) nor the other states, so the
    model's response is unchanged, while the output's sensitivity to their couplings (C_e: the
    delayed inputs themselves) is not zero and the fit can shape them into the dynamics it needs.
    The monomial coefficients (all zero) are resized to the new state count."""
    from nlsid.models.pnlss import Pnlss, exponents

    n, m = model.order, model.order + count
    A = np.zeros((m, m))
    A[:n, :n] = model.A
    for i in range(1, count):
        A[n + i, n + i - 1] = 1.0
    B = np.concatenate([model.B, [1.0], np.zeros(count - 1)])
    C = np.concatenate([model.C, np.zeros(count)])
    E = np.zeros((m, exponents(m, model.state_degrees, model.with_input).shape[0]))
    F = np.zeros(exponents(m, model.output_degrees, model.with_input).shape[0])
    return Pnlss(A, B, C, model.D, E, F, model.fs, model.state_degrees, model.output_degrees, model.with_input,
                 model.input_offset, model.output_offset, model.input_channels, model.zero_if_absent)


def _holdout(fit_runs: list[Run], val_runs: list[Run]) -> tuple[list[Run], list[Run], str]:
    """(fit runs, early-stopping runs, the rule in words).

    One estimation run is held out of the fit where its group (kind and level,
    :func:`nlsid.io.feeds.excitation_key`) keeps another run in the fit: the fit then still sees
    every level, and the iterate is chosen on data the score never sees. Otherwise (every level
    has one estimation run: holding one out would make the model extrapolate in amplitude, and a
    polynomial model does that badly) the iterate is chosen on the validation runs themselves:
    one number (the iteration) picked on them, a mild optimism of the yardstick's score, stated."""
    from nlsid.io.feeds import excitation_key

    keys = [excitation_key(run) for run in fit_runs]
    shared = [i for i, key in enumerate(keys) if keys.count(key) > 1]
    if shared:
        held = shared[-1]
        rest = [run for i, run in enumerate(fit_runs) if i != held]
        return rest, [fit_runs[held]], f"early stopping on estimation run {fit_runs[held].run_id}, held out of the fit"
    return (fit_runs, list(val_runs), "early stopping on the validation runs (no level has two estimation runs to "
                                      "hold one out): its validation error is slightly optimistic")


def affordable(order: int, samples: int) -> tuple[int, tuple[int, ...]] | None:
    """The richest shape of :data:`SHAPES` (extra states, monomial degrees) whose Levenberg-
    Marquardt iteration stays within :data:`WORK` (its normal matrix costs samples x parameters^2),
    or None: a polynomial in every state is then too large (an LFR form, whose nonlinearity acts
    on a few linear combinations of the states, is what such orders need)."""
    from nlsid.models.pnlss import exponents

    for extra, degrees in SHAPES:
        n = order + extra
        terms = exponents(n, degrees, True).shape[0]
        parameters = n * n + 2 * n + 1 + (n + 1) * terms
        if samples * parameters ** 2 <= WORK:
            return extra, degrees
    return None


def iterations(model, runs: list[Run]) -> int:
    """The nonlinear stage's iterations the fit may take: :data:`SENSITIVITY_WORK` over the work of
    one iteration's sensitivities (the samples simulated, a periodic run's steady-state lead-in
    included, times the parameters: a lightly damped model needs up to 20 periods of lead-in per
    period measured), within [MIN_ITERATIONS, MAX_ITERATIONS]."""
    from nlsid.simulate.pnlss_runs import lead_periods

    simulated = 0
    for run in runs:
        if run.period is not None and run.n_periods >= 1:
            simulated += (lead_periods(model, run.period) + run.n_periods) * run.period
        else:
            simulated += run.n_samples
    per_iteration = max(simulated * model.n_parameters, 1)
    return int(min(MAX_ITERATIONS, max(MIN_ITERATIONS, SENSITIVITY_WORK // per_iteration)))


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
    samples = sum(run.n_samples for run in fit_runs)
    try:
        model, _ = from_linear(start, fit_runs[0].fs, DEGREES, DEGREES, True, output_offset=output_offset)
        shape = affordable(model.order, samples)
        if shape is None:
            return Yardstick(f"not fitted: a polynomial state-space model of {model.order} states on {samples} samples "
                             f"costs more than {WORK:.0e} samples x parameters^2 per iteration even with cubic terms "
                             "alone (a form with the nonlinearity on a few state combinations is not built yet)")
        extra, degrees = shape
        if degrees != DEGREES:
            model, _ = from_linear(start, fit_runs[0].fs, degrees, degrees, True, output_offset=output_offset)
        model = with_delay_states(model, extra) if extra else model
        own, early, rule = _holdout(fit_runs, val_runs)
        fit = fit_pnlss(model, own, early, max_iterations=iterations(model, own + early),
                        linear_iterations=LINEAR_ITERATIONS, patience=PATIENCE)
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
