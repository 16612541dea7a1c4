"""A diagnosis as it is reported: the evidence, every hypothesis' outcome, the verdict, the chain
of accepted causes, the yardstick, and the words, summary and arrays made of them
(:mod:`nlsid.diagnose.diagnosis` computes it)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from nlsid.diagnose import accuracy, nuisances
from nlsid.diagnose import verdict as rules
from nlsid.diagnose.evidence import Evidence
from nlsid.diagnose.gain import Score, score
from nlsid.diagnose.hybrid import FILE as HYBRID
from nlsid.diagnose.hybrid import HybridFit
from nlsid.diagnose.outcome import MOVED, Outcome
from nlsid.diagnose.split import ESTIMATION, VALIDATION, Budget
from nlsid.diagnose.yardstick import FILE as BLACK_BOX
from nlsid.diagnose.yardstick import Yardstick
from nlsid.models.parameter_units import unit_of, with_unit


@dataclass
class Diagnosis:
    model_source: str
    roles: dict[str, str]
    evidence: Evidence
    original: Score
    outcomes: list[Outcome]
    verdict: rules.Verdict
    nuisances: nuisances.Nuisances = field(default_factory=nuisances.Nuisances)
    baseline: Score | None = None  # the user's model with the nuisances, on the validation runs
    chain: list[Outcome] = field(default_factory=list)  # the causes accepted, one per round
    accuracy: accuracy.Accuracy | None = None  # of the final model (None: exact, no forces)
    budget: Budget | None = None  # the estimation parts the hypotheses were fitted on (split.budgeted)
    leading: Outcome | None = None  # without a named cause: the best hypothesis that lowers the error
    validation_samples: int = 0  # the steady-state samples of the validation runs the scores are of
    yardstick: Yardstick | None = None  # the black-box model fitted to the same estimation data
    hybrid: HybridFit | None = None  # the final extended model with a black-box term for what remains
    notes: list[str] = field(default_factory=list)  # on the runs as simulated (a channel taken as zero)
    signal: str = "y"  # the judged signal: the output y, or in closed loop the command u (diagnose --fit-on)
    units: dict = field(default_factory=dict)  # the recording's (signal -> unit): the parameters' units

    @property
    def final(self) -> Outcome | None:
        """The last accepted cause: its extended model holds every cause of the chain."""
        return self.chain[-1] if self.chain else None

    def final_score(self) -> Score | None:
        """The final extended model's validation score against the user's model."""
        if self.final is None:
            return None
        val = [res for res in self.evidence.residuals if res.role == VALIDATION]
        return score(val, self.final.residuals)

    @property
    def winner(self) -> Outcome | None:
        return next((o for o in self.outcomes if o.hypothesis.name == self.verdict.winner), None)

    def headline(self) -> str:
        """The verdict in one sentence; where the judged signal is the command u, it says so
        (every error, gain and distance to the floor in it is of u)."""
        text = self._verdict_sentence()
        return text if self.signal == "y" else f"{text} [{JUDGED_ON_U}]"

    def _verdict_sentence(self) -> str:
        status, ev = self.verdict.status, self.evidence
        if status == rules.NO_DISCREPANCY:
            if ev.exact:
                return (f"No discrepancy: the simulation reproduces the measured output exactly (error "
                        f"{ev.error_rms:.3g} rms against {ev.output_rms:.3g} rms, within numerical precision); "
                        "the noise floor is zero")
            if ev.overall.significant:  # the nuisances explain what the evidence saw
                b = self.baseline
                found = ", ".join(with_unit(f"{k} = {v:.4g}", self.nuisance_unit(k))
                                  for k, v in self.nuisances.values.items())
                return (f"No significant discrepancy beyond the nuisances ({found}): with them the validation "
                        f"error is within the noise ({b.above_floor_db:+.1f} dB, p = {b.p_above_noise:.2g})")
            return (f"No significant discrepancy: the simulation error is within the noise "
                    f"({ev.overall.above_noise_db:+.1f} dB, p = {ev.overall.p_value:.2g})")
        if status == rules.UNDETERMINED:
            return (f"Undetermined: the noise level is unknown ({NOISE_UNKNOWN}), so the simulation error "
                    f"({ev.error_rms:.3g} rms against {ev.output_rms:.3g} rms of output) cannot be compared with "
                    f"it, and no hypothesis lowers the validation error significantly{self._leading_text()}")
        if status in rules.NAMED:
            stated = [o.mechanics_changed() for o in self.chain]
            causes = ", then ".join(f"{o.named()} ({o.headline_values(tuple(stated[:i]), self.units)})"
                                    for i, o in enumerate(self.chain))
            final = self.final_score()
            several = len(self.chain) > 1
            if status == rules.PARTLY_EXPLAINED and rules.partly(final.above_floor_db, final.p_above_noise):
                return (f"Cause{'s' if several else ''} in part: {causes} explain{'' if several else 's'} "
                        f"{final.gain_db:.1f} dB of the validation error; {final.above_floor_db:.1f} dB remain above "
                        f"the noise floor (p = {final.p_above_noise:.2g}): a further effect, outside the library or "
                        f"richer than the named cause, is left{self._versus_yardstick(final)}")
            if status == rules.PARTLY_EXPLAINED:
                return (f"Cause{'s' if several else ''} in part: {causes} explain{'' if several else 's'} "
                        f"{final.gain_db:.1f} dB of the validation error, {versus_floor(final)}"
                        f"{self._versus_yardstick(final)}")
            return (f"Cause{'s' if several else ''}: {causes}; the extended model's validation error is "
                    f"{gain_text(final)}, {versus_floor(final)}{self._versus_yardstick(final)}")
        if status == rules.OUTSIDE_LIBRARY:
            y, b = self.yardstick.score, self.baseline
            db = 10 * math.log10(rules.ratio(b.error_rms ** 2, y.error_rms ** 2))
            return (f"A nonlinearity outside the library: no hypothesis of the library lowers the validation error "
                    f"significantly, but a black-box state-space model does, by {db:.1f} dB ({y.error_rms:.3g} rms, "
                    f"{versus_floor(y)}); it is written as the extended model, labelled black-box, not a physical "
                    f"cause{self._leading_text()}")
        if ev.noise_zero:
            seen = f"the simulation error is {ev.error_rms:.3g} rms against a zero noise floor: noise-free data"
        elif not ev.overall.noise_known:
            seen = f"the simulation error is {ev.error_rms:.3g} rms; the noise level is unknown ({NOISE_UNKNOWN})"
        else:
            seen = f"the simulation error is {ev.overall.above_noise_db:.1f} dB above the noise"
        if status == rules.AMBIGUOUS:
            return f"Discrepancy ({seen}); equally good explanations: {', '.join(self.verdict.tied)}"
        if ev.constant_output:
            return (f"The measured output is constant in every run: nothing responded to the input, so no extension "
                    f"of the model can explain anything; the model's simulation error is its whole response "
                    f"({ev.error_rms:.3g} rms)")
        return f"Discrepancy ({seen}); no hypothesis of the library explains it{self._leading_text()}"

    def leading_summary(self) -> dict | None:
        """The leading candidate where no cause is named (``summary.json`` ``leading``), or None:
        its gain over the baseline (the model with its nuisances) on the validation runs in dB, the
        gain the verdict needs (10 log10 F*), the validation samples, and the multiple of them that
        would decide a real gain of that size (:func:`nlsid.diagnose.verdict.data_to_decide`)."""
        o = self.leading
        if o is None:
            return None
        power_ratio = rules.ratio(self.baseline.error_rms ** 2, o.score.error_rms ** 2)
        factor = rules.data_to_decide(power_ratio, self.verdict.dof)
        more = (factor - 1) * self.validation_samples if math.isfinite(factor) else math.inf
        return {"name": o.hypothesis.name, "title": o.named(), "gain_db": 10 * math.log10(power_ratio),
                "needed_db": 10 * math.log10(self.verdict.threshold), "validation_samples": self.validation_samples,
                "data_factor": factor, "more_samples": more if math.isfinite(more) else None,
                "file": CANDIDATE}

    def _leading_text(self) -> str:
        lead = self.leading_summary()
        if lead is None:
            return ""
        more = ("" if lead["more_samples"] is None else
                f"; if the gain is real, about {lead['more_samples']:,.0f} more validation samples of this kind "
                "would decide it")
        return (f"; most likely {lead['title']} ({lead['gain_db']:+.1f} dB on the validation runs, not significant: "
                f"{lead['needed_db']:+.1f} dB needed with {lead['validation_samples']} validation samples{more}; "
                f"its model in {CANDIDATE})")

    def explanation(self) -> dict | None:
        """How much of the error the named causes explain (``summary.json`` ``explanation``), or None
        without a cause: ``extent`` ``full`` (the final model at the noise floor, or above it by
        less than :data:`nlsid.diagnose.verdict.REMAINS_DB` or not significantly), ``partial``
        (the status ``partly_explained``) or ``unknown`` (no noise floor to measure the rest by),
        the final model's ``gain_db`` and ``above_floor_db`` (the remainder)."""
        final = self.final_score()
        if final is None:
            return None
        if self.verdict.status == rules.PARTLY_EXPLAINED:
            extent = "partial"
        elif final.exact or math.isfinite(final.above_floor_db):
            extent = "full"
        else:
            extent = "unknown"
        return {"extent": extent, "gain_db": final.gain_db, "above_floor_db": final.above_floor_db}

    def yardstick_ahead(self, other: Score | None) -> bool:
        """The yardstick's validation error power below ``other``'s by more than the verdict's F*
        (:mod:`nlsid.diagnose.verdict`, rule 2): a black-box model does significantly better."""
        y = self.yardstick
        if other is None or y is None or not y.fitted:
            return False
        return rules.ratio(other.error_rms ** 2, y.score.error_rms ** 2) > self.verdict.threshold

    def _versus_yardstick(self, other: Score) -> str:
        """The named cause against the yardstick, in words for the headline ("" when not fitted)."""
        y = self.yardstick
        if y is None or not y.fitted:
            return ""
        db = 10 * math.log10(rules.ratio(other.error_rms ** 2, y.score.error_rms ** 2))
        if self.yardstick_ahead(other):
            h = self.hybrid
            both = (f"; the extended model with a black-box term for it reaches {h.score.error_rms:.3g} rms ({HYBRID})"
                    if h is not None and h.fitted else "")
            return (f"; a black-box state-space model reaches {y.score.error_rms:.3g} rms, {db:.1f} dB lower: an effect "
                    f"outside the library remains{both}")
        return f"; the named cause reaches the black-box level ({y.score.error_rms:.3g} rms, {db:+.1f} dB)"

    def models(self) -> list[dict]:
        """The model files the folder holds with their validation errors (``summary.json``
        ``models``): ``file``, ``kind`` (``extended``: the named causes, physical; ``black_box``:
        the yardstick, in ``black_box_model.yaml`` and, with the status ``outside_library``, in
        ``extended_model.yaml`` too; ``hybrid``: the extended model with a black-box term for what
        it leaves, in ``hybrid_model.yaml``, where fitted (:mod:`nlsid.diagnose.hybrid`);
        ``candidate``: the leading candidate, not significant), ``error_rms``, ``gain_db`` (over
        the user's model)."""
        out = []
        final = self.final_score()
        y = self.yardstick
        if final is not None:
            out.append({"file": EXTENDED, "kind": "extended", "error_rms": final.error_rms, "gain_db": final.gain_db})
        if y is not None and y.fitted:
            out.append({"file": BLACK_BOX, "kind": "black_box", "error_rms": y.score.error_rms,
                        "gain_db": y.score.gain_db})
            if self.verdict.status == rules.OUTSIDE_LIBRARY:
                out.append({"file": EXTENDED, "kind": "black_box", "error_rms": y.score.error_rms,
                            "gain_db": y.score.gain_db})
        if self.hybrid is not None and self.hybrid.fitted:
            out.append({"file": HYBRID, "kind": "hybrid", "error_rms": self.hybrid.score.error_rms,
                        "gain_db": self.hybrid.score.gain_db})
        if self.leading is not None:
            out.append({"file": CANDIDATE, "kind": "candidate", "error_rms": self.leading.score.error_rms,
                        "gain_db": self.leading.score.gain_db})
        return out

    def best_model(self) -> str | None:
        """The file of :meth:`models` with the lowest validation error (the physical extension on a
        tie) among those significantly better than the user's model with its nuisances (the
        verdict's F rule against the baseline); None when none is: the user's model is as good."""
        base = self.baseline.error_rms ** 2 if self.baseline is not None else math.inf
        better = [m for m in self.models() if rules.ratio(base, m["error_rms"] ** 2) > self.verdict.threshold]
        better.sort(key=lambda m: (m["error_rms"], m["file"] != EXTENDED))
        return better[0]["file"] if better else None

    def _yardstick_finding(self) -> str:
        y = self.yardstick
        if not y.fitted:
            return f"black-box yardstick {y.reason}"
        fit = y.fit
        gain = f"{y.score.gain_db:+.1f} dB" if math.isfinite(y.score.gain_db) else "an exact match"
        return (f"black-box yardstick (PNLSS, {fit.model.order} states, degrees {list(fit.model.state_degrees)}, "
                f"{fit.model.n_parameters} parameters; {y.early_stopping}): validation gain "
                f"{gain}, {versus_floor(y.score)}")

    def _hybrid_finding(self) -> str:
        h = self.hybrid
        model = h.fit.model
        gain = f"{h.score.gain_db:+.1f} dB" if math.isfinite(h.score.gain_db) else "an exact match"
        return (f"hybrid model (the extended model with a black-box PNLSS term of {model.order} states, "
                f"{model.n_parameters} parameters, for what it leaves; {h.early_stopping}): validation gain {gain}, "
                f"{versus_floor(h.score)}")

    def moved_nuisances(self) -> list[dict]:
        """The nuisances that moved by more than :data:`MOVED` standard errors between the user's
        model (fitted first) and the final extended model, or the leading candidate's
        (:func:`nlsid.diagnose.nuisances.moved`): fitted without the cause they took part of it."""
        other = self.final or self.leading
        if other is None or other.found is None:
            return []
        return nuisances.moved(self.nuisances, other.found, MOVED)

    def nuisance_unit(self, key: str) -> str | None:
        """The unit of the nuisance ``key`` (``model.<key>`` of the user's model,
        :mod:`nlsid.models.parameter_units`), None where it is unknown."""
        model = next((o.model for o in self.outcomes if o.model is not None), None)
        return None if model is None else unit_of(model, f"model.{key}", self.units)

    def _nuisance_findings(self) -> list[str]:
        other = self.final or self.leading
        out = [f"{m['key']} {m['before']:.4g} on the user's model but "
               f"{with_unit(format(m['after'], '.4g'), self.nuisance_unit(m['key']))} with {other.hypothesis.title} "
               f"({m['standard_errors']:.1f} standard errors apart): fitted without the effect it absorbed part of "
               "it, so the first value is not a fact about the converters" for m in self.moved_nuisances()]
        if self.verdict.status == rules.PARTLY_EXPLAINED and self.final.found is not None and self.final.found.values:
            keys = ", ".join(self.final.found.values)
            out.append(f"with error left above the floor, the extended model's nuisances ({keys}) may still absorb "
                       "part of the remaining effect: read them with that caution")
        return out

    def _chain_summary(self) -> list[dict]:
        """Each accepted cause: its values, the gain over the model before it, the distance to the floor."""
        return [{"cause": o.hypothesis.name, "title": o.hypothesis.title, "qualifier": o.qualifier(),
                 "values": o.estimate.values, "units": o.units(self.units), "mechanics_changed": o.mechanics_changed(),
                 "std": o.estimate.std, "error_rms": o.score.error_rms, "gain_db": o.score.gain_db,
                 "above_floor_db": o.score.above_floor_db} for o in self.chain]

    def _samples(self) -> dict:
        """The arbitrary estimation samples the hypotheses' fits used, of all (None without any)."""
        if self.budget is None or not self.budget.available:
            return {"estimation_samples_used": None, "estimation_samples": None}
        return self.budget.summary()

    def findings(self) -> list[str]:
        out = (list(self.notes) + self.nuisances.findings(self.nuisance_unit) + self._nuisance_findings()
               + self.evidence.findings())
        if self.budget is not None and self.budget.active:
            out.append(budget_note(self.budget, self.final is not None))
        if self.accuracy is not None:
            out.append(f"{'extended' if self.final else 'the'} model " + self.accuracy.note())
        if self.yardstick is not None:
            out.append(self._yardstick_finding())
        if self.hybrid is not None and self.hybrid.fitted:
            out.append(self._hybrid_finding())
        ranked = [o for o in self.outcomes if o.score is not None]
        for o in ranked[:3]:
            gain = f"{o.score.gain_db:+.1f} dB" if math.isfinite(o.score.gain_db) else "error zero within numerical precision"
            out.append(f"{o.hypothesis.title}: validation gain {gain}, {versus_floor(o.score)}")
        return out

    def arrays(self) -> dict:
        """The result arrays of :mod:`nlsid.io.diagnosis_file` (figures of the report)."""
        import numpy as np

        ev = self.evidence
        bla = [{"level": r["level"], "u_rms": r["u_rms"], "frequency": r["frequency_hz"], "G": r["G"],
                "G_model": r["G_model"], "radius": r["radius"], "gain_error_db": r["gain_error_db"],
                "phase_error_deg": r["phase_error_deg"], "outside": r["outside"].astype(np.int8)} for r in ev.bla]
        spectrum = []
        for level, (measured, model, lines) in ev.spectra.items():
            spectrum.append({"level": level, "kind": lines.kind, "in_band": lines.in_band.astype(np.int8),
                             "frequency": lines.frequency(np.arange(lines.kind.size)), "y_power": measured.y_power,
                             "model_power": model.y_power, "noise": measured.y_noise})
        first = next(res for res in ev.residuals if res.role == VALIDATION)
        validation = {"run_id": first.run_id, "fs": first.fs, "original_error": first.residual}
        if self.final is not None:
            validation["extended_error"] = self.final.residuals[0].residual
        return {"bla": bla, "spectrum": spectrum, "time": ev.time, "validation": validation}

    def extended_header(self) -> list[str]:
        """Header comment of the extended model: each cause, its values with standard errors, the gain."""
        lines = [f"Extended by nlsid diagnose: {', then '.join(o.hypothesis.title for o in self.chain)} added to "
                 f"{self.model_source}"]
        for outcome in self.chain:
            for name, value in outcome.estimate.values.items():
                text = f"{name} = {value:.6g} +- {outcome.estimate.std[name]:.2g}"
                lines.append(f"  {with_unit(text, outcome.unit(name, self.units))} (one standard error)")
        final = self.final_score()
        gain = f"{final.gain_db:+.1f} dB" if math.isfinite(final.gain_db) else "zero within numerical precision"
        lines.append(f"Validation error {final.error_rms:.4g} rms ({gain} against the original "
                     f"model, {versus_floor(final)})")
        if self.verdict.status == rules.PARTLY_EXPLAINED:
            lines.append(f"Partly explained: {final.above_floor_db:.1f} dB remain above the noise floor")
        return lines

    def candidate_header(self) -> list[str]:
        """Header comment of the leading candidate's model (:data:`CANDIDATE`): not a named cause."""
        o, lead = self.leading, self.leading_summary()
        lines = [f"Leading candidate of nlsid diagnose, NOT a named cause (its gain is not significant): "
                 f"{o.hypothesis.title} added to {self.model_source}"]
        lines += [f"  {with_unit(f'{name} = {value:.6g} +- {o.estimate.std[name]:.2g}', o.unit(name, self.units))} "
                  "(one standard error)" for name, value in o.estimate.values.items()]
        lines.append(f"Validation error {o.score.error_rms:.4g} rms ({lead['gain_db']:+.1f} dB against the model with "
                     f"its nuisances; {lead['needed_db']:+.1f} dB needed to name it)")
        return lines

    def summary(self) -> dict:
        split = {role: sorted(k for k, v in self.roles.items() if v == role) for role in (ESTIMATION, VALIDATION)}
        final = self.final_score()
        gain = None
        if final is not None:
            gain = {"original": self.original.summary(), "extended": final.summary(),
                    "gain_db": final.gain_db, "distortion_explained": final.distortion_explained,
                    "distortion_gain_db": final.distortion_gain_db,
                    "extended_above_floor_db": final.above_floor_db}
        return {
            "headline": self.headline(), "fit_on": self.signal, "findings": self.findings(), "model": self.model_source,
            "split": split, "evidence": self.evidence.summary(), "original": self.original.summary(),
            "verdict": self.verdict.summary(), "hypotheses": [o.summary(self.units) for o in self.outcomes],
            "nuisances": {**self.nuisances.summary(), "moved": self.moved_nuisances()},
            "explanation": self.explanation(), "leading": self.leading_summary(),
            "yardstick": self.yardstick.summary() if self.yardstick is not None else None,
            "hybrid": self.hybrid.summary() if self.hybrid is not None else None,
            "models": self.models(), "best_model": self.best_model(), "baseline": self.baseline.summary() if self.baseline else None,
            "chain": self._chain_summary(), "gain": gain, **self._samples(),
            "simulation_accuracy": None if self.accuracy is None else {**dataclasses.asdict(self.accuracy),
                                                                         "sufficient": self.accuracy.sufficient},
        }


