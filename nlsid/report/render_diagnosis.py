"""The report page of a ``diagnosis/`` folder: the verdict, the evidence figures, then the numbers.

The verdict and the findings are those of ``summary.json`` (rules in :mod:`nlsid.diagnose.verdict`
and :mod:`nlsid.diagnose.evidence`), led by what an engineer decides on: the cause with its
parameters and their standard errors, and where the original model, the extended one and the
black-box yardstick stand against the noise floor; nuisances, numerical settings and each fit's
notes go to the collapsed details (:func:`split_findings`, :func:`optimiser_notes`); the figures come from ``results.h5``
(:mod:`nlsid.report.diagnosis_plots`); the tables rank the hypotheses by their validation error and
give the evidence per level and the gain, and, when the summary has a ``chain`` of causes, each of
its steps. A validation error's distance to the noise floor reads as in the verdict ("0.2 dB
below", :func:`floor_text`), and the distortion a hypothesis removes as a change in dB
(``distortion_gain_db``, :mod:`nlsid.diagnose.gain`).
"""

from __future__ import annotations

import math
from pathlib import Path

from nlsid.analysis.level_names import level_name
from nlsid.citations import BOOK, MOTION_STAGES
from nlsid.report.html import Figure, Page, Table, number
from nlsid.report.units import Units, units_of


def _level(value) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:g}"


def _level_of(rows: list[dict], units: Units) -> str:
    """The highest of the levels ``rows`` (rising, as ``bla`` numbers them), named as every stage
    names a level: ``level 2 (rms 4 N)`` (:mod:`nlsid.analysis.level_names`)."""
    return level_name(len(rows) - 1, rows[-1].get("u_rms"), units.known.get("u"))


def floor_text(score: dict | None) -> str:
    """Where a validation error lies against the noise floor, worded and rounded as the verdict
    (:func:`nlsid.diagnose.result.versus_floor`): ``0.2 dB below``, ``56.7 dB above``."""
    if not score:
        return "-"
    if score.get("noise_floor_zero"):
        return "exact match" if score.get("exact_match") else "zero floor (noise-free)"
    x = score.get("above_floor_db")
    if x is None or not math.isfinite(x):
        return "floor unknown"
    return f"{abs(x):.1f} dB {'above' if x >= 0 else 'below'}"


#: the opening words of the findings that are settings or side estimates rather than the answer
#: (:meth:`nlsid.diagnose.result.Diagnosis.findings`): they go to the page's collapsed details
DETAIL_OPENINGS = ("nuisances estimated first", "initial state fitted", "extended model simulated with",
                   "the model simulated with", "estimation budget", "black-box yardstick", "hybrid model")


def split_findings(findings: list[str]) -> tuple[list[str], list[str]]:
    """The findings an engineer decides on, and those for the details (:data:`DETAIL_OPENINGS`)."""
    lead = [line for line in findings if not line.startswith(DETAIL_OPENINGS)]
    return lead, [line for line in findings if line.startswith(DETAIL_OPENINGS)]


def _with_std(name: str, values: dict, std: dict, unit: str = "") -> str:
    text = f"{name} = {number(values[name], '.4g')}"
    if std.get(name) is not None:
        text += f" ± {number(std[name], '.2g')}"
    return text + (f" {unit}" if unit else "")


def _parameters(title: str, values: dict, std: dict, main: str | None, units: dict) -> str:
    """``Coulomb friction: fc = 100.2 ± 0.17 N; with it, the model's damping = 20 ± 0.0017 N s/m, ...``:
    each value with its unit (``units``, summary.json's; none where it is unknown)."""
    first = [_with_std(main, values, std, units.get(main) or "")] if main in values else []
    others = [_with_std(name, values, std, units.get(name) or "") for name in values if name != main]
    if not first:
        return f"{title}: {', '.join(others)}"
    return f"{title}: {first[0]}" + (f"; with it, the model's {', '.join(others)}" if others else "")


