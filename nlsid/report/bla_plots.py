"""Figures of the ``bla`` stage: matplotlib figures for the report page (SVG) and for ``--plots`` (PNG).

- ``spectrum_<level>.png``: the output spectrum as seed 000 Fig. 3: excited lines, odd and even
  detection lines, non-harmonic lines and the noise level, distinguished by marker and colour.
- ``bla_<level>.png``: |G_BLA| and its phase with the 95% confidence bounds (book Ex. 92) and the
  standard deviations of the estimate due to noise and to the stochastic nonlinear distortions
  (seed 000 Fig. 5), plus the fast method's odd and even levels when available.
- ``bla_vs_level.png``: |G_BLA| of every level and the band-mean distortion versus the rms input
  (seed 000 Figs. 4-5).

Axis labels carry the units of the recording (:class:`~nlsid.report.units.Units`). matplotlib is
imported inside the functions so that importing this module stays cheap.
"""

from __future__ import annotations

import io

import numpy as np

from nlsid.analysis.level_names import level_name
from nlsid.analysis.levels import LevelResult, across_levels
from nlsid.analysis.lines import EVEN, EXCITED, NONHARMONIC, ODD
from nlsid.report.axes import (FIGURE_HEIGHT, band_limits, frequency_axis, legend_outside, phase_axis,
                               plain_log_ticks, power_db, wrapped_band, wrapped_phase)
from nlsid.report.units import Units
from nlsid.report.vector import band, fit_labels, new_figure


def _figure(rows: int = 1):
    return new_figure(rows, height=FIGURE_HEIGHT)


