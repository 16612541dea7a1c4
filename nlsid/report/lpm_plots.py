"""The figure of a level of arbitrary runs (``bla.h5`` ``lpm_levels``): the Local Polynomial Method's FRF.

Top: |G| in dB with its confidence circle as a band (|G| - radius .. |G| + radius) and the standard
deviation of the estimate (noise plus nonlinear distortion: an upper bound of the noise part);
bottom: the phase. Frequencies on a log axis with plain tick labels.
"""

from __future__ import annotations

import numpy as np

from nlsid.analysis.level_names import level_name
from nlsid.report.axes import FIGURE_HEIGHT, frequency_axis, legend_outside, phase_axis, power_db, wrapped_phase
from nlsid.report.units import Units
from nlsid.report.vector import band, new_figure


def lpm_figure(stored: dict, probability: float, units: Units, index: int | None = None):
    """The figure of one stored ``lpm_levels`` group (nlsid.io.bla_file.read_bla); ``index``: its
    level's index among all of the BLA's (multisine levels first), which names it."""
    figure, (magnitude, phase) = new_figure(2, height=FIGURE_HEIGHT)
    f, G = stored["frequency"], stored["G"]
    radius = stored["radius"]
    magnitude.plot(f, power_db(np.abs(G) ** 2), color="k", linewidth=1, label="|G| (LPM)")
    band(magnitude, f, power_db(np.maximum(np.abs(G) - radius, 0.0) ** 2), power_db((np.abs(G) + radius) ** 2),
         f"{probability:.0%} bounds", color="tab:blue", alpha=0.25, linewidth=0)
    magnitude.plot(f, power_db(stored["var_G"]), color="tab:red", linewidth=0.8,
                   label="std of G: noise + distortion (upper bound of noise)")
    magnitude.set_ylabel(f"|G|, std ({units.ratio_db('y', 'u')})")
    legend_outside(magnitude, fontsize=8)
    phase.plot(*wrapped_phase(f, G), color="k", linewidth=1, label="phase of G (LPM)")
    phase_axis(phase)
    attrs = stored["attrs"]
    rms = attrs.get("u_rms")
    level = (level_name(index, rms, units.known.get("u")) if index is not None
             else f"u rms {units.value(format(rms, '.3g'), 'u')}" if rms is not None else "arbitrary runs")
    magnitude.set_title(f"{level}: {attrs['n_records']} records of {attrs['n_samples']} samples, "
                        f"window {2 * attrs['half_width'] + 1} lines, degree {attrs['degree']}, q = {attrs['dof']}",
                        fontsize=9)
    for axis in (magnitude, phase):
        frequency_axis(axis, f)
    return figure


def lpm_level_figure(level, units: Units, index: int | None = None):
    """The figure of an :class:`~nlsid.analysis.arbitrary.LPMLevel` as computed (``nlsid bla
    --plots``), the same as :func:`lpm_figure` draws of it once stored in ``bla.h5``."""
    result = level.result
    stored = {"frequency": level.frequency, "G": level.G, "radius": level.bounds.radius, "var_G": level.var_G,
              "attrs": {"level": float("nan") if level.level is None else float(level.level),
                        "u_rms": float(level.u_rms),
                        "n_records": int(result.n_records), "n_samples": int(result.n_samples),
                        "half_width": int(result.half_width), "degree": int(result.degree), "dof": int(result.dof)}}
    return lpm_figure(stored, level.probability, units, index)
