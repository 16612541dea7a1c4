"""The yardstick: a black-box nonlinear model fitted to the same estimation data as the named causes,
showing how much of the error is reachable at all.

The flexible model is a polynomial nonlinear state-space model (PNLSS, Paduart et al., Automatica
46, 2010; :mod:`nlsid.models.pnlss`, fitted by :func:`nlsid.fit.pnlss.fit_pnlss`),

    x[t+1] = A x + B u + E zeta(x, u),    y = C x + D u + F eta(x, u),

zeta and eta all monomials of the states and the input of total degrees 2 and 3 (:data:`DEGREES`),
or of a few combinations z of them (the LFR form, below).
Its linear part starts from the user's model (the linear dynamics from u to y of an LTI or
mechanical model, forces and blocks left out; of a block structure its filters in series), ZOH-
discretised at the runs' rate and balanced, with EXTRA_STATES more states (:func:`with_delay_states`)
so that it can hold dynamics the user's model lacks (an input filter before a second-order
model); its sensor offset starts from the one the nuisances found and is fitted with it. The
fit sees the estimation parts the hypotheses were fitted on (:func:`nlsid.diagnose.split.budgeted`).

Overfitting is held back by early stopping (:func:`nlsid.fit.pnlss.fit_pnlss`: the iterate with
the lowest error on held-out runs), on an estimation run held out of the fit where a level has two
(:func:`_holdout`), else on the validation runs (stated: a mild optimism). The yardstick is then scored on the validation runs
exactly as the hypotheses are (:mod:`nlsid.diagnose.gain`), so its error is comparable with the
named cause's: where the final extended model's error power exceeds the yardstick's by more than
the verdict's F* (:mod:`nlsid.diagnose.verdict`), an effect outside the library remains.

Its size is held to what an iteration can afford (:func:`affordable`, :data:`WORK`): where a
polynomial in every state and the input costs too much (its monomial count grows as n^3: 120 of
degrees 2 and 3 for 7 states and u), the nonlinear LFR form takes its place (Schoukens and Tiels,
2017): the same degrees in LFR_INPUTS (or fewer) linear combinations z = C_z x + D_z u, fitted with
the rest, the states kept (stated in the fit's notes). A model too large even then is not fitted
(stated).

Progress: a diagnosis plans the yardstick as a fixed amount of work (its ``step`` units,
:data:`nlsid.diagnose.diagnosis.YARDSTICK_WORK`); :class:`WorkProgress` advances them during the
fit in proportion to its accepted iterates against their budget (the iterations the fit may still
take, :func:`nlsid.fit.pnlss.fit_pnlss` ``progress``), so that a progress bar moves while the
yardstick is fitted rather than jumping at its end.

Not fitted (the reason stated) in closed loop (the yardstick models the plant from the recorded
u, while the diagnosis simulates the loop from r: their errors would not compare), for a model
without a linear part to start from (an ``equations`` model), and for noise-free data that the
user's model matches exactly.
"""

from __future__ import annotations

import dataclasses
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
LFR_INPUTS = 2          # combinations z = C_z x + D_z u of the LFR form, at most
# (extra states, degrees, LFR combinations: 0 for the full form), tried in this order
SHAPES = ((EXTRA_STATES, DEGREES, 0), (EXTRA_STATES, DEGREES, LFR_INPUTS), (EXTRA_STATES, DEGREES, 1), (0, DEGREES, 1))
LINEAR_ITERATIONS = 20
PATIENCE = 40          # iterates without a lower early-stopping error before the fit stops
FILE = "black_box_model.yaml"
PROGRESS_STEP = "yardstick iterates"  # the step name under which the fit advances a diagnosis' work


