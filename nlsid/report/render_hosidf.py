"""The report page of a ``hosidf.h5`` file: significant harmonics, H_1 versus amplitude, or the sweep optimum.

Grid verdict (numbers stored in the file, layout in ``docs/drafts/hosidf.md``):

- Which harmonics k >= 2 are significant where: a harmonic of a cell is significant when its mean
  output phasor clears the noise bound of seed 003 Eq. 6, ``|Y(k w0)| > eps_k = sigma(k) + 2 varsigma``
  (the ``significant`` dataset). The headline counts, per harmonic, the measured cells where it is
  significant and names the frequencies. The bound is a screen, not a test at a small false-alarm
  rate: a line holding only noise clears ``sigma(k)`` with probability e^-1 (``docs/drafts/hosidf.md``).
- How H_1 changes with amplitude (seed 000 Fig. 6): per frequency, ``20 log10 |H_1(a_max)/H_1(a_min)|``
  between the smallest and the largest measured amplitude; the largest in magnitude is reported
  with its standard deviation. ``|H|`` of a complex estimate with circular scatter of variance
  ``var`` (the variance of the mean, over repeats when available, else over periods) has a radial
  standard deviation ``sqrt(var/2)``, so the change in dB has ``sigma = (20/ln 10) sqrt(var_a/(2|H_a|^2)
  + var_b/(2|H_b|^2))`` to first order; a change beyond :data:`CHANGE_SIGMAS` = 3 sigma is called
  significant (a 0.3 % false-alarm rate for a Gaussian error).

Sweep verdict (seed 003): the optimum of the linearity cost (Definition 3, Eq. 5) and that of the
time-domain error (Eq. 7), with the cost at the optimum relative to the first swept value.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from nlsid.analysis.hosidf import CellHOSIDF, HarmonicStats, HOSIDFGrid
from nlsid.analysis.linearity_cost import Sweep, SweepPoint
from nlsid.errors import InputError
from nlsid.citations import FRICTION_COMPENSATION, MOTION_STAGES, SPECTRAL_ANALYSIS
from nlsid.report.html import Figure, Page, Table, number
from nlsid.io.hosidf_file import output_grids
from nlsid.report.units import Units, units_of

CHANGE_SIGMAS = 3.0
NBSP = "\u00a0"  # keeps a level and its check mark on one line
_DB = 20.0 / math.log(10.0)


def _grid(stored: dict, harmonics: int) -> HOSIDFGrid:
    """The :class:`HOSIDFGrid` of a ``/grid`` group, with a cell wherever ``n_repeats > 0``."""
    cells = {}
    for fi, ai in zip(*np.nonzero(stored["n_repeats"])):
        at = (fi, ai)
        stats = HarmonicStats(stored["Y"][at], stored["Y_var_mean"][at], float(stored["Y_avg_var"][at]),
                              float(stored["Y_var_var"][at]), stored["bound"][at])
        cells[(int(fi), int(ai))] = CellHOSIDF(
            frequency=float(stored["frequency"][fi]), line=int(stored["bin"][fi]), level=float(stored["level"][ai]),
            n_repeats=int(stored["n_repeats"][at]), n_periods=int(stored["n_periods"][at]),
            h=stored["H"][at], h_var_repeats=stored["H_var_repeats"][at], h_var_periods=stored["H_var_periods"][at],
            h000=stored["H000"][at], h000_var_repeats=stored["H000_var_repeats"][at],
            h000_var_periods=stored["H000_var_periods"][at], stats=stats)
    return HOSIDFGrid(stored["frequency"], stored["level"], harmonics, cells)


def _sweep(stored: dict) -> Sweep:
    """The :class:`Sweep` of a ``/sweep`` group.

    Run ids are not stored (``run_ids`` is empty). Table I's ``avg_var`` is the mean of
    ``Y_var_mean`` over k = 1..K, and ``varsigma^2`` follows from Eq. 6, ``bound = sigma(k) + 2 varsigma``.
    """
    points = []
    for m, value in enumerate(stored["value"]):
        var_mean, bound = stored["Y_var_mean"][m], stored["bound"][m]
        varsigma = float(np.mean(bound[1:] - np.sqrt(var_mean[1:]))) / 2
        stats = HarmonicStats(stored["Y"][m], var_mean, float(np.mean(var_mean[1:])), varsigma**2, bound)
        points.append(SweepPoint(float(value), [], stats, stored["H"][m], float(stored["cost"][m]),
                                 float(stored["cost_all"][m]), stored["used"][m].astype(bool),
                                 float(stored["time_error"][m])))
    return Sweep(str(stored["parameter"]), float(stored["frequency"]), float(stored["level"]), points)


def significance(grid: dict) -> list[dict]:
    """Per harmonic k >= 2: measured cells, cells where it clears its bound, and their frequencies."""
    measured = grid["n_repeats"] > 0
    out = []
    for k in grid["harmonic"][2:]:
        hit = (grid["significant"][..., k] > 0) & measured
        out.append({"k": int(k), "cells": int(measured.sum()), "significant_cells": int(hit.sum()),
                    "frequencies": grid["frequency"][hit.any(axis=1)]})
    return out


def h1_change(grid: dict) -> list[dict]:
    """Per frequency: the change of |H_1| (dB) from the smallest to the largest measured amplitude and its std."""
    h1 = grid["H"][..., 1]
    var = np.where(np.isfinite(grid["H_var_repeats"][..., 1]), grid["H_var_repeats"][..., 1],
                   grid["H_var_periods"][..., 1])
    rows = []
    for fi, frequency in enumerate(grid["frequency"]):
        measured = np.flatnonzero(grid["n_repeats"][fi] > 0)
        if measured.size < 2:
            continue
        a, b = measured[0], measured[-1]
        change = _DB * math.log(abs(h1[fi, b]) / abs(h1[fi, a]))
        sigma = _DB * math.sqrt(var[fi, a] / (2 * abs(h1[fi, a]) ** 2) + var[fi, b] / (2 * abs(h1[fi, b]) ** 2))
        rows.append({"frequency": float(frequency), "from_level": float(grid["level"][a]),
                     "to_level": float(grid["level"][b]), "change_db": change, "std_db": sigma})
    return rows


def _frequencies(values: np.ndarray) -> str:
    return ", ".join(f"{f:g}" for f in values) + " Hz"


def grid_verdict(grid: dict, units: Units, signal: str) -> tuple[str, list[str]]:
    """Headline and findings of a grid (rules in the module docstring); amplitudes in the unit of ``signal``."""
    table = significance(grid)
    seen = [row for row in table if row["significant_cells"]]
    if seen:
        parts = [f"k = {row['k']} in {row['significant_cells']}/{row['cells']} cells" for row in seen]
        distortion = "Harmonics above their noise bound: " + ", ".join(parts)
    else:
        distortion = "No harmonic above its noise bound: the response looks linear at these amplitudes"
    findings = [f"k = {row['k']} significant at {_frequencies(row['frequencies'])}" for row in seen]
    quiet = [str(row["k"]) for row in table if not row["significant_cells"]]
    if quiet and seen:
        findings.append(f"never above the bound: k = {', '.join(quiet)}")
    changes = h1_change(grid)
    if not changes:
        return f"{distortion}; one amplitude per frequency: H_1 versus amplitude not measured", findings
    worst = max(changes, key=lambda row: abs(row["change_db"]))
    verdict = "significant" if abs(worst["change_db"]) > CHANGE_SIGMAS * worst["std_db"] else "within the noise"
    headline = (f"{distortion}; |H_1| changes by up to {worst['change_db']:+.2f} dB from amplitude "
                f"{worst['from_level']:g} to {units.value(format(worst['to_level'], 'g'), signal)} "
                f"(at {worst['frequency']:g} Hz)")
    findings.append(f"largest |H_1| change {worst['change_db']:+.2f} dB ± {number(worst['std_db'], '.2g')} dB "
                    f"(1 sigma): {verdict} ({CHANGE_SIGMAS:g} sigma rule)")
    return headline, findings


def sweep_verdict(sweep: dict, units: Units, signal: str) -> tuple[str, list[str]]:
    """Headline and findings of a linearity-cost sweep (seed 003 Definition 3, Eq. 7)."""
    name, cost = str(sweep["parameter"]), sweep["cost"]
    best = int(np.argmin(cost))
    headline = (f"Optimum {name} = {sweep['optimum']:g} by the linearity cost; {sweep['time_optimum']:g} by the "
                f"time-domain error")
    findings = [f"sine of {sweep['frequency']:g} Hz, amplitude {units.value(format(sweep['level'], 'g'), signal)}; "
                f"{len(cost)} values of {name} "
                f"from {sweep['value'][0]:g} to {sweep['value'][-1]:g}"]
    if cost[0] > 0 and cost[best] > 0:
        findings.append(f"cost at the optimum {cost[best]:.3g}, {20 * math.log10(cost[best] / cost[0]):+.1f} dB "
                        f"relative to {name} = {sweep['value'][0]:g} ({cost[0]:.3g})")
    used = np.flatnonzero(sweep["used"][best])
    findings.append("harmonics in the cost at the optimum: " + (", ".join(f"k = {k}" for k in used) if used.size
                                                               else "none clears its bound (cost 0)"))
    return headline, findings


def _grid_tables(grid: dict, units: Units, signal: str, output: str = "y", of: str = "") -> list[Table]:
    """The cell and H_1 tables of one output's grid (``of``: `` (output NAME)`` in the captions)."""
    measured = grid["n_repeats"] > 0
    K = int(grid["harmonic"][-1])
    rows = []
    for fi, ai in zip(*np.nonzero(measured)):
        H, ratio = grid["H"][fi, ai], np.abs(grid["Y"][fi, ai]) / grid["bound"][fi, ai]
        marks = [f"{20 * math.log10(r):+.1f}{NBSP + '✓' if grid['significant'][fi, ai, k] else ''}" if r > 0 else "-"
                 for k, r in zip(range(2, K + 1), ratio[2:])]
        rows.append([f"{grid['frequency'][fi]:g}", f"{grid['level'][ai]:g}",
                     f"{grid['n_repeats'][fi, ai]} x {grid['n_periods'][fi, ai]}", number(abs(H[1])),
                     number(math.degrees(float(np.angle(H[1]))), ".1f"), *marks])
    change_rows = [[f"{r['frequency']:g}", f"{r['from_level']:g}", f"{r['to_level']:g}", f"{r['change_db']:+.3f}",
                    number(r["std_db"], ".2g")] for r in h1_change(grid)]
    tables = [Table(f"Cells: H_1 and each harmonic's level above its noise bound (dB){of}",
                    ["frequency Hz", units.label("amplitude", signal), "R x P",
                     f"|H_1| ({units.ratio(output, signal)})", "∠H_1 deg", *[f"k = {k}" for k in range(2, K + 1)]],
                    rows, note=f"k columns: 20 log10 |Y(k w0)| / eps_k, dB re the noise bound "
                               f"({FRICTION_COMPENSATION}, Table I, Eq. 6); ✓ marks a harmonic above its bound. "
                               "R repeats x P periods per cell.")]
    if change_rows:
        tables.append(Table(f"H_1 versus amplitude{of}", ["frequency Hz", units.label("from amplitude", signal),
                                                     units.label("to amplitude", signal), "Δ|H_1| dB", "std dB"],
                            change_rows,
                            note="Δ|H_1| = 20 log10 |H_1(to)/H_1(from)|; std to first order from the variance of "
                                 "the mean (over repeats, else periods)."))
    return tables