NOISE_UNKNOWN = "the runs have no two periods to separate noise from the rest"
JUDGED_ON_U = "judged on u, the command the controller computes: errors, gains and the noise floor are u's"
CANDIDATE = "candidate_model.yaml"  # the leading candidate's model (Diagnosis.leading), as the stage writes it
EXTENDED = "extended_model.yaml"    # the named causes' model (or the black box, status outside_library)


def budget_note(budget: Budget, refined: bool) -> str:
    """The estimation budget in words (:func:`nlsid.diagnose.split.budgeted`): what was fitted on
    how many samples, and the precision given up."""
    factor = math.sqrt(budget.available / budget.used)
    final = ("; the final model refined once more on all of them, so its values have the whole "
             "record's precision" if refined else "")
    return (f"estimation budget: the hypotheses were fitted on {budget.used} of the {budget.available} "
            f"estimation samples (their standard errors about {factor:.2g} times those of a fit on all){final}; "
            "validated on every validation sample")


def versus_floor(score: Score) -> str:
    """Where a model's validation error lies against the noise floor, in words ("0.3 dB above ...")."""
    if score.noise_zero:
        return "an exact match (the noise floor is zero)" if score.exact else "the noise floor is zero (noise-free data)"
    x = score.above_floor_db
    if not math.isfinite(x):
        return "the noise floor is unknown (judged on the validation runs alone)"
    return f"{abs(x):.1f} dB {'above' if x >= 0 else 'below'} the noise floor"


def gain_text(score: Score) -> str:
    """The extended model's validation error against the original's, in words."""
    if math.isfinite(score.gain_db):
        return f"{score.gain_db:.1f} dB smaller"
    return "zero within numerical precision"
