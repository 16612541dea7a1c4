"""The figure of a frequency response matrix (FRM): an n_y x n_u matrix of Bode plots with bounds.

Entry (i, a), from input a to output i, takes the column a of two rows of panels: the magnitude
``20 log10 |G_ia|`` with its confidence circle's magnitude bounds (``mag_lo``, ``mag_hi``, on the
total variance over the realizations: noise and stochastic nonlinear distortion) and the standard
deviations of the estimate from the noise and from noise plus nonlinear distortion, in dB re one
unit of the output per unit of the input; below it the phase, wrapped to +-180 degrees, with the
same circle's phase bounds. Schoukens, Pintelon and Rolain 2012, Section 3.8 and Eqs. 6-117, 6-88;
``docs/mimo.md``.

The figure is drawn from a ``/frm_levels/level_NN`` group as :func:`nlsid.io.bla_file.read_bla`
returns it, or from a ``/frm_lpm_levels/level_NN`` group (arbitrary runs, the Local Polynomial
Method for several inputs): there the one standard deviation, from ``var_G``, holds noise and
nonlinear distortion together (they cannot be told apart without periodic excitation), and the
bounds are the F(2, 2q) circles of the LPM. matplotlib is imported inside the functions so that
importing this module stays cheap.
"""

from __future__ import annotations

import numpy as np

from nlsid.report.axes import frequency_axis, phase_axis, power_db, wrapped_band, wrapped_phase
from nlsid.report.units import Units
from nlsid.report.vector import band, new_figure

#: inches per row of panels (a magnitude or a phase row)
ROW_HEIGHT = 1.9


def entry_title(inputs: list[str], outputs: list[str], i: int, a: int) -> str:
    """``from u to y``: the entry (i, a) of G by the recording's names."""
    return f"from {inputs[a]} to {outputs[i]}"


def std_curves(stored: dict) -> list[tuple[np.ndarray, str, str, str]]:
    """The standard deviations a level's magnitude panels draw: (F, n_y, n_u) values, line style,
    colour and label; total and noise for a multisine level, the LPM's one for arbitrary runs."""
    if "var_G" in stored:
        return [(np.sqrt(stored["var_G"]), "--", "tab:red", "std (noise + nonlinear, LPM)")]
    return [(stored["std_total"], "--", "tab:red", "std total (noise + nonlinear)"),
            (stored["std_noise"], ":", "tab:green", "std noise")]


def frm_figure(stored: dict, units: Units, name: str, model: np.ndarray | None = None):
    """The n_y x n_u Bode plots of one FRM level, of multisine or of arbitrary runs (module
    docstring); ``name`` titles the figure.

    ``model`` (F, n_y, n_u), a fitted model's FRM at the level's lines (``nlsid fit --plot``), adds
    per entry the model's magnitude and phase and the residual ``|G_model - G|`` in the magnitude
    panel, where it stands against the standard deviations: a model within its cost bound leaves a
    residual at or below the standard deviation of the estimate."""
    attrs = stored["attrs"]
    inputs, outputs = list(attrs["inputs"]), list(attrs["outputs"])
    n_y, n_u = len(outputs), len(inputs)
    probability = float(attrs["confidence"])
    figure, axes = new_figure(2 * n_y, n_u, width=8.0, height=ROW_HEIGHT)
    f, G = stored["frequency"], stored["G"]
    bounds = stored["bounds"]
    for i in range(n_y):
        for a in range(n_u):
            magnitude, phase = axes[2 * i * n_u + a], axes[(2 * i + 1) * n_u + a]
            magnitude.plot(f, power_db(np.abs(G[:, i, a]) ** 2), color="k", label="|G|")
            if model is not None:
                magnitude.plot(f, power_db(np.abs(model[:, i, a]) ** 2), color="tab:blue", label="|G model|")
                magnitude.plot(f, power_db(np.abs(model[:, i, a] - G[:, i, a]) ** 2), "-.", color="tab:orange",
                               label="|G model - G|")
            band(magnitude, f, power_db(bounds["mag_lo"][:, i, a] ** 2), power_db(bounds["mag_hi"][:, i, a] ** 2),
                 f"{probability:.0%} bounds", color="k", alpha=0.15)
            for std, style, colour, label in std_curves(stored):
                magnitude.plot(f, power_db(std[:, i, a] ** 2), style, color=colour, label=label)
            # the entry in the labels too: they head the figure's CSV columns, one per panel
            entry = f"{inputs[a]} to {outputs[i]}"
            magnitude.set_ylabel(f"{entry}: |G|, std ({units.ratio_db(outputs[i], inputs[a])})")
            magnitude.set_title(entry_title(inputs, outputs, i, a), fontsize=9)
            phase.plot(*wrapped_phase(f, G[:, i, a]), color="k", label="phase of G")
            if model is not None:
                phase.plot(*wrapped_phase(f, model[:, i, a]), color="tab:blue", label="phase of G model")
            band(phase, *wrapped_band(f, G[:, i, a], bounds["phase_lo"][:, i, a], bounds["phase_hi"][:, i, a]),
                 f"{probability:.0%} bounds", color="k", alpha=0.15)
            phase_axis(phase)
            phase.set_ylabel(f"{entry}: phase (deg)")
            for axis in (magnitude, phase):
                frequency_axis(axis, f)
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", ncols=min(4, len(labels)), fontsize="small")
    figure.suptitle(f"Frequency response matrix: {name}", fontsize=10)
    return figure