def _sweep_table(sweep: dict, units: Units) -> Table:
    rows = [[f"{v:g}", number(c, ".4g"), number(a, ".4g"), number(t, ".4g"),
             ", ".join(str(k) for k in np.flatnonzero(u)) or "-"]
            for v, c, a, t, u in zip(sweep["value"], sweep["cost"], sweep["cost_all"], sweep["time_error"],
                                     sweep["used"])]
    return Table(f"Linearity cost per value of {sweep['parameter']}",
                 [units.label(str(sweep["parameter"]), str(sweep["parameter"])), "f_c (Eq. 5)", "f (Eq. 4)",
                  units.label("ε (Eq. 7)", "y"), "harmonics in f_c"], rows,
                 note=f"{FRICTION_COMPENSATION}: f_c averages the significant harmonics k >= 2 relative to the "
                      "first (a ratio of like units, y/y); f uses k = 2..K; ε is the largest per-period rms "
                      "tracking error.")


_SWEEP_FIGURES = (
    ("sweep_harmonics", "Harmonics and cost versus the parameter. |Y(k w0)|/|Y(w0)| of the harmonics and the "
                        f"linearity cost f_c (as in {FRICTION_COMPENSATION}, Fig. 3)."),
    ("sweep_spectrum", "Harmonic spectrum, first value versus optimum. Mean and standard deviation at each "
                       f"harmonic (as in {FRICTION_COMPENSATION}, Fig. 4)."),
    ("sweep_hosidf", f"HOSIDFs versus the parameter. Magnitude and phase of H_1..H_5 (as in {FRICTION_COMPENSATION}, "
                     "Fig. 5)."),
    ("sweep_performance", "Frequency-domain cost and time-domain error. Both optima are marked (as in "
                          f"{FRICTION_COMPENSATION}, Fig. 6; ε of Eq. 7)."),
)


