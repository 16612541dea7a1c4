"""The frequency response matrix (FRM) levels of a ``bla.h5`` file on the report page.

A ``bla.h5`` of runs with several inputs or outputs holds ``frm_levels`` (``docs/formats.md``,
``docs/mimo.md``): per level the n_y x n_u FRM G, the standard deviation of each entry from the
noise (period-to-period scatter) and from noise plus stochastic nonlinear distortion
(realization-to-realization scatter), and the confidence circles of each entry. A file of these
alone gets a page of its own (:func:`render_frm`); a file that also holds single-input levels
gets them as a section of the BLA page (:func:`frm_parts`).

Verdict, at the highest level, where the distortion is largest, from the numbers stored in the
level's ``summary``:

- Per entry, the band means of the total and of the noise variance relative to ``|G_ia|^2``
  (``total_var_db``, ``noise_var_db``): their difference is the stochastic nonlinear distortion
  of that entry over the noise (Schoukens, Pintelon and Rolain 2012, Section 6.1.1; the total
  variance holds both). An entry shows nonlinear distortion when the difference exceeds
  :data:`~nlsid.report.detection.DETECTED_DB` = 3 dB, the threshold of the single-input page:
  the band mean over L lines of a variance estimated with 2 (M - 1) degrees of freedom per line
  has a relative standard deviation ``1/sqrt(L (M - 1))``, below 0.3 (about 1 dB) for the
  smallest useful design (L >= 10 lines, M = 2), so 3 dB is three standard deviations.
- Where only odd harmonics are excited, per output the band-mean power at the odd and at the even
  detection lines against the noise (``detection``: ``odd_db``, ``even_db``, ``noise_db``), odd
  and even distortion detected above :data:`~nlsid.report.detection.DETECTED_DB` as on the
  single-input page (book Eq. 5-9).
- Without a noise variance (P = 1) or a total variance (M = 1) nothing is compared, and the page
  says so.

The levels of arbitrary runs (``frm_lpm_levels``, the Local Polynomial Method for several inputs,
numbered after the multisine FRM levels as ``nlsid bla`` numbers them) have one variance per
entry, noise and nonlinear distortion together: their verdict gives its band mean relative to
``|G_ia|^2`` over the entries as an upper bound of the noise, never as a noise level. A file
with multisine FRM levels takes its headline from the highest of those.
"""

from __future__ import annotations

import math
from pathlib import Path

from nlsid.citations import BOOK
from nlsid.report.detection import DETECTED_DB
from nlsid.report.frm_plots import frm_figure
from nlsid.report.html import Figure, Page, Table, number
from nlsid.report.units import Units, units_of


def _finite(value) -> bool:
    return value is not None and math.isfinite(value)


def frm_level_name(index: int, summary: dict) -> str:
    """``FRM level 1, level 0.5``: FRM levels are numbered apart from the single-input levels, as
    ``nlsid bla`` prints them; the level attribute of the runs follows where they carry one."""
    level = summary.get("level")
    return f"FRM level {index}" + (f", level {level:g}" if _finite(level) else "")


def _units(stored: dict) -> Units:
    return units_of(stored["attrs"].get("units"))


def nonlinear_entries(summary: dict) -> tuple[list[str], list[str], list[str]]:
    """The entries ("from u to y") whose total variance stands more than DETECTED_DB above their
    noise variance, those within it, and those where either variance is not available."""
    above, within, unknown = [], [], []
    for row in summary["entries"]:
        name = f"from {row['input']} to {row['output']}"
        total, noise = row["total_var_db"], row["noise_var_db"]
        if not (_finite(total) and _finite(noise)):
            unknown.append(name)
        elif total - noise > DETECTED_DB:
            above.append(name)
        else:
            within.append(name)
    return above, within, unknown