def cause_lines(summary: dict) -> list[str]:
    """The named cause(s) with every estimated parameter ± one standard error, the main parameter
    first, each with its unit: each step of the chain of causes, else the verdict's winner."""
    by_name = {h.get("name"): h for h in summary["hypotheses"]}
    steps = summary.get("chain") or []
    if not steps:
        winner = by_name.get(summary["verdict"].get("winner"))
        steps = [{"cause": winner["name"], "title": winner["title"], "values": winner["values"],
                  "std": winner.get("std") or {}, "units": winner.get("units") or {}}] \
            if winner and winner.get("values") else []
    out = []
    for i, step in enumerate(steps):
        h = by_name.get(step.get("cause"), {})
        title = step.get("title") or step.get("cause", "-")
        units = step.get("units") or h.get("units") or {h.get("main_parameter"): h.get("unit", "")}
        text = _parameters(title, step.get("values", {}), step.get("std") or {}, h.get("main_parameter"), units)
        out.append((f"cause {i + 1}, " if len(steps) > 1 else "cause: ") + text + " (± one standard error)")
    return out


def standing_lines(summary: dict) -> list[str]:
    """Where the models' validation errors stand against the noise floor: the original, the
    extended (named causes), the black-box yardstick, which shows how far a flexible model gets,
    and the hybrid (the extended model with a black-box term) where it was fitted."""
    original, gain = summary["original"], summary.get("gain")
    text = f"validation error against the noise floor: original model {floor_text(original)}"
    if gain:
        text += (f", extended model (named causes) {floor_text(gain['extended'])}, "
                 f"{number(gain['gain_db'], '.1f')} dB smaller than the original's")
    lines = [text]
    yardstick = summary.get("yardstick")
    if yardstick and yardstick.get("fitted"):
        lines.append(f"a black-box model fitted to the same data as a yardstick (PNLSS) reaches "
                     f"{floor_text(yardstick['validation'])} the floor: what a flexible model gets, beside "
                     "the named causes")
    elif yardstick:
        lines.append("no black-box yardstick to compare with (why: in the details below)")
    hybrid = summary.get("hybrid")
    if hybrid and hybrid.get("fitted"):
        lines.append(f"the extended model with a black-box term for what it leaves (hybrid_model.yaml) reaches "
                     f"{floor_text(hybrid['validation'])} the floor, its physical part as named")
    return lines


def optimiser_notes(summary: dict) -> list[str]:
    """Each fitted hypothesis' note of its estimate (start, identifiability, parameters the data
    determine poorly): for whoever checks the fit, not for the decision."""
    return [f"{h['title']}: {h['note']}" for h in summary["hypotheses"] if h.get("note") and h.get("values")]


def _figures(arrays: dict, units: Units, signal: str = "y") -> list[Figure]:
    from nlsid.report import diagnosis_plots as plots
    from nlsid.report.vector import figure

    out = []
    if arrays["bla"]:
        top = arrays["bla"][-1]
        out.append(figure(plots.model_vs_bla(top, units),
                          f"Model against the measured BLA at {_level_of(arrays['bla'], units)}. The band is the BLA's 95% "
                          f"confidence region ({BOOK}, Ex. 92); crosses mark lines where the model lies outside it.",
                          "model_vs_bla"))
    if arrays["spectrum"]:
        top = arrays["spectrum"][-1]
        same = len(arrays["bla"]) == len(arrays["spectrum"])  # one BLA and one spectrum per level
        top_name = _level_of(arrays["bla"], units) if same else f"level {_level(top['level'])}"
        out.append(figure(plots.spectrum(top, units),
                          f"Output spectrum at {top_name}. Measured power at the excited, odd and "
                          "even lines, the model's at the same lines, and the noise variance (as in "
                          f"{MOTION_STAGES}, Fig. 3).", "spectrum"))
    if len(arrays["bla"]) > 1:
        out.append(figure(plots.bla_vs_level(arrays["bla"], units),
                          "BLA versus excitation level. Measured (solid) and model (dashed) per level: a model without "
                          "the nonlinearity shows no change with level.", "bla_vs_level"))
    time = arrays["time"]
    if "residual" in time:
        states = (" Positions in m and velocities in m/s, the SI units of the mechanical templates."
                  if "position" in time or "velocity" in time else "")
        out.append(figure(plots.residual_vs_state(time, units, signal),
                          f"Residual against the model's internal signals. Mean steady-state period of run "
                          f"{time['run_id']}, the estimation run with the largest input, where the hypotheses are "
                          "estimated and a nonlinearity shows most: a jump at zero velocity is friction, a cubic "
                          f"trend in position a cubic spring.{states}", "residual_vs_state"))
    validation = arrays["validation"]
    if "original_error" in validation:
        out.append(figure(plots.before_after(validation, units, signal),
                          f"Simulation error before and after. Mean period of validation run {validation['run_id']}, "
                          "held out of every estimate (unlike the run of the residual figure), for the original "
                          "model and the extended one.", "before_after"))
    return out