def _figures(data: dict, units: Units) -> list[Figure]:
    from nlsid.report import hosidf_plots as plots
    from nlsid.report.vector import figure

    signal = str(data["input_signal"])
    figures = []
    if "grid" in data:
        analytic = data["grid"].get("analytic", {}).get("H")
        several = len(data["outputs"]) > 1
        for output, stored in output_grids(data).items():
            grid = _grid(stored, int(data["harmonics"]))
            to, suffix, title = (f" to output {output}", f"_{output}", output) if several else ("", "", None)
            figures.append(figure(plots.first_hosidf_figure(grid, units, analytic, signal, output, title),
                                  f"First HOSIDF over frequency{to}. |H_1| and its phase, one line per amplitude"
                                  + (f", analytic ({SPECTRAL_ANALYSIS}, Lemma 2) dashed" if analytic is not None
                                     else "") + f" (as in {MOTION_STAGES}, Fig. 7).", f"hosidf_h1_map{suffix}"))
            for fi, frequency in enumerate(grid.frequencies):
                figures.append(figure(plots.versus_amplitude_figure(grid, fi, units, signal, output, title),
                                      f"HOSIDFs versus amplitude at {frequency:g} Hz{to}. |H_k| ({MOTION_STAGES}, "
                                      f"Eqs. 8-9) solid, standard deviation of the mean dashed (as in "
                                      f"{MOTION_STAGES}, Fig. 6).", f"hosidf_vs_amplitude_f{fi:03d}{suffix}"))
    if "sweep" in data:
        drawn = plots.sweep_figure_list(_sweep(data["sweep"]), units, signal)
        figures += [figure(mpl, caption, name) for mpl, (name, caption) in zip(drawn, _SWEEP_FIGURES)]
    return figures