def frm_verdict(summary: dict) -> tuple[str, list[str]]:
    """Headline and findings of one FRM level (module docstring)."""
    shape = f"{len(summary['outputs'])} outputs x {len(summary['inputs'])} inputs"
    lo, hi = summary["band_hz"]
    head = f"Frequency response matrix of {shape} over {lo:.3g} to {hi:.3g} Hz"
    above, within, unknown = nonlinear_entries(summary)
    findings = [f"M = {summary['realizations']} realizations of E = {summary['experiments']} experiments of "
                f"P = {summary['periods']} periods, {summary['excited_lines']} excited lines"]
    if unknown and not (above or within):
        missing = "one period per realization (P = 1): no noise variance" if summary["periods"] < 2 else \
            "one realization (M = 1): no total variance"
        head = f"{head}; nonlinear distortion not separated from the noise ({missing})"
    elif above:
        head = (f"{head}; stochastic nonlinear distortion above the noise {', '.join(above)}"
                + (f"; none {', '.join(within)}" if within else ""))
    else:
        head = f"{head}; no stochastic nonlinear distortion above the noise in any entry"
    findings.append(f"an entry shows stochastic nonlinear distortion when its total variance stands more than "
                    f"{DETECTED_DB:g} dB above its noise variance (band means; {BOOK}, Section 6.1.1)")
    if unknown and (above or within):
        findings.append(f"variances not available {', '.join(unknown)}")
    for row in summary.get("detection") or ():
        output = summary["outputs"][int(row["output"])]
        parts = []
        for kind in ("odd", "even"):
            level, noise = row[f"{kind}_db"], row["noise_db"]
            if _finite(level) and _finite(noise):
                seen = "detected" if level - noise > DETECTED_DB else "not detected"
                parts.append(f"{kind} {level - noise:+.1f} dB re the noise ({seen})")
        if parts:
            findings.append(f"output {output}, detection lines: {', '.join(parts)}")
    return head, findings


def lpm_frm_verdict(summary: dict) -> tuple[str, list[str]]:
    """Headline and findings of one FRM level of arbitrary runs (module docstring)."""
    shape = f"{len(summary['outputs'])} outputs x {len(summary['inputs'])} inputs"
    lo, hi = summary["band_hz"]
    levels = [row["total_var_db"] for row in summary["entries"] if _finite(row["total_var_db"])]
    head = (f"Frequency response matrix of {shape} of arbitrary excitation by the Local Polynomial Method over "
            f"{lo:.3g} to {hi:.3g} Hz")
    if levels:
        head += (f"; noise plus nonlinear distortion {min(levels):.1f} to {max(levels):.1f} dB relative to |G|² over "
                 "the entries (an upper bound of the noise: the two cannot be separated without periodic excitation)")
    lpm = summary["lpm"]
    findings = [f"M = {summary['records']} records of N = {summary['samples']} samples, q = {lpm['dof']} degrees of "
                f"freedom, window {lpm['lines']} lines, degree {lpm['degree']}, {summary['excited_lines']} lines"]
    return head, findings


def _table(stored: dict, name: str, units: Units) -> Table:
    summary = stored["attrs"]["summary"]
    rows = [[f"from {row['input']} to {row['output']}", number(row["bla_db"], ".1f"),
             units.ratio_db(row["output"], row["input"]), number(row["noise_var_db"], ".1f"),
             number(row["total_var_db"], ".1f")] for row in summary["entries"]]
    return Table(f"Frequency response matrix per entry, {name}",
                 ["entry", "|G| band mean (dB)", "dB reference", "noise var (dB re |G|²)",
                  "total var (dB re |G|²)"], rows, text=(0, 2),
                 note="|G| band mean: mean over the excited lines of 20 log10 |G|; noise and total var: 10 log10 of "
                      "the band mean of the variance of G relative to |G|² (noise: period-to-period scatter; "
                      "total: realization-to-realization scatter, noise and nonlinear distortion).")


def _lpm_table(stored: dict, name: str, units: Units) -> Table:
    summary = stored["attrs"]["summary"]
    rows = [[f"from {row['input']} to {row['output']}", number(row["bla_db"], ".1f"),
             units.ratio_db(row["output"], row["input"]), number(row["total_var_db"], ".1f")]
            for row in summary["entries"]]
    return Table(f"Frequency response matrix per entry, {name} (Local Polynomial Method)",
                 ["entry", "|G| band mean (dB)", "dB reference", "noise+NL var (dB re |G|², upper bound)"], rows,
                 text=(0, 2), note="|G| band mean: mean over the band's lines of 20 log10 |G|; noise+NL var: 10 log10 "
                                   "of the band mean of the variance of G relative to |G|²; it bounds the noise from "
                                   "above.")