def _png(figure) -> bytes:
    fit_labels(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


def _title(level: LevelResult, units: Units, index: int | None) -> str:
    """``level 1 (rms 2 N), M = 3, P = 2`` (:mod:`nlsid.analysis.level_names`); without its index
    the level is named by its rms alone."""
    name = (level_name(index, level.u_rms, units.known.get("u")) if index is not None
            else f"u rms {units.value(format(level.u_rms, '.3g'), 'u')}")
    return f"{name}, M = {level.n_realizations}, P = {level.n_periods}"


def spectrum_figure(level: LevelResult, units: Units, index: int | None = None):
    """Output spectrum (rms over realizations) with the line classes distinguished (seed 000 Fig. 3)."""
    figure, (axis,) = _figure()
    lines, spectrum = level.lines, level.spectrum
    styles = ((EXCITED, "excited", "k", "o"), (ODD, "odd detection", "tab:red", "v"),
              (EVEN, "even detection", "tab:blue", "^"), (NONHARMONIC, "non-harmonic", "tab:gray", "."))
    for kind, label, colour, marker in styles:
        bins = np.flatnonzero(lines.kind == kind)
        if bins.size:
            axis.plot(lines.frequency(bins), power_db(spectrum.y_power[bins]), linestyle="none", marker=marker,
                      markersize=3, color=colour, label=label)
    bins = lines.bins
    axis.plot(lines.frequency(bins), power_db(spectrum.y_noise[bins]), color="tab:green", linewidth=1,
              label="noise (variance of the P-mean)")
    excited = lines.frequency(np.flatnonzero(lines.kind == EXCITED))
    frequency_axis(axis, excited)
    band_limits(axis, excited)
    axis.set_ylabel(f"output power ({units.power_db('y')})")
    axis.set_title(f"Output spectrum: {_title(level, units, index)}")
    legend_outside(axis)
    return figure


def bla_figure(level: LevelResult, units: Units, index: int | None = None):
    """|G_BLA| and phase with confidence bounds and noise / nonlinear standard deviations."""
    figure, (magnitude, phase) = _figure(2)
    robust, f = level.robust, level.lines.frequency(level.lines.excited)
    M = robust.n_realizations
    magnitude.plot(f, power_db(np.abs(robust.G) ** 2), color="k", label="|G_BLA|")
    band(magnitude, f, power_db(robust.bounds.mag_lo**2), power_db(robust.bounds.mag_hi**2), "95% bounds", color="k",
         alpha=0.15)
    magnitude.plot(f, power_db(robust.var_nl / M), "--", color="tab:red", label="std nonlinear (of the estimate)")
    magnitude.plot(f, power_db(robust.var_noise), ":", color="tab:green", label="std noise (of the estimate)")
    if level.fast is not None:
        magnitude.plot(f, power_db(level.fast.var_nl / level.fast.n_runs), "-.", color="tab:orange",
                       label="fast method: std nonlinear" + (" (odd)" if level.lines.odd_grid else ""))
        if level.fast.var_nl_even is not None:
            magnitude.plot(f, power_db(level.fast.var_nl_even / level.fast.n_runs), "-.", color="tab:blue",
                           label="fast method: std nonlinear (even)")
    magnitude.set_ylabel(f"|G_BLA|, std ({units.ratio_db('y', 'u')})")
    magnitude.set_title(f"BLA ({robust.method}): {_title(level, units, index)}")
    # beside the axes: six curves spread over the whole height leave no free corner
    magnitude.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    # wrapped to +-180 degrees: unwrapped, the noise of incoherent lines adds up to thousands of
    # degrees and flattens the coherent part; the bounds are computed around np.angle, the wrapped phase
    phase.plot(*wrapped_phase(f, robust.G), color="k", label="phase of G_BLA")
    band(phase, *wrapped_band(f, robust.G, robust.bounds.phase_lo, robust.bounds.phase_hi), "95% bounds",
         color="k", alpha=0.15)
    phase_axis(phase)
    for axis in (magnitude, phase):
        frequency_axis(axis, f)
    return figure


def levels_figure(levels: list[LevelResult], units: Units):
    """|G_BLA| per level, and band-mean nonlinear and noise variances versus the rms input."""
    figure, (curves, trend) = _figure(2)
    for index, level in enumerate(levels):
        curves.plot(level.lines.frequency(level.lines.excited), power_db(np.abs(level.robust.G) ** 2),
                    label=level_name(index, level.u_rms, units.known.get("u")))
    frequency_axis(curves, np.concatenate([level.lines.frequency(level.lines.excited) for level in levels]))
    curves.set_ylabel(f"|G_BLA| ({units.ratio_db('y', 'u')})")
    legend_outside(curves)
    rows = across_levels(levels)["levels"]
    rms = [row["u_rms"] for row in rows]
    trend.semilogx(rms, [row["nl_var_db"] for row in rows], "o--", color="tab:red", label="nonlinear variance")
    trend.semilogx(rms, [row["noise_var_db"] for row in rows], "s:", color="tab:green", label="noise variance")
    plain_log_ticks(trend.xaxis)
    trend.set_xlabel(units.label("u rms", "u"))
    trend.set_ylabel("band mean (dB re |G_BLA|²)")
    legend_outside(trend)
    return figure


def render_figures(levels: list[LevelResult], units: Units, lpm_levels=()) -> dict[str, bytes]:
    """Every figure of the stage as PNG bytes, keyed by file name (render first, write later):
    those of the multisine ``levels`` (``bla_vs_level.png`` when there is one), and
    ``lpm_level_NN.png`` per level of arbitrary runs (:class:`~nlsid.analysis.arbitrary.LPMLevel`)."""
    from nlsid.report.lpm_plots import lpm_level_figure

    out = {}
    for index, level in enumerate(levels):
        out[f"spectrum_level_{index:02d}.png"] = _png(spectrum_figure(level, units, index))
        out[f"bla_level_{index:02d}.png"] = _png(bla_figure(level, units, index))
    if levels:
        out["bla_vs_level.png"] = _png(levels_figure(levels, units))
    for index, level in enumerate(lpm_levels):
        out[f"lpm_level_{index:02d}.png"] = _png(lpm_level_figure(level, units, len(levels) + index))
    return out