def render_hosidf(path: Path) -> Page:
    """The report page of a ``hosidf.h5`` file: a grid, a sweep, or both (module docstring)."""
    from nlsid.io.hosidf_file import read_hosidf

    data = read_hosidf(path)
    if "grid" not in data and "sweep" not in data:
        raise InputError(f"{path}:/", "holds neither a /grid nor a /sweep group")
    headline, findings, tables, numbers = "", [], [], {"harmonics": int(data["harmonics"]),
                                                       "input_signal": str(data["input_signal"])}
    units, signal = units_of(data.get("units")), str(data["input_signal"])
    if "grid" in data and len(data["outputs"]) > 1:
        headline, findings, tables, numbers["grid"], numbers["outputs"] = _outputs_parts(data, units, signal)
    elif "grid" in data:
        grid = data["grid"]
        headline, findings = grid_verdict(grid, units, signal)
        tables += _grid_tables(grid, units, signal)
        numbers["grid"] = {"frequencies": grid["frequency"], "levels": grid["level"],
                           "significance": significance(grid), "h1_change": h1_change(grid)}
    if "sweep" in data:
        sweep = data["sweep"]
        sweep_headline, sweep_findings = sweep_verdict(sweep, units, signal)
        headline = f"{headline}; {sweep_headline}" if headline else sweep_headline
        findings += sweep_findings
        tables.append(_sweep_table(sweep, units))
        numbers["sweep"] = {key: sweep[key] for key in ("parameter", "frequency", "level", "optimum", "time_optimum",
                                                       "value", "cost", "cost_all", "time_error")}
    return Page(kind="Higher order sinusoidal input describing functions", title=f"HOSIDF report: {Path(path).name}",
                source=str(path), headline=headline, findings=findings, figures=_figures(data, units.for_figures()),
                tables=tables, provenance=data["provenance"], numbers=numbers,
                note=units.missing_note(*data["outputs"], signal))


def _outputs_parts(data: dict, units: Units, signal: str) -> tuple[str, list[str], list[Table], dict, list[dict]]:
    """Headline, findings, tables and numbers (the first output's ``grid``, and ``outputs``) of a
    grid of several outputs: each output's verdict as a finding, the headline naming the harmonics
    above their noise bound per output."""
    grids = output_grids(data)
    parts, findings, tables, rows = [], [], [], []
    for output, grid in grids.items():
        headline, found = grid_verdict(grid, units, signal)
        findings += [f"to {output}: {headline}"] + [f"to {output}: {item}" for item in found]
        tables += _grid_tables(grid, units, signal, output, f" (output {output})")
        seen = [row["k"] for row in significance(grid) if row["significant_cells"]]
        parts.append(f"{output}: k = {', '.join(str(k) for k in seen)}" if seen else f"{output}: none")
        rows.append({"output": output, "significance": significance(grid), "h1_change": h1_change(grid)})
    first = next(iter(grids.values()))
    headline = f"HOSIDFs to {len(grids)} outputs; harmonics above their noise bound to " + "; ".join(parts)
    numbers = {"frequencies": first["frequency"], "levels": first["level"], "significance": rows[0]["significance"],
               "h1_change": rows[0]["h1_change"]}
    return headline, findings, tables, numbers, rows
