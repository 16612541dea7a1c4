"""The report page of a ``diagnosis/`` folder: the verdict, the evidence figures, then the numbers.

The verdict and the findings are those of ``summary.json`` (rules in :mod:`nlsid.diagnose.verdict`
and :mod:`nlsid.diagnose.evidence`); the figures come from ``results.h5``
(:mod:`nlsid.report.diagnosis_plots`); the tables rank the hypotheses by their validation error and
give the evidence per level and the gain.
"""

from __future__ import annotations

import math
from pathlib import Path

from nlsid.report.html import Figure, Page, Table, number


def _level(value) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:g}"


def _figures(arrays: dict) -> list[Figure]:
    from nlsid.report import diagnosis_plots as plots

    out = []
    if arrays["bla"]:
        top = arrays["bla"][-1]
        out.append(Figure(plots.model_vs_bla(top),
                          f"Model against the measured BLA at level {_level(top['level'])}. The band is the BLA's 95% "
                          "confidence region (book Ex. 92); crosses mark lines where the model lies outside it.",
                          "model_vs_bla"))
    if arrays["spectrum"]:
        top = arrays["spectrum"][-1]
        out.append(Figure(plots.spectrum(top),
                          f"Output spectrum at level {_level(top['level'])}. Measured power at the excited, odd and even "
                          "lines, the model's at the same lines, and the noise variance (seed 000 Fig. 3).",
                          "spectrum"))
    if len(arrays["bla"]) > 1:
        out.append(Figure(plots.bla_vs_level(arrays["bla"]),
                          "BLA versus excitation level. Measured (solid) and model (dashed) per level: a model without "
                          "the nonlinearity shows no change with level.", "bla_vs_level"))
    if "residual" in arrays["time"]:
        out.append(Figure(plots.residual_vs_state(arrays["time"]),
                          f"Residual against the model's internal signals. Mean period of run {arrays['time']['run_id']}: "
                          "a jump at zero velocity is friction, a cubic trend in position a cubic spring.",
                          "residual_vs_state"))
    if "original_error" in arrays["validation"]:
        out.append(Figure(plots.before_after(arrays["validation"]),
                          f"Simulation error before and after. Validation run {arrays['validation']['run_id']}, "
                          "mean period: the original model and the extended one.", "before_after"))
    return out


def _tables(summary: dict) -> list[Table]:
    rows = []
    for h in summary["hypotheses"]:
        v = h.get("validation")
        main = h["main_parameter"]
        value = h.get("values", {}).get(main)
        std = h.get("std", {}).get(main)
        rows.append([h["title"], f"{main} = {number(value, '.4g')} ± {number(std, '.2g')}" if value is not None else "-",
                     number(v and v["gain_db"], "+.1f"), number(v and v["above_floor_db"], ".1f"),
                     number(v and v["distortion_explained"], ".0%"), h["reason"] or h.get("note", "")])
    ev = summary["evidence"]
    level_rows = []
    for lines, bla in zip(ev["lines"], ev["bla"]):
        level_rows.append([_level(lines["level"]), number(lines["u_rms"]), f"{bla['outside_bounds']}/{bla['lines']}",
                           number(bla["gain_error_max_db"], "+.1f"), number(bla["phase_error_max_deg"], "+.0f"),
                           number(lines["excited"]["above_noise_db"], ".1f"), number(lines["odd"]["above_noise_db"], ".1f"),
                           number(lines["even"]["above_noise_db"], ".1f")])
    split = summary["split"]
    tables = [
        Table("Hypotheses, ranked by validation error", ["hypothesis", "main parameter", "gain dB", "above floor dB",
                                                          "distortion explained", "note"], rows,
              note=f"Estimated on {len(split['estimation'])} runs, validated on {len(split['validation'])} others. "
                   f"A cause is named when its error power is below the original's by more than the F threshold "
                   f"{summary['verdict']['f_threshold']:.3g} (alpha {summary['verdict']['alpha']:g})."),
        Table("Residual per level", ["level", "u rms", "model outside BLA bounds", "gain error dB", "phase error deg",
                                     "excited dB", "odd dB", "even dB"], level_rows,
              note="Residual power above the noise at the in-band excited, odd and even lines (dB)."),
    ]
    harmonic_rows = [[number(row["frequency_hz"], "g"), _level(row["level"]), str(row["runs"]),
                      number(row["fundamental"]["above_noise_db"], ".1f"), number(row["odd"]["above_noise_db"], ".1f"),
                      number(row["even"]["above_noise_db"], ".1f"),
                      " ".join(number(x, ".0f") for x in row["harmonic_above_noise_db"][1:])]
                     for row in ev.get("harmonics", [])]
    if harmonic_rows:
        tables.append(Table("Residual at the sine harmonics (HOSIDF)", ["frequency Hz", "level", "runs", "fundamental dB",
                                                                       "odd dB", "even dB", "harmonics 2, 3, ... dB"],
                            harmonic_rows, note="Residual power above the noise at the harmonics of each sine: what "
                                                "the model misses of each HOSIDF (odd: odd nonlinearity, even: even)."))
    original = summary["original"]
    gain = summary.get("gain")
    gain_rows = [["original model", number(original["error_rms"], ".4g"), number(original["error_db"], ".1f"),
                  number(original["above_floor_db"], ".1f")]]
    if gain:
        ext = gain["extended"]
        gain_rows.append(["extended model", number(ext["error_rms"], ".4g"), number(ext["error_db"], ".1f"),
                          number(ext["above_floor_db"], ".1f")])
    floor = gain["extended"] if gain else original
    gain_rows.append(["noise floor", number(floor["noise_rms"], ".4g"), number(floor["noise_db"], ".1f"), "0.0"])
    tables.append(Table("Validation error", ["model", "rms", "dB", "above floor dB"], gain_rows,
                        note="Mean steady-state period of the validation runs, without its mean value. Each model's "
                             "floor is the noise in its own residual (period-to-period variance over P): the error "
                             "the true model would show. The floor row is the best model's."))
    return tables


def render_diagnosis(path: Path) -> Page:
    """The report page of a diagnosis folder."""
    from nlsid.io.diagnosis_file import read_diagnosis

    summary, arrays = read_diagnosis(path)
    return Page(kind="Model diagnosis", title=f"Diagnosis of {Path(summary['model']).name}", source=str(path),
                headline=summary["headline"], findings=list(summary["findings"]), figures=_figures(arrays),
                tables=_tables(summary), provenance=summary.get("provenance", {}),
                numbers={k: summary[k] for k in ("verdict", "original", "gain", "evidence", "split")})
