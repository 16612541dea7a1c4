"""The ``diagnose`` stage as a library call: evidence, hypotheses, verdict, extension and gain.

:func:`diagnose` takes a model config (plain data, as loaded from YAML) and the measured runs and
answers the four questions of the stage: what the simulation gets wrong
(:mod:`~nlsid.diagnose.evidence`), the cause (:mod:`~nlsid.diagnose.hypotheses` ranked by
:mod:`~nlsid.diagnose.verdict`), the extension (the winner's extended config), and the gain on
validation data (:mod:`~nlsid.diagnose.gain`).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Callable

from nlsid.diagnose import accuracy, nuisances
from nlsid.diagnose import verdict as rules
from nlsid.diagnose.evidence import Evidence, gather
from nlsid.diagnose.significance import verdict_dof
from nlsid.diagnose.gain import Score, model_residuals, score
from nlsid.diagnose.hybrid import HybridFit, fit_hybrid
from nlsid.diagnose.hypotheses import LIBRARY, Context, Estimate, Hypothesis
from nlsid.diagnose.hypotheses.base import with_lti
from nlsid.diagnose.hypotheses.mechanics import linear_paths
from nlsid.diagnose.simulation import ModelRunner
from nlsid.diagnose.split import BUDGET_ABOVE, BUDGET_SAMPLES, ESTIMATION, VALIDATION, Budget, assign, budgeted
from nlsid.diagnose.outcome import Outcome
from nlsid.diagnose.result import Diagnosis
from nlsid.diagnose.yardstick import WorkProgress, Yardstick, fit_yardstick
from nlsid.errors import InputError
from nlsid.io.ranges import SampleRange
from nlsid.io.run import Run
from nlsid.io.units import common_units
from nlsid.simulate.channels import absent_notes
from nlsid.simulate.threads import blas_in_one_thread


FIT_STEPS = 25
STALL_DB = 0.01  # a refinement stops where its last steps gained less than this (fit_free_parameters) ...
STALL_SHARE = 0.01  # ... or less than this share of its distance in dB above the noise floor
NUMERATOR = re.compile(r"\.num\[\d+\]$")  # a numerator coefficient's key path (:func:`refine`)
FINAL_EVALUATIONS = 2  # cost evaluations of the final model's refinement on every estimation sample (_refine_on_all)


def refine(hypothesis: Hypothesis, data: dict, estimate: Estimate, runs: list[Run], source: str,
           nominal: dict, carried: dict[str, str] | None = None, fit_on: str = "y"
           ) -> tuple[Estimate, dict, dict, dict, nuisances.Nuisances]:
    """The signature estimate refined by the fit engine (simulation error of the estimation runs),
    together with the nuisances (:mod:`nlsid.diagnose.nuisances`, starting at their values in
    ``data``): fitted on a model that lacks the cause, they absorb part of it (a skew takes some of
    a friction's phase lag), so each hypothesis re-fits them with its own parameters. A dead time
    and the output timing are one shift: the delay hypothesis takes it whole (the timing back at
    its value in the user's ``nominal`` model, not fitted). An estimate with an ``lti`` extends
    the model with that LTI part in place of its own (:func:`with_lti`: a discrete model's
    continuous equivalent). Returns the estimate, the extended config with every fitted value
    written in, the free parameters fitted (key path -> FreeParameter), the hypothesis'
    parameters' key paths and the nuisances as re-fitted with them.

    Each parameter keeps its sign and stays within three decades of its signature estimate, but a
    numerator coefficient of a linear part (a key path ending in ``num[i]``), which may change sign
    or vanish: a zero may lie in either half-plane, and the continuous equivalent of a discrete BLA
    carries a zero of the sampling that a plant of relative degree 2 lacks (a Duffing oscillator
    seen through a 2/2 fit: s-coefficient 74 at the start, about 0 in truth; held at 0.074, the
    lower bound of three decades, the cubic feedback's test error on a larger record was 1.2 mV
    instead of 0.06 mV). The optimiser stops, as converged, where its last four accepted steps
    lowered the error by less than STALL_DB (0.01 dB) together, or less than STALL_SHARE (1 %) of
    its distance in dB above the estimation runs' noise floor: a hypothesis that is not the cause
    creeps along a valley (a Stribeck law on LuGre presliding spent its last 9 Jacobians at the
    same -0.35 dB; on the battery 795 -> 686 simulations of a LuGre diagnosis, same verdict and
    values). It gets :func:`budget` cost evaluations (besides its finite-difference Jacobians):
    the fits of a present effect with a few parameters converge in 5 to 15; a hypothesis that is
    not the cause can wander into parameters the simulator is slow on (a Stribeck curve steeper
    than the mass can follow), and is then scored where the budget stopped it, with the optimiser's warning.
    ``fit_on``: the judged signal whose simulation error is minimised (``y``, or in closed loop ``u``).

    An estimate with ``alternatives`` (starts it cannot tell apart, e.g. the two signs of a shape
    parameter) is refined from each in turn and the fit of the least simulation error kept (the sum
    of squares of measured minus simulated mean steady-state periods of the judged signal of
    ``runs``, :meth:`Context.simulation_rss`, the same measure for every start: the fit engine's own
    error is over mean periods or whole runs as each start's model settles), its note naming the
    start that won and the others' errors (a fit whose error is not finite loses); an alternative
    whose fit fails is passed over (said in the note).
    """
    first = _refine_start(hypothesis, data, dataclasses.replace(estimate, alternatives=()), runs, source, nominal,
                          carried, fit_on)
    if not estimate.alternatives:
        return first
    tried, failed = [first], []
    for alternative in estimate.alternatives:
        try:
            tried.append(_refine_start(hypothesis, data, alternative, runs, source, nominal, carried, fit_on))
        except InputError as exc:
            failed.append(f"alternative start {len(tried) + len(failed)} not refined ({exc})")
    costs = [Context(ModelRunner.from_data(fit[1], source), runs, [], [], signal=fit_on).simulation_rss(fit[1])
             for fit in tried]
    best = min(range(len(tried)), key=lambda i: costs[i] if math.isfinite(costs[i]) else math.inf)
    others = ", ".join(f"start {i + 1} {costs[i]:.4g}" for i in range(len(tried)) if i != best)
    won = (f"of {len(estimate.alternatives) + 1} starts refined in turn, start {best + 1} (the "
           f"{'estimate' if best == 0 else 'alternative'} above) kept: simulation error (sum of squares) "
           f"{costs[best]:.4g} against {others or 'none'}")
    refined, *rest = tried[best]
    return (dataclasses.replace(refined, note="; ".join([refined.note, won, *failed])), *rest)


def _refine_start(hypothesis: Hypothesis, data: dict, estimate: Estimate, runs: list[Run], source: str,
                  nominal: dict, carried: dict[str, str] | None = None, fit_on: str = "y"
                  ) -> tuple[Estimate, dict, dict, dict, nuisances.Nuisances]:
    """:func:`refine` from one start (``estimate``'s alternatives not looked at)."""
    from nlsid.fit.extension import fit_free_parameters
    from nlsid.fit.free_parameters import FreeParameter, value_at

    if estimate.lti is not None:  # the model's LTI part in the form the hypothesis extends
        data = with_lti(data, estimate.lti)
    extended = hypothesis.extend(data, estimate.values)
    timing = hypothesis.family != "delay"
    if not timing:
        extended["model"].pop("output_timing", None)
        if "output_timing" in nominal["model"]:
            extended["model"]["output_timing"] = nominal["model"]["output_timing"]
    paths = estimate.paths if estimate.paths is not None else hypothesis.paths(data) if hypothesis.paths else {}
    if hypothesis.refits_linear:
        paths = {**linear_paths(extended), **paths}
    paths = {**_carried(carried or {}, extended), **paths}
    free = nuisances.free_nuisances(ModelRunner.from_data(extended, source), runs, timing)
    for key in hypothesis.holds:  # held at its value in ``data``
        free.pop(f"model.{key}", None)
    starts = {f"model.{key}": value for key, value in (estimate.starts or {}).items()}
    for path, value in starts.items():  # a nuisance started elsewhere (within the bounds it has)
        if path in free:
            p = free[path]
            free[path] = dataclasses.replace(p, start=min(max(value, p.lower), p.upper))
    for name, path in paths.items():  # a parameter without a signature estimate starts at the model's value
        start = (estimate.values[name] if name in estimate.values
                 else starts[path] if path in starts else float(value_at(extended, path)))
        if not (math.isfinite(start) and start != 0):
            raise InputError(name, f"the signature estimate is {start:g}: nothing to refine (no sign to keep)")
        bounds = (-abs(start) * 1e3, abs(start) * 1e3) if NUMERATOR.search(path) else sorted((start * 1e-3, start * 1e3))
        free[path] = FreeParameter(start, *bounds)
    fit = fit_free_parameters(extended, free, runs, [], source=source, max_evaluations=budget(free),
                              stall_db=STALL_DB, stall_share=STALL_SHARE, fit_on=fit_on, run_errors=False)
    values, std = _derived(hypothesis, *_fitted(estimate, fit, paths), free, paths, fit.config["model"])
    what = "refined by the fit engine (simulation error)" if paths else "nuisances re-fitted with it"
    reading = hypothesis.reading(values) if hypothesis.reading is not None else ""
    note = "; ".join(filter(None, [estimate.note, what, *fit.warnings, reading]))
    return Estimate(values, std, estimate.explained_db, note), fit.config, free, paths, nuisances.fitted(fit)


def _update_earlier(chain: list[Outcome]) -> None:
    """The earlier causes' values and standard errors as the last one's refinement left them (it
    refined them again: :func:`_carried`), so that the chain reports the final model's values."""
    last = chain[-1].estimate
    for earlier in chain[:-1]:
        names = [name for name in earlier.paths if name in last.values]
        earlier.estimate = dataclasses.replace(
            earlier.estimate, values={**earlier.estimate.values, **{n: last.values[n] for n in names}},
            std={**earlier.estimate.std, **{n: last.std[n] for n in names}})


def _carried(carried: dict[str, str], extended: dict) -> dict[str, str]:
    """The parameters of the causes accepted in earlier rounds (name -> key path) that the
    extended config still holds, with a value that has a sign to keep: refined again with each
    hypothesis of a later round (fitted without the later cause, they carry part of it: Coulomb
    friction fitted before a cubic spring came out 1.6 % high, and the final model stayed 5 dB above
    the floor with it held)."""
    from nlsid.fit.free_parameters import value_at

    out = {}
    for name, path in carried.items():
        try:
            value = value_at(extended, path)
        except InputError:  # the later hypothesis rebuilt the model: the path is gone
            continue
        if isinstance(value, (int, float)) and math.isfinite(value) and value != 0:
            out[name] = path
    return out


def _fitted(estimate: Estimate, fit, paths: dict[str, str]) -> tuple[dict, dict]:
    """The estimate's values and standard errors with those of its parameters at ``paths`` taken
    from the fit engine's result ``fit``."""
    values = {**estimate.values, **{name: fit.value(path) for name, path in paths.items()}}
    std = {**estimate.std, **{name: float(fit.std[fit.names.index(path)]) for name, path in paths.items()}}
    return values, std


def _derived(hypothesis: Hypothesis, values: dict, std: dict, free: dict, paths: dict[str, str],
             model: dict) -> tuple[dict, dict]:
    """``values`` and ``std`` with the hypothesis' derived values (``Hypothesis.derive``: of the
    fitted values against their starts, the model's own; standard errors not computed, NaN)."""
    if hypothesis.derive is None:
        return values, std
    starts = {name: free[path].start for name, path in paths.items() if path in free}
    extra = hypothesis.derive(values, starts, model)
    return values | extra, std | {name: float("nan") for name in extra}


def budget(free: dict) -> int:
    """Cost evaluations of a refinement: :data:`FIT_STEPS`, or two per free parameter where there
    are more (a Wiener-Hammerstein model's 27 on an analog stand-in: stopped at 25 its test error
    was 0.94 mV, with 56 0.50 mV)."""
    return max(FIT_STEPS, 2 * len(free))


def refit_finer(outcome: Outcome, substeps: int, runs: list[Run], source: str, fit_on: str = "y") -> None:
    """Re-fit ``outcome``'s free parameters (those of its :func:`refine`) from their fitted values
    with ``substeps`` sub-steps per sample, which its extended config then keeps
    (:mod:`nlsid.diagnose.accuracy`: the default step missed a tenth of the floor), on the judged
    signal ``fit_on``."""
    from nlsid.fit.extension import fit_free_parameters

    data = copy.deepcopy(outcome.extended)
    data.setdefault("simulation", {})["substeps"] = substeps
    free = {path: dataclasses.replace(p, start=None) for path, p in outcome.free.items()}
    fit = fit_free_parameters(data, free, runs, [], source=source, max_evaluations=budget(free),
                              stall_db=STALL_DB, fit_on=fit_on, run_errors=False)
    est = outcome.estimate
    values, std = _derived(outcome.hypothesis, *_fitted(est, fit, outcome.paths), outcome.free, outcome.paths,
                           fit.config["model"])
    note = "; ".join([est.note, f"re-fitted with {substeps} sub-steps per sample (the simulation's error "
                                "below a tenth of the floor)", *fit.warnings])
    outcome.estimate = Estimate(values, std, est.explained_db, note)
    outcome.extended, outcome.found = fit.config, nuisances.fitted(fit)


def sufficient_simpler(hypothesis: Hypothesis, outcomes: list[Outcome]) -> Outcome | None:
    """An already scored hypothesis with fewer parameters whose validation error is not
    significantly above the noise (p >= ALPHA), or None.

    Such a hypothesis makes fitting the richer one pointless: a hypothesis is named over it only
    when ``E_simpler / E_richer > F*`` (:mod:`nlsid.diagnose.verdict`), and with ``E_simpler``
    within ``F*`` of the noise floor that needs ``E_richer`` below the floor, which on validation
    runs (noise the fit never saw) happens with probability about ALPHA; at equal errors the
    explanation with fewer parameters is the one named (within a family the verdict's own rule;
    across families a tie the data cannot resolve, which the simpler explanation settles). The
    hypotheses are tried in the order of their parameter counts (:func:`_by_parameters`), so a
    present cubic spring (one parameter) at the floor spares the Stribeck and LuGre fits (three
    and four) that a family that is not the cause would cost, and a Coulomb friction at the floor
    spares them likewise.
    """
    for outcome in outcomes:
        h = outcome.hypothesis
        if (len(h.parameters) < len(hypothesis.parameters) and outcome.score is not None
                and outcome.score.within_floor):
            return outcome
    return None


def _by_parameters(library: tuple[Hypothesis, ...]) -> list[Hypothesis]:
    """The library in the order its hypotheses are tried: by parameter count, the library's order
    among equals (a family's simpler members first, so a richer member can start from their fits)."""
    return sorted(library, key=lambda h: len(h.parameters))


def _score(outcome: Outcome, runner: ModelRunner, val_runs: list[Run], val_res: list, signal: str = "y") -> None:
    try:
        extended = runner.with_changes(outcome.extended)
    except InputError as exc:
        outcome.reason = f"the extended model is not valid: {exc.what}"
        return
    try:  # valid as a config, the extension may still not run (a dead time that destabilises the loop)
        outcome.residuals = model_residuals(extended, val_runs, val_res, signal)
    except InputError as exc:
        outcome.reason = f"the extended model does not run: {exc.what}"
        return
    outcome.score = score(val_res, outcome.residuals)


MAX_CAUSES = 3  # causes accepted one after the other at most (each round fits the whole library)
YARDSTICK = True  # whether diagnose() fits the black-box yardstick when its caller does not say
HYBRID = True  # whether diagnose() fits the hybrid model (nlsid.diagnose.hybrid) where the yardstick is ahead

# The work :func:`diagnose` reports to its ``step``, in units of one free parameter of a hypothesis'
# fit (about five simulations of the estimation runs: a finite-difference Jacobian column for each of
# the fit's evaluations; 4.7 on average over the 22 fits of the sample stage and of a two-cause
# diagnosis, tests/diagnose/test_diagnose_chain.py). A fit's time per unit varied as much as its time
# per simulation there (coefficient of variation 0.49 against 0.51 on the sample, 1.04 against 1.17
# on the two-cause diagnosis: a friction law simulates slower than a polynomial), and the free
# parameters are known before the fit. The other steps are weighed by their time against the
# average unit of the same diagnosis (the sample's 0.72 s, the two-cause one's 0.17 s on 2 loaded cores).
FIT_FREE_BESIDES = 5  # free parameters of a hypothesis' fit besides its own, expected before it is fitted
#                       (the nuisances and the linear parameters it refines: 5 or 6 in 17 of those fits)
EVIDENCE_WORK = 4  # a round's evidence (its simulation of every run, BLA, distortion; measured 2.5 and 16)
NUISANCE_WORK = 1  # a round's nuisances (measured 1.1 and 1.4)
YARDSTICK_WORK = 230  # the black-box yardstick's fit (measured 316 and 165: within 1.4 times of both)
HYBRID_WORK = YARDSTICK_WORK  # the hybrid's black-box term: a PNLSS fit of the yardstick's size and budget


def fit_work(hypothesis: Hypothesis, carried: dict[str, str] | None = None) -> int:
    """The work a hypothesis' fit is expected to take before it is fitted: its free parameters
    (its own, :data:`FIT_FREE_BESIDES` and the ``carried`` parameters of earlier causes) + 1."""
    return len(hypothesis.parameters) + FIT_FREE_BESIDES + len(carried or {}) + 1


def round_work(runner: ModelRunner, accepted: tuple[str, ...] = (), carried: dict[str, str] | None = None
               ) -> dict[str, int]:
    """The expected work (:func:`fit_work`) of each hypothesis a round of ``runner``'s model may fit:
    those of a family not ``accepted`` that apply to the model."""
    return {h.name: fit_work(h, carried) for h in LIBRARY if h.family not in accepted and h.applies(runner) is None}


def planned_work(data: dict, source: str, yardstick: bool | None = None) -> int:
    """The work :func:`diagnose` plans before it starts: the first round's (evidence, nuisances and
    :func:`round_work`) and the yardstick's (``yardstick``: as :func:`diagnose`'s argument)."""
    wanted = YARDSTICK if yardstick is None else yardstick
    loop = data.get("closed_loop")
    if isinstance(loop, dict) and isinstance(loop.get("computation_delay"), (str, dict)):
        # computation_delay: auto is chosen later, from the data; which hypotheses apply does not depend on it
        data = {**data, "closed_loop": {**loop, "computation_delay": 0}}
    work = round_work(ModelRunner.from_data(data, source))
    return EVIDENCE_WORK + NUISANCE_WORK + sum(work.values()) + (YARDSTICK_WORK if wanted else 0)


@blas_in_one_thread
def diagnose(data: dict, source: str, runs: list[Run], where: str,
             step: Callable[[str, int, int], None] | None = None, *, validate_on: list[Run] = (),
             estimation_range: SampleRange | None = None, validation_range: SampleRange | None = None,
             estimation_budget: int | None = BUDGET_SAMPLES, budget_above: int = BUDGET_ABOVE,
             yardstick: bool | None = None, fit_on: str = "y") -> Diagnosis:
    """Diagnose the model ``data`` (from ``source``) on the measured ``runs`` (from ``where``);
    ``validate_on`` (runs of further recordings) and the ranges: :func:`nlsid.diagnose.split.assign`.

    Several effects: once a cause is named, the extended model is diagnosed again (the families
    already accepted left out), until its validation error is at the noise floor, no hypothesis
    improves it significantly, or :data:`MAX_CAUSES` are named; in a later round every hypothesis
    is refined together with the parameters of the causes accepted before it (:func:`_carried`).
    A tie between families (an ambiguous verdict) is resolved by the next round where it can be
    (:func:`_resolve_tie`). The result is the first round's
    diagnosis (the evidence against the user's model) with the ``chain`` of accepted causes; the
    extended model is the last one's.

    ``estimation_budget``: the estimation samples of arbitrary records the hypotheses are fitted
    on where those records hold more than ``budget_above`` (:func:`nlsid.diagnose.split.budgeted`);
    the final model is then refined once more on all of them (:func:`_refine_on_all`). None: every
    fit on all of them.

    ``yardstick``: fit the black-box model of :mod:`nlsid.diagnose.yardstick` after the chain
    (None: :data:`YARDSTICK`, True); without it the status rests on the noise floor alone (never
    ``outside_library``) and ``summary.json`` ``yardstick`` says it was not asked for. Where the
    yardstick is significantly better than the final extended model, the hybrid model of
    :mod:`nlsid.diagnose.hybrid` is fitted after it (:data:`HYBRID`; its work,
    :data:`HYBRID_WORK`, planned when it starts, and done at the step ``"hybrid"``, the last one
    then); otherwise ``Diagnosis.hybrid`` says why not.

    ``fit_on``: the judged signal, the output ``y`` or in closed loop the command ``u`` (the plant
    input the simulated controller computes): every hypothesis and the nuisances are fitted on it,
    the evidence, the noise floor, the scores and the verdict are of it
    (:mod:`nlsid.diagnose.evidence`, "The judged signal"). ``u`` needs a model with a
    ``closed_loop`` (:func:`check_fit_on`).

    ``step(name, work, planned)`` is told the progress in units of work (:func:`fit_work`): ``work``
    done by the step ``name``, and ``planned``, the change of the work planned. The work planned
    at the start (:func:`planned_work`) is the yardstick's and the first round's; each round plans
    its own (``name`` ``"round"``, no work) with its evidence, nuisances and the hypotheses that
    apply (:func:`round_work`). A hypothesis fitted does the work of its free parameters + 1 (the
    difference from the work expected of it is added to the work planned); one not fitted (its
    signature, the evidence or a simpler hypothesis at the noise floor rules it out) takes its
    share back without work, as the yardstick not fitted does. The yardstick's fit advances its
    share in proportion to its iterates (``name`` ``"yardstick iterates"``,
    :class:`nlsid.diagnose.yardstick.WorkProgress`); the last step, ``"yardstick"``, does the rest
    of it, or where the yardstick was not fitted takes back what was not done. The work done
    reaches the work planned there.
    """
    wanted = YARDSTICK if yardstick is None else yardstick
    step = _planning(step or (lambda name, work, planned: None), YARDSTICK_WORK if wanted else 0)
    check_fit_on(fit_on, ModelRunner.from_data(data, source))  # the model is valid before the data are looked at
    runs, roles = assign(runs, where, validate_on, estimation_range, validation_range)
    budget = budgeted(runs, roles, estimation_budget or math.inf, budget_above if estimation_budget else math.inf)
    first = current = last = _round(data, source, runs, roles, where, step, (), budget=budget, signal=fit_on)
    first.units = common_units(run.units for run in runs)  # the parameters' units (nlsid.models.parameter_units)
    following = None  # the next round, where resolving a tie computed it already
    while True:
        if current.verdict.status == rules.AMBIGUOUS and len(first.chain) + 1 < MAX_CAUSES:
            resolved = _resolve_tie(current, first.chain, data, source, runs, roles, where, step, budget)
            if resolved is not None:
                current.verdict, following = resolved
        if current.verdict.status != rules.EXPLAINED:
            break
        first.chain.append(current.winner)
        _update_earlier(first.chain)
        last = current
        done = current.winner.score.within_floor
        if done or len(first.chain) == MAX_CAUSES:
            break
        current = following or _next_round(current.winner, first.chain, data, source, runs, roles, where, step,
                                           budget, fit_on)
        following = None
    first.accuracy = _accurate(first, last, data, source, runs, roles, budget)
    _refine_on_all(first, last, data, source, runs, roles)
    advanced = WorkProgress(step, YARDSTICK_WORK)  # the fit's iterates move the yardstick's share
    first.yardstick = (_yardstick(first, data, source, runs, roles, budget, advanced) if wanted
                       else Yardstick("not fitted: not asked for (--no-yardstick)"))
    work = YARDSTICK_WORK - advanced.units if first.yardstick.fitted else 0
    step("yardstick", work, work + advanced.units - YARDSTICK_WORK if wanted else 0)
    first.hybrid = (_hybrid(first, source, runs, roles, budget, step) if wanted and HYBRID
                    else HybridFit("not fitted: " + ("no yardstick (not asked for)" if not wanted else "not asked for")))
    judge_extent(first)
    return first


def _planning(step: Callable[[str, int, int], None], work: int) -> Callable[[str, int, int], None]:
    """``step`` with ``work`` added to the work planned by its first call (the first round's plan):
    the whole plan told at once."""
    pending = [work]

    def planning(name: str, done: int, planned: int) -> None:
        step(name, done, planned + (pending.pop() if pending else 0))

    return planning


SIGNALS = ("y", "u")  # the signals a diagnosis can judge: the output, or in closed loop the command


def check_fit_on(fit_on: str, runner: ModelRunner, name: str = "fit_on") -> None:
    """Refuse a judged signal other than ``y`` or ``u``, and ``u`` for a model without a
    ``closed_loop`` (in open loop the recorded u is the input the simulation is driven by);
    ``name`` is the argument's name in the message."""
    if fit_on not in SIGNALS:
        raise InputError(name, f"expected y or u, got {fit_on!r}")
    if fit_on == "u" and not runner.closed:
        raise InputError(name, "u is judged only in closed loop (the model has no closed_loop): in open loop the "
                               "recorded u is the input the simulation is driven by")


def _yardstick(first: Diagnosis, data: dict, source: str, runs: list[Run], roles: dict[str, str],
               budget: Budget | None, progress=None) -> Yardstick:
    """The black-box model (:mod:`nlsid.diagnose.yardstick`) fitted to the estimation parts the
    hypotheses saw, with the sensor offset the nuisances found, and scored on the validation runs;
    ``progress(count, budget)`` told the fit's iterates."""
    ev = first.evidence
    if ev.exact or ev.constant_output:
        return Yardstick("not fitted: " + ("the model matches the noise-free data exactly" if ev.exact
                                           else "the measured output is constant"))
    by_id = {run.run_id: run for run in runs}
    est_runs = [by_id[res.run_id] for res in ev.residuals if res.role == ESTIMATION]
    val = [res for res in ev.residuals if res.role == VALIDATION]
    fit_runs = budget.of(est_runs) if budget is not None else est_runs
    offset = first.nuisances.values.get("output_offset", float(data["model"].get("output_offset", 0.0)))
    return fit_yardstick(ModelRunner.from_data(data, source), fit_runs, [by_id[res.run_id] for res in val], val,
                         offset, progress)


def _hybrid(first: Diagnosis, source: str, runs: list[Run], roles: dict[str, str], budget: Budget | None,
            step: Callable[[str, int, int], None]) -> HybridFit:
    """The hybrid model (:mod:`nlsid.diagnose.hybrid`) where the yardstick is significantly better
    than the final extended model, fitted on the estimation parts the yardstick saw and scored on
    the validation runs; else why it is not fitted."""
    y, final = first.yardstick, first.final
    if final is None:
        return HybridFit("not fitted: no named cause, so no physical extension to add a black-box term to")
    if not y.fitted:
        return HybridFit(f"not fitted: no yardstick to start its black-box term from ({y.reason})")
    if not first.yardstick_ahead(first.final_score()):
        return HybridFit("not fitted: the black-box yardstick is not significantly better than the extended model "
                         "(the verdict's F rule), so no remainder is left for a black-box term")
    step("hybrid", 0, HYBRID_WORK)
    by_id = {run.run_id: run for run in runs}
    est_runs = [by_id[res.run_id] for res in first.evidence.residuals if res.role == ESTIMATION]
    val = [res for res in first.evidence.residuals if res.role == VALIDATION]
    fit_runs = budget.of(est_runs) if budget is not None else est_runs
    result = fit_hybrid(final.extended, source, y, fit_runs, [by_id[res.run_id] for res in val], val)
    step("hybrid", HYBRID_WORK if result.fitted else 0, 0 if result.fitted else -HYBRID_WORK)
    return result


def judge_extent(first: Diagnosis) -> None:
    """How much the verdict explains (:mod:`nlsid.diagnose.verdict`): a named cause whose final
    model stays significantly above the floor makes the status ``partly_explained``; without a
    named cause, the best-scored hypothesis is the leading candidate when its gain over the
    baseline is suggestive (:func:`nlsid.diagnose.verdict.suggestive`). The yardstick decides
    too: a named cause's final model that it beats significantly (the F rule) is partly
    explained, whatever the floor; without a named cause, a yardstick that beats the baseline
    significantly makes the status ``outside_library``."""
    status = first.verdict.status
    final = first.final_score()
    if status == rules.EXPLAINED and final is not None and (rules.partly(final.above_floor_db, final.p_above_noise)
                                                            or first.yardstick_ahead(final)):
        first.verdict = dataclasses.replace(first.verdict, status=rules.PARTLY_EXPLAINED)
    if status in (rules.UNEXPLAINED, rules.UNDETERMINED) and first.yardstick_ahead(first.baseline):
        first.verdict = dataclasses.replace(first.verdict, status=rules.OUTSIDE_LIBRARY)
    if status in (rules.UNEXPLAINED, rules.UNDETERMINED) and first.baseline is not None:
        base = first.baseline.error_rms ** 2
        better = [o for o in first.outcomes if o.score is not None and o.estimate is not None
                  and rules.suggestive(rules.ratio(base, o.score.error_rms ** 2), first.verdict.dof)]
        first.leading = better[0] if better else None


def _refine_on_all(first: Diagnosis, last: Diagnosis, data: dict, source: str, runs: list[Run],
                   roles: dict[str, str]) -> None:
    """Where the hypotheses were fitted within the estimation budget, the final model's free
    parameters refined once more on every estimation sample, from the budget's fit, and scored again
    on the validation runs (``last``: the round that accepted it). The budget's fit is within about
    sqrt(N / B) of its standard errors of the optimum on all N samples, where the cost is nearly
    quadratic, so one Gauss-Newton step reaches it: :data:`FINAL_EVALUATIONS` (2) cost evaluations
    are the start and that step, with a Jacobian at each (the second gives the standard errors).
    Measured on the 40000-sample Duffing record of tests/diagnose/test_diagnose_budget.py (budget 4096): k3
    0.01 standard errors from the fit on all samples with 2 evaluations (16 simulations), 0.0002
    with 3 or 6 (24, 27). The earlier causes take its values
    (:func:`_update_earlier`); the verdict stays the budget's."""
    from nlsid.fit.extension import fit_free_parameters

    outcome = first.final
    if first.budget is None or not first.budget.active or outcome is None or not outcome.free:
        return
    estimation = [run for run in runs if roles.get(run.run_id) == ESTIMATION]
    free = {path: dataclasses.replace(p, start=None) for path, p in outcome.free.items()}
    est = outcome.estimate
    try:
        fit = fit_free_parameters(outcome.extended, free, estimation, [], source=source,
                                  max_evaluations=FINAL_EVALUATIONS, stall_db=STALL_DB, fit_on=first.signal,
                                  run_errors=False)
    except InputError as exc:  # the budget's fit stands, and says why
        outcome.estimate = dataclasses.replace(est, note=f"{est.note}; not refined on all estimation samples: {exc}")
        return
    values, std = _derived(outcome.hypothesis, *_fitted(est, fit, outcome.paths), outcome.free, outcome.paths,
                           fit.config["model"])
    capped = [w for w in fit.warnings if w.startswith("optimiser stopped")]  # said in words below
    warnings = [w for w in fit.warnings if w not in capped]
    cap = f", stopped at its {FINAL_EVALUATIONS} cost evaluations" if capped else ""
    again = f"refined once more on all {first.budget.available} estimation samples ({fit.evaluations} simulations{cap})"
    note = "; ".join([est.note, f"{again}, with: {', '.join(warnings)}" if warnings else again])
    outcome.estimate = Estimate(values, std, est.explained_db, note)
    outcome.extended, outcome.found = fit.config, nuisances.fitted(fit)
    val = [res for res in last.evidence.residuals if res.role == VALIDATION]
    by_id = {run.run_id: run for run in runs}
    _score(outcome, ModelRunner.from_data(data, source), [by_id[res.run_id] for res in val], val, first.signal)
    _update_earlier(first.chain)


def _next_round(cause: Outcome, chain: list[Outcome], data: dict, source: str, runs: list[Run],
                roles: dict[str, str], where: str, step: Callable[[str], None],
                budget: Budget | None = None, signal: str = "y") -> "Diagnosis":
    """The round that diagnoses ``cause``'s extended model, the families of ``chain`` (which ends
    with ``cause``) left out and their parameters refined again (:func:`_carried`), on the judged
    ``signal``."""
    accepted = tuple(o.hypothesis.family for o in chain)
    carried = {name: path for o in chain for name, path in o.paths.items()}
    return _round(cause.extended, source, runs, roles, where, step, accepted, carried, data, budget, signal)


@dataclass(frozen=True)
class _Branch:
    """A tied hypothesis taken as the cause, and the round after it (:func:`_resolve_tie`)."""

    outcome: Outcome
    following: "Diagnosis"

    @property
    def causes(self) -> list[Outcome]:
        explained = self.following.verdict.status == rules.EXPLAINED
        return [self.outcome] + ([self.following.winner] if explained else [])

    @property
    def power(self) -> float:
        return self.causes[-1].score.error_rms ** 2

    @property
    def size(self) -> int:
        return sum(len(o.hypothesis.parameters) for o in self.causes)

    @property
    def names(self) -> frozenset:
        return frozenset(o.hypothesis.name for o in self.causes)


def _resolve_tie(current: "Diagnosis", chain: list[Outcome], data: dict, source: str, runs: list[Run],
                 roles: dict[str, str], where: str, step: Callable[[str], None], budget: Budget | None = None):
    """A tie between families resolved by what comes after each: two differences from reality at
    once (a dead time and a quadratic output) leave each of their hypotheses alone an equal share
    of the error, and a missing resonance, which mimics a dead time's phase lag in the band, ties
    with the dead time until the other difference is in the model. Each tied hypothesis is taken
    as a cause and the next round run on its extended model; a branch ends with that round's cause
    if it names one, else with the tied hypothesis. The branches whose final validation error is
    within the verdict's F* of the best are equally good; of them the simplest (the fewest
    parameters of their causes' own, as rule 3 of :mod:`nlsid.diagnose.verdict` within a family)
    is taken when the simplest name one set of causes (a dead time then a quadratic output, or the
    other way round). The tied hypotheses are tried from the fewest parameters up, and one whose
    branch would have more parameters than a branch that ends at the noise floor has in all (its
    own, and one more where it alone is not at the floor) is not tried: it could only be richer
    (a missing resonance, three parameters, after a dead time and a quadratic term at the floor:
    39 -> 14 s). Returns (the verdict with that branch's first cause, its next round), or None
    (the verdict stays ambiguous)."""
    tied = sorted((o for o in current.outcomes if o.hypothesis.name in current.verdict.tied and o.score is not None),
                  key=lambda o: len(o.hypothesis.parameters))
    branches: list[_Branch] = []
    for outcome in tied:
        at_floor = [b.size for b in branches if b.causes[-1].score.within_floor]
        least = len(outcome.hypothesis.parameters) + (not outcome.score.within_floor)
        if at_floor and least > min(at_floor):
            continue
        branches.append(_Branch(outcome, _next_round(outcome, [*chain, outcome], data, source, runs, roles, where,
                                                     step, budget, current.signal)))
    best = min(b.power for b in branches)
    near = [b for b in branches if rules.ratio(b.power, best) <= current.verdict.threshold]
    fewest = min(b.size for b in near)
    simplest = sorted((b for b in near if b.size == fewest), key=lambda b: b.power)
    if len({b.names for b in simplest}) > 1:
        return None
    chosen = simplest[0]
    return dataclasses.replace(current.verdict, status=rules.EXPLAINED, winner=chosen.outcome.hypothesis.name), \
        chosen.following


def _accurate(first: Diagnosis, last: Diagnosis, data: dict, source: str, runs: list[Run],
              roles: dict[str, str], budget: Budget | None = None) -> accuracy.Accuracy | None:
    """The accuracy of the final model (:mod:`nlsid.diagnose.accuracy`) against the noise where it
    is measured, else the best model's validation error.

    Where the default step misses a tenth of it and :func:`accuracy.refit_substeps` gives the
    sub-steps to re-fit at, every scored hypothesis of the final cause's family in the round
    that accepted it (``last``) is re-fitted at them (:func:`refit_finer`) and scored again, and
    that round's verdict is taken again: the step's error is what a richer law of one family fits
    (Coulomb named LuGre at 10 sub-steps), so the laws of the family are compared at the step the
    data need. A member whose own simulation already meets the aim at its step is kept as fitted
    (a Coulomb law that 10 sub-steps simulate to 4e-10 where a stiff LuGre law needs 50: refitting
    it at 50 took 49 s on a stage recording and left it where it was). Other families stay as
    scored: they were beaten by more than the F rule's margin. Checked, and re-fitted, on the
    estimation parts of the ``budget`` (the step's error is a property of the simulation, which
    the part shows as well as the whole record).
    """
    outcome = first.final
    estimation = [run for run in runs if roles.get(run.run_id) == ESTIMATION]
    estimation = budget.of(estimation) if budget is not None else estimation
    floor, floor_from = _accuracy_floor(first, outcome)
    signal = first.signal
    checked = accuracy.check(outcome.extended if outcome is not None else data, source, estimation, floor, floor_from,
                             signal)
    if checked is None or checked.sufficient or outcome is None or not outcome.free:
        return checked
    substeps = accuracy.refit_substeps(checked, outcome.extended)
    if substeps is None:
        return checked
    val = [res for res in last.evidence.residuals if res.role == VALIDATION]
    by_id = {run.run_id: run for run in runs}
    runner = ModelRunner.from_data(data, source)
    for member in last.outcomes:
        if member.hypothesis.family == outcome.hypothesis.family and member.score is not None and member.free:
            own = member is outcome or accuracy.check(member.extended, source, estimation, floor, floor_from, signal)
            if own is True or own is None or not own.sufficient:
                try:
                    refit_finer(member, substeps, estimation, source, signal)
                except InputError:  # a member extended in discrete time runs one step per sample: no finer step
                    continue
                _score(member, runner, [by_id[res.run_id] for res in val], val, signal)
    last.outcomes.sort(key=_rank)
    last.verdict = _decide(last.evidence, last.nuisances, last.baseline, last.outcomes, val)
    if last.verdict.status == rules.EXPLAINED:
        first.chain[-1] = last.winner
    floor, floor_from = _accuracy_floor(first, first.final)
    again = accuracy.check(first.final.extended, source, estimation, floor, floor_from, signal)
    return dataclasses.replace(again, refit=True) if again is not None else None


def _accuracy_floor(first: Diagnosis, final: Outcome | None) -> tuple[float, str]:
    """What the final model's simulation error is compared with, and what it is
    (:class:`accuracy.Accuracy` ``floor_from``)."""
    if first.evidence.overall.noise_known and first.evidence.noise_rms > 0:
        return first.evidence.noise_rms, "noise"
    if final is not None:
        return final.score.error_rms, "validation"
    return first.evidence.error_rms, "model"


def _rank(outcome: Outcome) -> tuple[bool, float]:
    """Scored outcomes first, by validation error."""
    return outcome.score is None, outcome.score.error_rms if outcome.score else math.inf


def _decide(evidence: Evidence, found: nuisances.Nuisances, baseline: Score, outcomes: list[Outcome],
            val: list) -> rules.Verdict:
    """The verdict (:mod:`nlsid.diagnose.verdict`) over the scored ``outcomes``, against the
    baseline (the model with its nuisances) on the validation residuals ``val``."""
    candidates = [rules.Candidate(o.hypothesis.name, o.hypothesis.family, len(o.hypothesis.parameters),
                                  o.score.error_rms ** 2, o.generalizes) for o in outcomes if o.score is not None]
    discrepancy = evidence.overall.significant if evidence.overall.noise_known else None
    if discrepancy and found.values and baseline.within_floor:
        discrepancy = False  # the nuisances explain what the evidence saw
    return rules.decide(discrepancy, baseline.error_rms ** 2, candidates, verdict_dof(val))


def _round(data: dict, source: str, runs: list[Run], roles: dict[str, str], where: str,
           step: Callable[[str], None], accepted: tuple[str, ...], carried: dict[str, str] | None = None,
           users: dict | None = None, budget: Budget | None = None, signal: str = "y") -> Diagnosis:
    """One diagnosis of the model ``data``: evidence, nuisances, every hypothesis of a family not in
    ``accepted``, the verdict. ``users``: the user's model (default ``data``), against which the
    outcomes state the mechanics they changed (:meth:`Outcome.mechanics_changed`): the chain
    reports the final model's values for every step (:func:`_update_earlier`), so every step's
    changes are those of the final model against the user's.

    The evidence and the hypotheses' signatures are those of the model as given. The nuisances
    (:mod:`nlsid.diagnose.nuisances`) are fitted to it first; the model with them is the baseline:
    at the noise floor it means nothing beyond noise (and the nuisances), and a hypothesis is a
    cause only when it beats the baseline significantly (each re-fits the nuisances with its own
    parameters, :func:`refine`). The nuisances and the hypotheses are fitted on the estimation
    parts of the ``budget`` (:func:`nlsid.diagnose.split.budgeted`; all of them without one); the
    evidence and the scores are of the whole runs. All of it is of the judged ``signal`` (``y``, or
    in closed loop ``u``: :func:`diagnose`).
    """
    runner = ModelRunner.from_data(data, source)
    expected = round_work(runner, accepted, carried)  # each hypothesis' share of the work (diagnose)
    step("round", 0, EVIDENCE_WORK + NUISANCE_WORK + sum(expected.values()))
    evidence, _ = gather(runner, runs, roles, where, signal)
    by_id = {run.run_id: run for run in runs}
    step("evidence", EVIDENCE_WORK, 0)
    est = [res for res in evidence.residuals if res.role == ESTIMATION]
    val = [res for res in evidence.residuals if res.role == VALIDATION]
    est_runs, val_runs = [by_id[r.run_id] for r in est], [by_id[r.run_id] for r in val]
    fit_runs = budget.of(est_runs) if budget is not None else est_runs
    fit_residuals = [res.residual if part is run else res.residual[:part.period]
                     for res, run, part in zip(est, est_runs, fit_runs)]
    adjusted, found = ((data, nuisances.Nuisances()) if evidence.exact
                       else nuisances.estimate(data, source, fit_runs, signal))
    with_nuisances = ModelRunner.from_data(adjusted, source)
    found = dataclasses.replace(found, initial=nuisances.initial_states(with_nuisances, est_runs + val_runs))
    baseline = score(val, model_residuals(with_nuisances, val_runs, val, signal))
    step("nuisances", NUISANCE_WORK, 0)
    context = Context(runner, fit_runs, fit_residuals, [runner.internal(run) for run in fit_runs],
                      evidence.bla_levels, signal=signal)
    dof = verdict_dof(val)
    outcomes = []
    for hypothesis in _by_parameters(LIBRARY):
        outcome = Outcome(hypothesis, model=users or data)
        outcomes.append(outcome)
        try:
            if hypothesis.family in accepted:
                outcome.reason = f"not fitted: a {hypothesis.family} cause is already in the model (an earlier step)"
                continue
            reason = hypothesis.applies(runner)
            if reason is not None:
                outcome.reason = f"does not apply: {reason}"
                continue
            if evidence.exact:
                outcome.reason = "not fitted: the model reproduces the noise-free data exactly (no residual to explain)"
                continue
            if evidence.constant_output:
                outcome.reason = ("not fitted: the measured output is constant in every run (no response to the input "
                                  "to explain)")
                continue
            if hypothesis.distorts and evidence.distortion_testable and not (evidence.odd_seen or evidence.even_seen):
                outcome.reason = ("not fitted: the detection lines show no nonlinear distortion (odd or even), "
                                  "which a nonlinearity of this kind would leave")
                continue
            simpler = sufficient_simpler(hypothesis, outcomes)
            if simpler is not None:
                reached = ("matches the data exactly" if simpler.score.exact
                           else f"already reaches the noise floor (p = {simpler.score.p_above_noise:.2g})")
                outcome.reason = (f"not fitted: {simpler.hypothesis.title} {reached} with fewer parameters, so this "
                                  "hypothesis cannot be significantly better")
                continue
            try:
                estimate = hypothesis.estimate(context)
            except InputError as exc:  # a start whose simulation the model refuses (diverges): no start, said
                outcome.reason = f"no start estimate: {exc}"
                continue
            if isinstance(estimate, str):
                outcome.reason = estimate
                continue
            try:
                estimate, extended, outcome.free, outcome.paths, outcome.found = refine(
                    hypothesis, adjusted, estimate, fit_runs, source, data, carried, signal)
            except InputError as exc:
                outcome.reason = f"the fit failed: {exc}"
                continue
            if hypothesis.parameters and all(math.isinf(estimate.std.get(n, 0.0)) for n in hypothesis.parameters):
                outcome.reason = ("not a cause: at its fitted values none of its parameters has an effect on the "
                                  "estimation runs (a limit beyond the signal's range), so any gain is the re-fit of "
                                  "the rest of the model")
                continue
            outcome.estimate = context.fitted[hypothesis.name] = estimate
            outcome.extended = context.extended[hypothesis.name] = extended
            _score(outcome, runner, val_runs, val, signal)
            if outcome.score is not None:
                context.errors[hypothesis.name] = outcome.score.error_rms
                context.improves[hypothesis.name] = rules.suggestive(
                    rules.ratio(baseline.error_rms ** 2, outcome.score.error_rms ** 2), dof)
        finally:  # whichever way the hypothesis ended: its work done, or its share taken back
            if hypothesis.name in expected:
                fitted = bool(outcome.free) or outcome.estimate is not None
                work = len(outcome.free) + 1 if fitted else 0
                step(hypothesis.name, work, work - expected[hypothesis.name])
    outcomes.sort(key=_rank)
    verdict = _decide(evidence, found, baseline, outcomes, val)
    samples = sum(res.period * res.n_periods for res in val)
    return Diagnosis(source, roles, evidence, score(val), outcomes, verdict, found, baseline, budget=budget,
                     notes=absent_notes(runner.config, runs),
                     validation_samples=samples, signal=signal)
