"""The report page of a ``bla.h5`` file: the distortion verdict, the BLA figures and the level tables.

Verdict (computed from the numbers stored in the file, ``LevelResult.summary`` and
``across_levels``; see ``docs/drafts/bla.md``), at the highest excitation level, where the
distortion is largest:

- Output spectrum at the in-band detection lines (seed 000 Fig. 3 and Eq. 7; book Section 6.2):
  ``odd_above_noise_db`` and ``even_above_noise_db`` compare the band-mean power at the odd and at
  the even detection lines with the band-mean noise variance of the P-averaged output spectrum,
  on the same scale. A class of distortion is *detected* when it is more than
  :data:`~nlsid.report.detection.DETECTED_DB` = 3 dB above the noise (justified in
  :mod:`nlsid.report.detection`).
- On an odd grid the odd and even detection lines separate odd from even distortion (book Section
  6.1.2, Ex. 89.c): the headline gives ``odd_above_even_db``. On a full grid both classes of
  detection line carry odd and even contributions, so only their maximum above the noise is given.
- Without detection lines the robust method still separates the nonlinear variance of the BLA
  from the noise variance (book (6-7), (6-21)): ``nl_var_db - noise_var_db`` plays the same role.
- Across levels (seed 000 Figs. 4-5): ``bla_change_max_db``, the largest change of ``|G_BLA|``
  (20 log10 of the ratio to the lowest level) over the excited lines, for levels that excite the
  same lines.
- Without a noise level the rules above have nothing to compare with (the summary's
  ``noise_floor``): with one period per realization (``unknown``, P = 1) the page says that the
  noise is unknown and gives what the file has (odd against even detection lines; the confidence
  bounds then hold noise and distortion together, from the total variance over M realizations);
  on noise-free data (``zero``) a class of distortion is present when its band mean stands above
  numerical precision, :data:`~nlsid.analysis.precision.PRECISION_DB` = -180 dB relative to the
  output at the excited lines (or to ``|G_BLA|^2`` for the robust nonlinear variance), and its
  level is given relative to the output, never to the noise. Every class of non-excited harmonic
  lines is read, beyond the band too: "no distortion" is said only when none stands above
  precision. With P = 1 the detection lines' levels below the output (upper bounds of the
  distortion) and the line-class comparison of :mod:`nlsid.analysis.distortion_class` are given.
- Without detection lines and with a noise level, a nonlinear variance is "not measurable" only
  for M = 1 or P = 1 (:func:`~nlsid.analysis.bla.nonlinear_variance_missing`); with M >= 2 and
  P >= 2 a band mean below zero means no distortion above the noise.

The frequency response matrix levels of runs with several inputs or outputs (``frm_levels``,
``frm_lpm_levels``) are drawn by :mod:`nlsid.report.render_frm`: on a page of their own when the file holds nothing else,
else after the levels of this page.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nlsid.analysis.bla import RobustBLA, nonlinear_variance_missing
from nlsid.analysis.confidence import Bounds
from nlsid.analysis.fast_bla import FastBLA
from nlsid.analysis.level_names import level_name
from nlsid.analysis.levels import LevelResult
from nlsid.analysis.lines import EVEN, ODD, classify_lines
from nlsid.analysis.output_spectrum import OutputSpectrum
from nlsid.analysis.precision import PRECISION_DB
from nlsid.errors import InputError
from nlsid.citations import BOOK, MOTION_STAGES
from nlsid.report.detection import DETECTED_DB
from nlsid.report.html import Figure, Page, Table, number
from nlsid.report.units import Units, units_of


def _finite(value) -> bool:
    return value is not None and math.isfinite(value)


def _bounds(group: dict) -> Bounds:
    return Bounds(*(group[name] for name in ("radius", "mag_lo", "mag_hi", "phase_lo", "phase_hi")))


def _level(stored: dict, where: str) -> LevelResult:
    """A :class:`LevelResult` rebuilt from one ``/levels/level_NN`` group (for the figures).

    The file keeps everything the figures and the summary use; the per-run bias checks of the fast
    method are not stored (their outcome is in the level's warnings), so ``bias_checks`` is empty.
    """
    attrs = stored["attrs"]
    lines = classify_lines(int(attrs["period"]), float(attrs["fs"]), stored["excited_bins"])
    if not np.array_equal(lines.kind, stored["lines"]["kind"]):
        raise InputError(f"{where}/lines/kind", "does not match the line classes of excited_bins and period")
    robust, fast, per_line = stored["robust"], stored["fast"], stored["lines"]
    M, P = int(attrs["n_realizations"]), int(attrs["n_periods"])
    rebuilt_robust = RobustBLA(
        method=str(attrs["method"]), bins=lines.excited, n_realizations=M, n_periods=P, G=robust["G"],
        var_total=robust["var_total"], var_noise=robust["var_noise"], var_nl=robust["var_nl"],
        var_noise_period=robust["var_noise_period"], var_ys=robust["var_ys"], bounds=_bounds(robust),
        var_input_nl=robust.get("var_input_nl"))
    rebuilt_fast = None
    if fast is not None:
        rebuilt_fast = FastBLA(
            n_runs=M, G=fast["G"], var_noise=fast["var_noise"], var_total=fast["var_total"], var_nl=fast["var_nl"],
            var_nl_even=fast.get("var_nl_even"), Yc_power=fast["yc_power"], Yc_noise=fast["yc_noise"],
            fraction_significant_y=fast["fraction_significant_y"],
            fraction_significant_u=fast["fraction_significant_u"], bias_checks={}, bounds=_bounds(fast))
    level = float(attrs["level"])
    return LevelResult(
        level=None if math.isnan(level) else level, run_ids=list(attrs["run_ids"]), lines=lines, n_periods=P,
        u_rms=float(attrs["u_rms"]), robust=rebuilt_robust, fast=rebuilt_fast,
        spectrum=OutputSpectrum(per_line["u_power"], per_line["u_noise"], per_line["y_power"], per_line["y_noise"]),
        warnings=list(attrs["warnings"]))


def _variance_text(value, summary: dict, nonlinear: bool = False) -> str:
    """A variance level (dB) for the page; a zero or unknown noise is said, never shown as a number."""
    floor = noise_floor(summary)
    if _finite(value) and floor == "zero" and value < PRECISION_DB:
        return "zero within numerical precision"
    if _finite(value):
        return f"{value:.1f} dB"
    if floor == "unknown":
        return "unknown (P = 1: noise and distortion not separated)"
    if floor == "zero" and not nonlinear:
        return "zero (noise-free data)"
    return "-"


def noise_floor(summary: dict) -> str:
    """The level's ``noise_floor`` (``estimated``, ``zero``, ``unknown``); files written before the key
    existed: ``unknown`` with one period per realization, else ``estimated``."""
    return summary.get("noise_floor") or ("unknown" if summary["periods"] < 2 else "estimated")


def _above_precision(spectrum: dict) -> dict[str, float]:
    """How far (dB) below the output at the excited lines each class of non-excited harmonic lines
    stands, for the classes above numerical precision: ``odd`` and ``even`` in band, ``out_of_band``
    (the stronger of the odd and even harmonics beyond the band). A class whose lines hold exactly
    zero power has a null level: no distortion of that class."""
    excited = spectrum["excited_db"]
    levels = {"odd": spectrum.get("odd_db"), "even": spectrum.get("even_db"),
              "out_of_band": max((v for v in (spectrum.get("odd_out_of_band_db"), spectrum.get("even_out_of_band_db"))
                                  if _finite(v)), default=None)}
    if not _finite(excited):
        return {}
    return {name: excited - level for name, level in levels.items() if _finite(level) and level - excited > PRECISION_DB}


def _noise_free_verdict(summary: dict, detection: bool) -> tuple[str, list[str]]:
    """A zero noise floor: distortion is whatever stands above numerical precision (PRECISION_DB
    relative to the output at the excited lines, or to |G_BLA|^2 for the robust variances). The
    non-excited harmonic lines are read in every case (in band and beyond it): "no distortion" is
    said only when none of them and no measured nonlinear variance stands above precision."""
    spectrum = summary["spectrum"]
    zero = "the noise floor is zero (noise-free data)"
    findings = [f"noise-free data: every level above numerical precision ({PRECISION_DB:.0f} dB of the output) "
                "is distortion, and no level has a ratio to the noise"]
    below = _above_precision(spectrum)
    text = {name: f"{gap:.0f} dB below the output at the excited lines" for name, gap in below.items()}
    nl = summary["nl_var_db"]
    nl_seen = _finite(nl) and nl > PRECISION_DB
    outside = (f"Nonlinear distortion at the harmonics beyond the excited band, {text['out_of_band']}; {zero}"
               if "out_of_band" in below else "")
    if not detection:
        findings.append("no detection lines: odd and even distortion cannot be told apart (use a random-grid "
                        f"multisine, {BOOK}, Section 6.1.2)")
        if nl_seen:
            return f"Nonlinear distortion: its variance is {nl:.0f} dB relative to |G_BLA|²; {zero}", findings
        if outside:
            return outside, findings
        if not _finite(nl):
            missing = nonlinear_variance_missing(int(summary["realizations"]), int(summary["periods"]))
            findings.append(f"the nonlinear variance at the excited lines is not measured: the robust method {missing}")
            return ("No nonlinear distortion beyond numerical precision at the non-excited harmonic lines; at the "
                    f"excited lines it is not measured (M = {summary['realizations']}); {zero}"), findings
        return f"No nonlinear distortion beyond numerical precision; {zero}", findings
    if not summary["odd_grid"]:
        findings.append("full grid: the detection lines carry odd and even distortion together")
        inside = [below[name] for name in ("odd", "even") if name in below]
        if inside:
            return f"Nonlinear distortion at the detection lines, {min(inside):.0f} dB below the output; {zero}", findings
    elif "odd" in below and "even" in below:
        return f"Odd and even nonlinear distortion: odd {text['odd']}, even {text['even']}; {zero}", findings
    elif "odd" in below:
        return f"Odd nonlinear distortion {text['odd']}, no even distortion beyond numerical precision; {zero}", findings
    elif "even" in below:
        return f"Even nonlinear distortion {text['even']}, no odd distortion beyond numerical precision; {zero}", findings
    if outside:
        return outside, findings
    if nl_seen:
        return f"Nonlinear distortion: its variance is {nl:.0f} dB relative to |G_BLA|²; {zero}", findings
    return f"No nonlinear distortion beyond numerical precision; {zero}", findings


def _noise_unknown_verdict(summary: dict) -> tuple[str, list[str]]:
    """One period per realization: no noise estimate, so nothing is compared with the noise. The
    non-excited lines still hold the distortion: the odd against the even detection lines, the level
    of the strongest class below the output (noise plus distortion: an upper bound of the distortion),
    and the classes compared with each other (:mod:`nlsid.analysis.distortion_class`)."""
    spectrum = summary["spectrum"]
    head = "Noise level unknown (one period per realization, P = 1): distortion cannot be compared with the noise"
    findings = ["P = 1: the noise variance cannot be estimated, so noise and nonlinear distortion are not "
                f"separated ({BOOK}, Section 6.1.1)"]
    if summary["realizations"] >= 2:
        findings.append(f"the BLA's confidence bounds come from the total variance over the {summary['realizations']} "
                        "realizations (noise and nonlinear distortion together)")
    else:
        findings.append("one realization and one period: the BLA has no confidence bounds")
    excited = spectrum["excited_db"]
    levels = {name: spectrum.get(f"{name}_db") for name in ("odd", "even")}
    seen = {name: excited - v for name, v in levels.items() if _finite(v) and _finite(excited)}
    if seen:
        findings.append("detection lines (noise plus distortion, so upper bounds of the distortion): "
                        + ", ".join(f"{name} {gap:.0f} dB below the output at the excited lines"
                                    for name, gap in seen.items()))
    classified = summary.get("distortion_class")
    if classified:
        findings.append(f"line classes compared with each other: {classified['verdict']}")
    gap = spectrum["odd_above_even_db"]
    if summary["odd_grid"] and _finite(gap):
        lead = "odd" if gap >= 0 else "even"
        head = f"{head}; the {lead} detection lines are {abs(gap):.0f} dB above the {'even' if gap >= 0 else 'odd'}"
    elif seen:
        head = f"{head}; the detection lines stand {min(seen.values()):.0f} dB below the output (noise plus distortion)"
    if classified and not classified["verdict"].startswith(("no distortion", "no non-excited")):
        head = f"{head}; {classified['verdict'].split(':')[0]}"
    return head, findings


def distortion_verdict(summary: dict, detection: bool | None = None) -> tuple[str, list[str]]:
    """Headline and findings on the nonlinear distortion of one level (rules in the module docstring).

    ``detection``: whether the level has in-band detection lines (None: judged from the summary's
    levels, which are null both without such lines and, on noise-free data, where they hold no power)."""
    floor = noise_floor(summary)
    if floor == "zero":
        spectrum = summary["spectrum"]
        if detection is None:
            detection = _finite(spectrum["odd_db"]) or _finite(spectrum["even_db"])
        return _noise_free_verdict(summary, detection)
    if floor == "unknown":
        return _noise_unknown_verdict(summary)
    spectrum = summary["spectrum"]
    odd, even = spectrum["odd_above_noise_db"], spectrum["even_above_noise_db"]
    findings = []
    if not (_finite(odd) or _finite(even)):
        nl, noise = summary["nl_var_db"], summary["noise_var_db"]
        excess = nl - noise if _finite(nl) and _finite(noise) else float("nan")
        findings.append("no detection lines: odd and even distortion cannot be told apart (use a random-grid "
                        f"multisine, {BOOK}, Section 6.1.2)")
        if not _finite(excess):
            missing = nonlinear_variance_missing(int(summary["realizations"]), int(summary["periods"]))
            if missing:
                return f"Nonlinear distortion not measurable: the robust method {missing}", findings
            if _finite(noise):
                # a non-positive band mean of M (var_total - var_noise): the realizations spread no
                # more than the noise explains (the estimate is unbiased, so it falls below zero by chance)
                return ("No nonlinear distortion detected: the BLA varies over the realizations no more than its "
                        "noise explains (nonlinear variance estimate below zero)"), findings
            return "Nonlinear distortion not measurable: no noise level to compare it with", findings
        if excess > DETECTED_DB:
            return f"Nonlinear distortion {excess:.0f} dB above the noise (robust-method variances)", findings
        return f"No nonlinear distortion detected: its variance is within {DETECTED_DB:g} dB of the noise", findings
    if not summary["odd_grid"]:
        top = float(np.nanmax([odd, even]))
        findings.append("full grid: the detection lines carry odd and even distortion together")
        if top > DETECTED_DB:
            return f"Nonlinear distortion {top:.0f} dB above the noise at the detection lines", findings
        return f"No nonlinear distortion detected: detection lines within {DETECTED_DB:g} dB of the noise", findings
    odd_seen, even_seen = _finite(odd) and odd > DETECTED_DB, _finite(even) and even > DETECTED_DB
    gap = spectrum["odd_above_even_db"]
    if odd_seen and even_seen:
        lead = "odd" if gap >= 0 else "even"
        return (f"Odd and even nonlinear distortion: {lead} dominates by {abs(gap):.0f} dB; odd {odd:.0f} dB, "
                f"even {even:.0f} dB above the noise"), findings
    if odd_seen:
        return f"Odd nonlinear distortion {gap:.0f} dB above even, {odd:.0f} dB above the noise", findings
    if even_seen:
        return f"Even nonlinear distortion {-gap:.0f} dB above odd, {even:.0f} dB above the noise", findings
    return f"No nonlinear distortion detected: odd and even lines within {DETECTED_DB:g} dB of the noise", findings


def level_verdict(across: dict, units: Units) -> str:
    """The change of |G_BLA| over the levels (seed 000 Figs. 4-5), or why it is not available."""
    rows = across["levels"]
    if len(rows) < 2:
        return "one level: the dependence of the BLA on the level was not measured"
    changes = [row["bla_change_max_db"] for row in rows[1:] if _finite(row.get("bla_change_max_db"))]
    if not changes:
        return "the levels excite different lines: their BLAs are compared in the figure only"
    largest = max(changes, key=abs)
    return (f"BLA changes by up to {largest:+.1f} dB over {len(rows)} levels "
            f"(u rms {rows[0]['u_rms']:.3g} to {units.value(format(rows[-1]['u_rms'], '.3g'), 'u')})")


def _name(summary: dict, index: int, units: Units) -> str:
    """``level 1 (rms 2 N)``: the index ``fit --level`` takes and the input's rms (:mod:`nlsid.analysis.level_names`)."""
    return level_name(index, summary.get("u_rms"), units.known.get("u"))


def _tables(summaries: list[dict], across: dict, probability: float, units: Units) -> list[Table]:
    change = {i: row for i, row in enumerate(across["levels"])}
    bla_rows, spectrum_rows = [], []
    for i, s in enumerate(summaries):
        sp = s["spectrum"]
        unknown = {"zero": "zero", "unknown": "unknown (P = 1)"}.get(noise_floor(s), "-")
        bla_rows.append([str(i), number(s["u_rms"]), f"{s['realizations']} x {s['periods']}", s["method"],
                         str(s["excited_lines"]), number(s["bla_db"], ".1f"),
                         number(s["nl_var_db"], ".1f") if _finite(s["nl_var_db"]) or noise_floor(s) != "unknown" else unknown,
                         number(s["noise_var_db"], ".1f") if _finite(s["noise_var_db"]) else unknown, number(change[i].get("bla_change_mean_db"), "+.2f"),
                         number(change[i].get("bla_change_max_db"), "+.2f")])
        spectrum_rows.append([_name(s, i, units), number(sp["excited_db"], ".1f"), number(sp["odd_db"], ".1f"),
                              number(sp["even_db"], ".1f"), number(sp["nonharmonic_db"], ".1f"),
                              number(sp["noise_db"], ".1f") if _finite(sp["noise_db"])
                              else {"zero": "zero", "unknown": "unknown (P = 1)"}.get(noise_floor(s), "-"),
                              number(sp["odd_above_even_db"], ".1f"),
                              number(sp["odd_above_noise_db"], ".1f"), number(sp["even_above_noise_db"], ".1f"),
                              number(sp["excited_above_odd_db"], ".1f")])
    return [
        Table("BLA per level (robust method)",
              ["level", units.label("u rms", "u"), "M x P", "method", "lines",
               f"|G|² ({units.ratio_db('y', 'u')})", "NL var (dB re |G|²)", "noise var (dB re |G|²)",
               "ΔG mean dB", "ΔG max dB"], bla_rows,
              note=(f"|G|²: band mean of |G_BLA|². NL var: var(G_S) of one realization ({BOOK}, Eq. 6-7); "
                    f"noise var: var(N_G) of one period (Eq. 6-21); both relative to |G|². ΔG: 20 log10 "
                    f"|G/G_first level| (dB re 1, a ratio of like transfer functions), mean and largest over the "
                    f"lines. Level: the index fit --level takes. Confidence bounds in the figures: "
                    f"{probability:.0%}.")),
        Table(f"Output spectrum per level: band means in band ({units.power_db('y')})",
              ["level", "excited", "odd", "even", "non-harm.", "noise", "odd−even dB", "odd−noise dB",
               "even−noise dB", "excited−odd dB"], spectrum_rows,
              note=f"Powers of the P-averaged output spectrum, rms over realizations ({MOTION_STAGES}, Eq. 7); "
                   f"noise: variance of the P-mean on the same scale ({BOOK}, Eq. 6-12). The differences are "
                   "ratios of powers of y (dB re 1 y²/y²)."),
    ]


_CAPTIONS = {
    "bla_vs_level": ("BLA versus excitation level. Top: |G_BLA| of every level; bottom: band-mean nonlinear "
                     f"and noise variances relative to |G_BLA|² versus the rms input (as in {MOTION_STAGES}, "
                     "Figs. 4-5)."),
    "spectrum": ("Output spectrum at {name}. Excited lines, odd and even detection lines, non-harmonic lines "
                 f"and the noise variance of the averaged spectrum (as in {MOTION_STAGES}, Fig. 3)."),
    "bla": ("BLA at {name} with its {p:.0%} confidence bounds. The standard deviations of the estimate due to "
            f"the nonlinear distortion and to the noise are shown with it (as in {MOTION_STAGES}, Fig. 5; "
            f"bounds as in {BOOK}, Ex. 92)."),
}


def _figures(levels: list[LevelResult], summaries: list[dict], probability: float, units: Units) -> list[Figure]:
    from nlsid.report.bla_plots import bla_figure, levels_figure, spectrum_figure
    from nlsid.report.vector import figure

    drawn = {"spectrum": spectrum_figure, "bla": bla_figure}
    order = [len(levels) - 1, *range(len(levels) - 1)]  # the highest level first
    out = []
    if len(levels) > 1:
        out.append(figure(levels_figure(levels, units.for_figures()), _CAPTIONS["bla_vs_level"], "bla_vs_level"))
    for index in order:
        name = _name(summaries[index], index, units)
        for key in ("spectrum", "bla"):
            caption = _CAPTIONS[key].format(name=name, p=probability)
            caption += {"unknown": " The noise is unknown at this level (one period per realization, P = 1): no "
                                   "noise level is drawn, and the bounds hold noise and distortion together.",
                        "zero": " The data are noise-free: the noise floor is zero (not drawn)."}.get(
                            noise_floor(summaries[index]), "")
            out.append(figure(drawn[key](levels[index], units.for_figures(), index), caption,
                              f"{key}_level_{index:02d}"))
    return out


def render_bla(path: Path) -> Page:
    """The report page of a ``bla.h5`` file (module docstring for the verdict)."""
    from nlsid.io.bla_file import read_bla

    data = read_bla(path)
    if not data["levels"] and not data["lpm_levels"]:
        if data["frm_levels"] or data.get("frm_lpm_levels"):
            from nlsid.report.render_frm import render_frm

            return render_frm(path, data)
        raise InputError(f"{path}:/levels", "holds no level")
    if not data["levels"]:
        return _with_frm(_lpm_page(path, data), data)
    levels = [_level(stored, f"{path}:/levels/{stored['name']}") for stored in data["levels"]]
    summaries = [stored["attrs"]["summary"] for stored in data["levels"]]
    across = data["attrs"]["across_levels"]
    probability = float(data["attrs"]["confidence"])
    units = units_of(data["attrs"].get("units"))
    top = summaries[-1]
    top_lines = levels[-1].lines
    detection = bool(np.any(((top_lines.kind == ODD) | (top_lines.kind == EVEN)) & top_lines.in_band))
    distortion, findings = distortion_verdict(top, detection)
    headline = f"{distortion}; {level_verdict(across, units)}"
    spectrum = top["spectrum"]
    findings = [f"verdict at the highest level, {_name(top, len(summaries) - 1, units)}"] + findings
    if _finite(spectrum["excited_above_odd_db"]) and not (noise_floor(top) == "zero"
                                                          and spectrum["excited_above_odd_db"] > -PRECISION_DB):
        findings.append(f"odd distortion {spectrum['excited_above_odd_db']:.0f} dB below the output at the "
                        "excited lines")
    findings.append(f"nonlinear variance of the BLA {_variance_text(top['nl_var_db'], top, nonlinear=True)}, noise "
                    f"variance {_variance_text(top['noise_var_db'], top)} relative to |G_BLA|² (band means)")
    warnings = list(data["attrs"]["warnings"]) + [f"{_name(s, i, units)}: {w}" for i, s in enumerate(summaries)
                                                  for w in s["warnings"]]
    lpm_figures, lpm_tables, lpm_warnings = _lpm_parts(data, probability, units)
    return _with_frm(Page(
        kind="Best Linear Approximation", title=f"BLA report: {Path(path).name}", source=str(path),
        headline=headline, findings=findings, figures=_figures(levels, summaries, probability, units) + lpm_figures,
        tables=_tables(summaries, across, probability, units) + lpm_tables, warnings=warnings + lpm_warnings,
        provenance=data["attrs"]["provenance"], note=units.missing_note("u", "y"),
        numbers={"levels": summaries, "across_levels": across, "confidence": probability,
                 "detected_threshold_db": DETECTED_DB, "units": units.known,
                 "lpm_levels": [stored["attrs"]["summary"] for stored in data["lpm_levels"]]}), data)


def _with_frm(page: Page, data: dict) -> Page:
    """``page`` with the frequency response matrix levels of ``data`` added after its own
    (:mod:`nlsid.report.render_frm`): their figures, tables, findings and warnings, and their
    summaries as ``numbers["frm_levels"]`` and ``numbers["frm_lpm_levels"]``."""
    if not data["frm_levels"] and not data.get("frm_lpm_levels"):
        return page
    from nlsid.report.render_frm import frm_parts

    figures, tables, findings, warnings, summaries = frm_parts(data)
    page.figures += figures
    page.tables += tables
    page.findings += findings
    page.warnings += warnings
    page.numbers["frm_levels"] = summaries[:len(data["frm_levels"])]
    page.numbers["frm_lpm_levels"] = summaries[len(data["frm_levels"]):]
    return page


def lpm_headline(summary: dict, units: Units) -> str:
    """The verdict of a level of arbitrary runs: what the LPM measured, with its floor as a bound."""
    lo, hi = summary["band_hz"]
    return (f"FRF of arbitrary excitation by the Local Polynomial Method over {lo:.3g} to {hi:.3g} Hz: "
            f"|G|² {summary['bla_db']:.1f} {units.ratio_db('y', 'u')} on average; noise plus nonlinear distortion "
            f"{summary['total_var_db']:.1f} dB relative to |G|² (an upper bound of the noise: the two "
            "cannot be separated without periodic excitation)")


def _lpm_parts(data: dict, probability: float, units: Units) -> tuple[list[Figure], list[Table], list[str]]:
    from nlsid.report.lpm_plots import lpm_figure
    from nlsid.report.vector import figure

    figures, rows, warnings = [], [], []
    first = len(data["levels"])  # the levels of arbitrary runs are numbered after the multisine levels
    for index, stored in enumerate(data["lpm_levels"]):
        summary = stored["attrs"]["summary"]
        name = _name(summary, first + index, units)
        figures.append(figure(lpm_figure(stored, probability, units.for_figures(), first + index),
                              f"FRF of the arbitrary runs at {name} by the Local Polynomial Method ({BOOK}, "
                              f"Section 3.7) with its {probability:.0%} confidence "
                              "bounds, F(2, 2q) with q degrees of freedom. The red curve is the standard "
                              "deviation of the estimate: noise and nonlinear distortion together.",
                              f"lpm_level_{index:02d}"))
        lo, hi = summary["band_hz"]
        rows.append([str(first + index), number(summary["u_rms"]), str(summary["realizations"]), summary["method"],
                     f"{lo:.4g} .. {hi:.4g}", str(summary["excited_lines"]), number(summary["bla_db"], ".1f"),
                     number(summary["total_var_db"], ".1f"), str(summary["lpm"]["dof"])])
        warnings += [f"arbitrary {name}: {w}" for w in summary["warnings"]]
    tables = [Table("BLA of arbitrary runs per level (Local Polynomial Method)",
                    ["level", units.label("u rms", "u"), "records", "method", "band Hz", "lines",
                     f"|G|² ({units.ratio_db('y', 'u')})", "noise+NL var (dB re |G|², upper bound)", "dof q"], rows,
                    note="noise+NL var: band mean of the variance of G relative to |G|²; it bounds the noise "
                         "from above.")] if rows else []
    return figures, tables, warnings


def _lpm_page(path: Path, data: dict) -> Page:
    """The page of a bla.h5 holding only levels of arbitrary runs."""
    probability = float(data["attrs"]["confidence"])
    units = units_of(data["attrs"].get("units"))
    summaries = [stored["attrs"]["summary"] for stored in data["lpm_levels"]]
    figures, tables, warnings = _lpm_parts(data, probability, units)
    top = summaries[-1]
    findings = [f"{_name(s, i, units)}: {s['realizations']} records, q = {s['lpm']['dof']} degrees of freedom, window "
                f"{s['lpm']['lines']} lines, degree {s['lpm']['degree']}" for i, s in enumerate(summaries)]
    return Page(kind="Best Linear Approximation", title=f"BLA report: {Path(path).name}", source=str(path),
                headline=lpm_headline(top, units), findings=findings, figures=figures, tables=tables,
                warnings=list(data["attrs"]["warnings"]) + warnings, provenance=data["attrs"]["provenance"],
                note=units.missing_note("u", "y"),
                numbers={"levels": [], "lpm_levels": summaries, "confidence": probability})