def _caption(stored: dict, name: str) -> str:
    attrs = stored["attrs"]
    probability = float(attrs["confidence"])
    if "var_G" in stored:
        return (f"Frequency response matrix, {name}, by the Local Polynomial Method. One Bode plot per entry, from "
                f"each input (column) to each output (pair of rows): |G| with its {probability:.0%} confidence "
                "bounds, F(2, 2q) with q degrees of freedom (grey), the standard deviation of the estimate (red, "
                f"dashed: noise and nonlinear distortion together), and the phase with the same bounds ({BOOK}, "
                "Section 3.7).")
    return (f"Frequency response matrix, {name}. One Bode plot per entry, from each input (column) to each output "
            f"(pair of rows): |G| with its {probability:.0%} confidence bounds on the total variance, F(2, 2M - 2) "
            "(grey), the standard deviation of the estimate from noise plus stochastic nonlinear distortion "
            f"(red, dashed) and from the noise alone (green, dotted), and the phase with the same bounds ({BOOK}, "
            "Eqs. 6-117 and 6-88).")


def frm_parts(data: dict) -> tuple[list[Figure], list[Table], list[str], list[str], list[dict]]:
    """Figures, tables, findings, warnings and summaries of the ``frm_levels`` (the highest
    level's figure first) and then the ``frm_lpm_levels`` of :func:`nlsid.io.bla_file.read_bla`'s
    ``data`` (numbered after them)."""
    from nlsid.report.vector import figure

    multisine, arbitrary = data["frm_levels"], data.get("frm_lpm_levels", [])
    stored_levels = multisine + arbitrary
    summaries = [stored["attrs"]["summary"] for stored in stored_levels]
    figures, tables, findings, warnings = [], [], [], []
    order = [len(multisine) - 1, *range(len(multisine) - 1)] if multisine else []
    for index in order + list(range(len(multisine), len(stored_levels))):
        stored, name = stored_levels[index], frm_level_name(index, summaries[index])
        units = _units(stored)
        figures.append(figure(frm_figure(stored, units.for_figures(), name), _caption(stored, name),
                              f"frm_level_{index:02d}"))
    for index, stored in enumerate(stored_levels):
        name = frm_level_name(index, summaries[index])
        lpm = index >= len(multisine)
        tables.append((_lpm_table if lpm else _table)(stored, name, _units(stored).for_figures()))
        head, found = (lpm_frm_verdict if lpm else frm_verdict)(summaries[index])
        findings.append(f"{name}: {head}")
        findings += [f"{name}: {item}" for item in found]
        warnings += [f"{name}: {w}" for w in stored["attrs"]["warnings"]]
    return figures, tables, findings, warnings, summaries


def render_frm(path: Path, data: dict) -> Page:
    """The page of a ``bla.h5`` that holds only frequency response matrix levels (of multisine or
    of arbitrary runs); the headline is that of the highest multisine FRM level, else of the
    highest level of arbitrary runs."""
    figures, tables, findings, warnings, summaries = frm_parts(data)
    multisine = len(data["frm_levels"])
    top = multisine - 1 if multisine else len(summaries) - 1
    headline, _ = (frm_verdict if multisine else lpm_frm_verdict)(summaries[top])
    name = frm_level_name(top, summaries[top])
    findings = [item for item in findings if item != f"{name}: {headline}"]
    stored = (data["frm_levels"] + data.get("frm_lpm_levels", []))[top]
    names = [*summaries[top]["inputs"], *summaries[top]["outputs"]]
    several = multisine > 1 or (not multisine and len(summaries) > 1)
    return Page(kind="Best Linear Approximation", title=f"BLA report: {Path(path).name}", source=str(path),
                headline=f"{headline} at the highest, {name}" if several else headline,
                findings=findings, figures=figures,
                tables=tables, warnings=list(data["attrs"]["warnings"]) + warnings,
                provenance=data["attrs"]["provenance"], note=_units(stored).missing_note(*names),
                numbers={"levels": [], "lpm_levels": [], "frm_levels": summaries[:multisine],
                         "frm_lpm_levels": summaries[multisine:],
                         "confidence": float(data["attrs"]["confidence"]), "detected_threshold_db": DETECTED_DB})