def _hypothesis_table(summary: dict, units: Units) -> Table:
    rows = []
    for h in summary["hypotheses"]:
        v = h.get("validation")
        main = h["main_parameter"]
        value = h.get("values", {}).get(main)
        std = h.get("std", {}).get(main)
        unit = (h.get("units") or {}).get(main, h.get("unit")) or ""
        parameter = (f"{main} = {number(value, '.4g')} ± {number(std, '.2g')}" + (f" {unit}" if unit else "")
                     if value is not None else "-")
        rows.append([h["title"], parameter,
                     number(v and v["gain_db"], "+.1f"), floor_text(v),
                     number(v and v.get("distortion_gain_db"), "+.1f"),
                     h["reason"] or ("winner" if h.get("name") == summary["verdict"].get("winner") else "")])
    split, verdict = summary["split"], summary["verdict"]
    return Table("Hypotheses, ranked by validation error",
                 ["hypothesis", "main parameter", "validation gain dB", "validation error vs noise floor",
                  "distortion gain dB", "note"], rows, text=(0, 1, 5),
                 note=f"Estimated on {len(split['estimation'])} runs, validated on {len(split['validation'])} others. "
                      "Main parameter ± one standard error, from the sandwich estimator (Huber 1967, White 1980) "
                      "with the residual's spectrum, so correlated residuals (coloured noise, model error) "
                      "widen it; white residuals of a right model leave it small. Validation gain: the error's drop against the original model (> 0: smaller). Distortion "
                      "gain: the drop of the residual power at the odd and even detection lines of the validation "
                      "multisines (> 0: the hypothesis removes distortion, < 0: it adds some). A cause is named "
                      "when its error power is below the original's by more than the F threshold "
                      f"{verdict['f_threshold']:.3g} (alpha {verdict['alpha']:g}). Each fit's notes (start, "
                      "parameters the data determine poorly) are in the details under the verdict.")


def _level_table(evidence: dict, units: Units) -> Table:
    rows = [[str(index), number(lines["u_rms"]), f"{bla['outside_bounds']}/{bla['lines']}",
             number(bla["gain_error_max_db"], "+.1f"), number(bla["phase_error_max_deg"], "+.0f"),
             number(lines["excited"]["above_noise_db"], ".1f"), number(lines["odd"]["above_noise_db"], ".1f"),
             number(lines["even"]["above_noise_db"], ".1f")]
            for index, (lines, bla) in enumerate(zip(evidence["lines"], evidence["bla"]))]
    return Table("Residual per level", ["level", units.label("u rms", "u"),
                                        "model outside BLA bounds", "gain error dB", "phase error deg",
                                        "excited dB", "odd dB", "even dB"], rows,
                 note="Level: its index as bla numbers the recording's multisine levels (fit --level). "
                      "Gain and phase error: the largest of the measured BLA against the model's, 20 log10 "
                      "|G/G_model| (dB re 1, a ratio of like transfer functions) and its angle. Excited, odd, "
                      "even: residual power above the noise at the in-band lines of each class (dB re the noise "
                      "power).")


def _harmonic_table(evidence: dict, units: Units) -> Table | None:
    rows = [[number(row["frequency_hz"], "g"), _level(row["level"]), str(row["runs"]),
             number(row["fundamental"]["above_noise_db"], ".1f"), number(row["odd"]["above_noise_db"], ".1f"),
             number(row["even"]["above_noise_db"], ".1f"),
             " ".join(number(x, ".0f") for x in row["harmonic_above_noise_db"][1:])]
            for row in evidence.get("harmonics", [])]
    if not rows:
        return None
    return Table("Residual at the sine harmonics (HOSIDF)",
                 ["frequency Hz", units.label("amplitude", "u"), "runs", "fundamental dB", "odd dB", "even dB",
                  "harmonics 2, 3, ... dB"], rows,
                 note="Residual power above the noise (dB re the noise power) at the harmonics of each sine: what "
                      "the model misses of each HOSIDF (odd: odd nonlinearity, even: even).")