class WorkProgress:
    """The ``progress(count, budget)`` of :func:`nlsid.fit.pnlss.fit_pnlss` as ``work`` units of
    a diagnosis' ``step(name, work, planned)``: after ``count`` of ``budget`` iterations,
    floor(work x count / budget) units done in all, each increase told as
    ``step(PROGRESS_STEP, increase, 0)``. Whole units, never more than ``work``: the fit's budget
    only falls, so the units only rise, and reach ``work`` when the fit ends (count = budget).
    :attr:`units` is what has been told so far."""

    def __init__(self, step, work: int):
        self.step, self.work, self.units = step, int(work), 0

    def __call__(self, count: int, budget: int) -> None:
        units = min(self.work, self.work * count // budget) if budget > 0 else 0
        if units > self.units:
            self.step(PROGRESS_STEP, units - self.units, 0)
            self.units = units


#: The PNLSS fit's summary keys that summary.json keeps of a black-box model (with its own extras).
FIT_KEYS = ("status", "reason", "states", "state_degrees", "output_degrees", "form", "lfr_inputs", "parameters",
            "notes", "estimation_rms", "validation_rms")


@dataclass
class BlackBoxFit:
    """A model with a PNLSS part fitted by the diagnosis and scored on the validation runs, or why
    it was not fitted (``reason``): the yardstick (:class:`Yardstick`) and the hybrid
    (:class:`nlsid.diagnose.hybrid.HybridFit`)."""

    reason: str = ""
    config: dict | None = None          # the model config
    fit: object | None = None           # nlsid.fit.pnlss.PnlssFit of the PNLSS part
    score: Score | None = None
    residuals: list = field(default_factory=list)
    early_stopping: str = ""

    @property
    def fitted(self) -> bool:
        return self.score is not None

    def fit_summary(self, extra: tuple[str, ...]) -> dict:
        """The PNLSS fit's summary keys :data:`FIT_KEYS` and ``extra``."""
        fit = self.fit.summary()
        return {key: fit[key] for key in (*FIT_KEYS, *extra)}


@dataclass
class Yardstick(BlackBoxFit):
    """The black-box model's fit and validation score (``config``: ``model: {type: pnlss, ...}``),
    or why it was not fitted (``reason``)."""

    def summary(self) -> dict:
        """``summary.json`` ``yardstick`` (docs/formats.md)."""
        if not self.fitted:
            return {"fitted": False, "reason": self.reason, "file": None}
        return {"fitted": True, "reason": "", "file": FILE, "kind": "pnlss", "early_stopping": self.early_stopping,
                "fit": self.fit_summary(("linear_estimation_rms",)), "validation": self.score.summary()}

    def header(self, source: str) -> list[str]:
        """Header comment of :data:`FILE`."""
        s = self.score
        return [f"Black-box yardstick of nlsid diagnose (a PNLSS model, not a physical cause) fitted to the "
                f"estimation data of {source}",
                f"{self.fit.model.order} states, monomials of degrees {list(self.fit.model.state_degrees)}"
                + self.fit.model.form_text + f", {self.fit.model.n_parameters} parameters; {self.fit.reason}",
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
    The monomial coefficients (all zero) are resized to the new state count; an LFR form's
    combinations get zero weights on the new states."""
    from nlsid.models.pnlss import exponents

    n, m = model.order, model.order + count
    A = np.zeros((m, m))
    A[:n, :n] = model.A
    for i in range(1, count):
        A[n + i, n + i - 1] = 1.0
    B = np.concatenate([model.B, [1.0], np.zeros(count - 1)])
    C = np.concatenate([model.C, np.zeros(count)])
    if model.lfr:
        Cz = np.hstack([model.Cz, np.zeros((model.lfr_inputs, count))])
        return model.replace(A=A, B=B, C=C, E=np.zeros((m, model.E.shape[1])), F=np.zeros_like(model.F), Cz=Cz)
    E = np.zeros((m, exponents(m, model.state_degrees, model.with_input).shape[0]))
    F = np.zeros(exponents(m, model.output_degrees, model.with_input).shape[0])
    return model.replace(A=A, B=B, C=C, E=E, F=F)


def as_recorded(runs: list[Run]) -> list[Run]:
    """The runs as the PNLSS fit takes them: a part of an arbitrary record that diagnose compares
    as one period (:class:`nlsid.io.ranges.RangeRun`) becomes the arbitrary record of exactly its
    samples, started from an initial state the fit estimates (not a period repeated in steady
    state, which a record that is not periodic is not); other runs as they are."""
    from nlsid.io.ranges import RangeRun

    out = []
    for run in runs:
        if not isinstance(run, RangeRun):
            out.append(run)
            continue
        window = slice(run.start, run.start + run.period)
        fields = {f.name: getattr(run, f.name) for f in dataclasses.fields(Run)}
        for name in ("u", "y", "r"):
            if fields[name] is not None:
                fields[name] = fields[name][window]
        fields.update(channels={name: x[window] for name, x in run.channels.items()}, period=None,
                      transient_periods=0)
        out.append(Run(**fields))
    return out


def _holdout(fit_runs: list[Run], val_runs: list[Run]) -> tuple[list[Run], list[Run], str]:
    """(fit runs, early-stopping runs, the rule in words).

    One estimation run is held out of the fit where its group (kind and level,
    :func:`nlsid.feeds.excitation_key`) keeps another run in the fit: the fit then still sees
    every level, and the iterate is chosen on data the score never sees. Otherwise (every level
    has one estimation run: holding one out would make the model extrapolate in amplitude, and a
    polynomial model does that badly) the iterate is chosen on the validation runs themselves:
    one number (the iteration) picked on them, a mild optimism of the yardstick's score, stated."""
    from nlsid.feeds import excitation_key

    keys = [excitation_key(run) for run in fit_runs]
    shared = [i for i, key in enumerate(keys) if keys.count(key) > 1]
    if shared:
        held = shared[-1]
        rest = [run for i, run in enumerate(fit_runs) if i != held]
        return rest, [fit_runs[held]], f"early stopping on estimation run {fit_runs[held].run_id}, held out of the fit"
    return (fit_runs, list(val_runs), "early stopping on the validation runs (no level has two estimation runs to "
                                      "hold one out): its validation error is slightly optimistic")


def parameters(order: int, degrees: tuple[int, ...], lfr_inputs: int = 0) -> int:
    """Coefficients of a PNLSS model of ``order`` states with monomials of ``degrees`` in both
    equations: of the states and the input (``lfr_inputs`` 0), or of that many combinations z
    (the LFR form, whose Cz and Dz count too)."""
    from nlsid.models.pnlss import exponents

    n = order
    if lfr_inputs:
        terms = exponents(lfr_inputs, degrees, False).shape[0]
        return n * n + 2 * n + 1 + (n + 1) * terms + lfr_inputs * (n + 1)
    terms = exponents(n, degrees, True).shape[0]
    return n * n + 2 * n + 1 + (n + 1) * terms


def affordable(order: int, samples: int) -> tuple[int, tuple[int, ...], int] | None:
    """The richest shape of :data:`SHAPES` (extra states, monomial degrees, LFR combinations: 0
    for the full form) whose Levenberg-Marquardt iteration stays within :data:`WORK` (its normal
    matrix costs samples x parameters^2), or None. The full form is tried first; where its
    polynomial in every state is too large, the LFR form with the same states and degrees, its
    nonlinearity on a few linear combinations of them."""
    for extra, degrees, inputs in SHAPES:
        if inputs > order + extra + 1:
            continue
        if samples * parameters(order + extra, degrees, inputs) ** 2 <= WORK:
            return extra, degrees, inputs
    return None


def iterations(model, runs: list[Run]) -> int:
    """The nonlinear stage's iterations the fit may take: :data:`SENSITIVITY_WORK` over the work of
    one iteration's sensitivities (the samples simulated, a periodic run's steady-state lead-in
    included, times the parameters: a lightly damped model needs up to 20 periods of lead-in
    ahead of the mean period it is fitted on, :mod:`nlsid.simulate.pnlss_runs`), within
    [MIN_ITERATIONS, MAX_ITERATIONS]."""
    from nlsid.simulate.pnlss_runs import lead_periods

    simulated = 0
    for run in runs:
        if run.period is not None and run.n_periods >= 1:
            simulated += (lead_periods(model, run.period) + 1) * run.period
        else:
            simulated += run.n_samples
    per_iteration = max(simulated * model.n_parameters, 1)
    return int(min(MAX_ITERATIONS, max(MIN_ITERATIONS, SENSITIVITY_WORK // per_iteration)))


def fit_yardstick(runner: ModelRunner, fit_runs: list[Run], val_runs: list[Run], val: list,
                  output_offset: float = 0.0, progress=None) -> Yardstick:
    """Fit and score the yardstick (module docstring). ``fit_runs``: the estimation parts the
    hypotheses were fitted on; ``val_runs`` and ``val``: the validation runs and the user's
    model's residuals on them (:func:`nlsid.diagnose.gain.score`); ``progress(count, budget)``:
    told the fit's accepted iterates (:func:`nlsid.fit.pnlss.fit_pnlss`, e.g. a :class:`WorkProgress`)."""
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
                             f"costs more than {WORK:.0e} samples x parameters^2 per iteration even in the LFR form "
                             "with one combination z = Cz x + Dz u")
        extra, degrees, inputs = shape
        if inputs or degrees != DEGREES:
            model, _ = from_linear(start, fit_runs[0].fs, degrees, degrees, True, output_offset=output_offset,
                                   lfr_inputs=inputs)
        model = with_delay_states(model, extra) if extra else model
        own, early, rule = _holdout(fit_runs, val_runs)
        own, early = as_recorded(own), as_recorded(early)
        fit = fit_pnlss(model, own, early, max_iterations=iterations(model, own + early),
                        linear_iterations=LINEAR_ITERATIONS, patience=PATIENCE, progress=progress)
        if inputs:
            full = parameters(model.order, degrees)
            fit.notes.insert(0, f"LFR form: a polynomial in all {model.order} states and u would have {full} parameters, "
                                f"{samples} x {full}^2 = {samples * full ** 2:.2g} samples x parameters^2 per iteration "
                                f"(the limit is {WORK:.0e}); the nonlinearity acts on {inputs} combination(s) "
                                f"z = Cz x + Dz u instead ({model.n_parameters} parameters), the states kept")
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
