"""The figure of a level of arbitrary runs (``bla.h5`` ``lpm_levels``): the Local Polynomial Method's FRF.

Top: |G| in dB with its confidence circle as a band (|G| - radius .. |G| + radius) and the standard
deviation of the estimate (noise plus nonlinear distortion: an upper bound of the noise part);
bottom: the phase. Frequencies on a log axis with plain tick labels.
"""

from __future__ import annotations

import numpy as np

from nlsid.report.axes import FIGURE_HEIGHT, plain_log_ticks, power_db, unwrapped_phase
from nlsid.report.units import Units
from nlsid.report.vector import band, new_figure


def lpm_figure(stored: dict, probability: float, units: Units):
    """The figure of one stored ``lpm_levels`` group (nlsid.io.bla_file.read_bla)."""
    figure, (magnitude, phase) = new_figure(2, height=FIGURE_HEIGHT)
    f, G = stored["frequency"], stored["G"]
    radius = stored["radius"]
    magnitude.plot(f, power_db(np.abs(G) ** 2), color="k", linewidth=1, label="|G| (LPM)")
    band(magnitude, f, power_db(np.maximum(np.abs(G) - radius, 0.0) ** 2), power_db((np.abs(G) + radius) ** 2),
         f"{probability:.0%} bounds", color="tab:blue", alpha=0.25, linewidth=0)
    magnitude.plot(f, power_db(stored["var_G"]), color="tab:red", linewidth=0.8,
                   label="std of G: noise + distortion (upper bound of noise)")
    magnitude.set_ylabel(f"|G|, std ({units.ratio_db('y', 'u')})")
    magnitude.legend(fontsize=8, loc="best")
    degrees, _ = unwrapped_phase(G)
    phase.plot(f, degrees, color="k", linewidth=1, label="phase of G (LPM)")
    phase.set_ylabel("phase (deg)")
    attrs = stored["attrs"]
    level = "no level" if not np.isfinite(attrs["level"]) else f"level {attrs['level']:g}"
    magnitude.set_title(f"{level}: {attrs['n_records']} records of {attrs['n_samples']} samples, "
                        f"window {2 * attrs['half_width'] + 1} lines, degree {attrs['degree']}, q = {attrs['dof']}",
                        fontsize=9)
    for axis in (magnitude, phase):
        axis.set_xlabel("frequency (Hz)")
        if np.all(f > 0):
            axis.set_xscale("log")
            plain_log_ticks(axis.xaxis)
        axis.grid(True, which="both", alpha=0.3)
    return figure


def lpm_level_figure(level, units: Units):
    """The figure of an :class:`~nlsid.analysis.arbitrary.LPMLevel` as computed (``nlsid bla
    --plots``), the same as :func:`lpm_figure` draws of it once stored in ``bla.h5``."""
    result = level.result
    stored = {"frequency": level.frequency, "G": level.G, "radius": level.bounds.radius, "var_G": level.var_G,
              "attrs": {"level": float("nan") if level.level is None else float(level.level),
                        "n_records": int(result.n_records), "n_samples": int(result.n_samples),
                        "half_width": int(result.half_width), "degree": int(result.degree), "dof": int(result.dof)}}
    return lpm_figure(stored, level.probability, units)