def _error_table(summary: dict, units: Units) -> Table:
    original, gain = summary["original"], summary.get("gain")
    rows = [["original model", number(original["error_rms"], ".4g"), number(original["error_db"], ".1f"),
             floor_text(original)]]
    best = summary.get("best_model")
    if gain:
        ext = gain["extended"]
        label = "extended model (named causes)" + (", best" if best == "extended_model.yaml" else "")
        rows.append([label, number(ext["error_rms"], ".4g"), number(ext["error_db"], ".1f"), floor_text(ext)])
    yardstick = summary.get("yardstick") or {}
    if yardstick.get("fitted"):
        val = yardstick["validation"]
        label = "black-box yardstick (PNLSS)" + (", best" if best == "black_box_model.yaml" else "")
        rows.append([label, number(val["error_rms"], ".4g"), number(val["error_db"], ".1f"), floor_text(val)])
    hybrid = summary.get("hybrid") or {}
    if hybrid.get("fitted"):
        val = hybrid["validation"]
        label = "hybrid (extended model + black-box term)" + (", best" if best == "hybrid_model.yaml" else "")
        rows.append([label, number(val["error_rms"], ".4g"), number(val["error_db"], ".1f"), floor_text(val)])
    floor = gain["extended"] if gain else original
    rows.append(["noise floor", number(floor["noise_rms"], ".4g"), number(floor["noise_db"], ".1f"), "the floor"])
    signal = summary.get("fit_on", "y")  # the judged signal (diagnose --fit-on)
    return Table("Validation error", ["model", units.label(_of("rms", signal), signal),
                                      f"level ({units.level_db(signal)})", "vs noise floor"], rows,
                 note="Mean steady-state period of the validation runs, without its mean value. Each model's "
                      "floor is the noise in its own residual (period-to-period variance over P): the error "
                      "the true model would show. The floor row is the best model's. The black-box yardstick is "
                      "fitted to the same estimation data: what a flexible model reaches, beside what the named "
                      "causes reach; \"best\" marks summary.json's best_model.")


def _values(step: dict) -> str:
    std, units = step.get("std", {}), step.get("units") or {}
    return "; ".join(f"{name} = {number(value, '.4g')}" + (f" ± {number(std[name], '.2g')}" if name in std else "")
                     + (f" {units[name]}" if units.get(name) else "")
                     for name, value in step.get("values", {}).items()) or "-"


def _of(quantity: str, signal: str) -> str:
    """A column's quantity, naming the judged signal where it is not the output y (diagnose --fit-on u)."""
    return quantity if signal == "y" else f"{quantity} of {signal}"


def _chain_table(chain: list[dict], units: Units, signal: str = "y") -> Table:
    rows = [[str(i + 1), step.get("title") or step.get("cause", "-"), _values(step),
             number(step.get("error_rms"), ".4g"), number(step.get("gain_db"), "+.1f"), floor_text(step)]
            for i, step in enumerate(chain)]
    return Table("Chain of causes", ["step", "cause", "values",
                                     units.label(_of("validation error rms", signal), signal),
                                     "validation gain dB", "validation error vs noise floor"], rows, text=(1, 2),
                 note="Each step adds one cause to the model of the step before and diagnoses again; the gain is "
                      "against that model, the error and its distance to the floor those of the model after the "
                      "step.")


def _tables(summary: dict, units: Units) -> list[Table]:
    tables = [_chain_table(summary["chain"], units, summary.get("fit_on", "y"))] if summary.get("chain") else []
    tables += [_hypothesis_table(summary, units), _level_table(summary["evidence"], units)]
    harmonics = _harmonic_table(summary["evidence"], units)
    return tables + ([harmonics] if harmonics else []) + [_error_table(summary, units)]


def render_diagnosis(path: Path) -> Page:
    """The report page of a diagnosis folder."""
    from nlsid.io.diagnosis_file import read_diagnosis

    summary, arrays = read_diagnosis(path)
    units = units_of(summary.get("units"))
    keys = ("verdict", "original", "gain", "evidence", "split", "units", "chain", "explanation", "yardstick",
            "best_model", "fit_on")
    lead, details = split_findings(list(summary["findings"]))
    return Page(kind="Model diagnosis", title=f"Diagnosis of {Path(summary['model']).name}", source=str(path),
                headline=summary["headline"], findings=cause_lines(summary) + standing_lines(summary) + lead,
                details=details + optimiser_notes(summary),
                details_title="Details: nuisances, numerical settings and the fits' notes",
                figures=_figures(arrays, units.for_figures(), summary.get("fit_on", "y")),
                note=units.missing_note("u", "y"),
                tables=_tables(summary, units), provenance=summary.get("provenance", {}),
                numbers={k: summary[k] for k in keys if k in summary})
