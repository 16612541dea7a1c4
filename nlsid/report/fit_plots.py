"""Figure of a transfer function fitted to a BLA (``nlsid fit --plot``): magnitude and phase of the
data and the model, the residual |G_BLA - G_model|, the model's standard deviation, and the noise and
nonlinear standard deviations of the averaged BLA (the weights' parts, book Ex 99 and 100).

matplotlib is imported inside the function so that importing this module stays cheap.
"""

from __future__ import annotations

import io

import numpy as np

from nlsid.report.axes import frequency_axis, legend_outside, phase_axis, wrapped_phase
from nlsid.report.units import Units
from nlsid.report.vector import fit_labels, new_figure


def _db(magnitude: np.ndarray) -> np.ndarray:
    magnitude = np.asarray(magnitude, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(magnitude > 0, 20 * np.log10(magnitude), np.nan)


def tf_fit_png(frequency: np.ndarray, data: np.ndarray, model: np.ndarray, model_std: np.ndarray,
               noise_std: np.ndarray, nl_std: np.ndarray, title: str, units: Units) -> bytes:
    """PNG bytes of the two-panel figure (dB magnitudes in the BLA's units; phase in degrees)."""
    figure, (magnitude, phase) = new_figure(2, height=3.2)
    magnitude.plot(frequency, _db(np.abs(data)), "k.", markersize=3, label="BLA")
    magnitude.plot(frequency, _db(np.abs(model)), color="tab:blue", linewidth=1.2, label="model")
    magnitude.plot(frequency, _db(np.abs(data - model)), "r.", markersize=2, label="|residual|")
    magnitude.plot(frequency, _db(model_std), color="tab:blue", linestyle=":", linewidth=1, label="model std")
    magnitude.plot(frequency, _db(noise_std), color="tab:green", linewidth=1, label="noise std")
    magnitude.plot(frequency, _db(nl_std), color="tab:orange", linewidth=1, label="nonlinear std")
    magnitude.set_ylabel(f"|G|, std ({units.ratio_db('y', 'u')})")
    magnitude.set_title(title)
    legend_outside(magnitude)
    phase.plot(*wrapped_phase(frequency, data), "k.", markersize=3, label="BLA")
    phase.plot(*wrapped_phase(frequency, model), color="tab:blue", linewidth=1.2, label="model")
    phase_axis(phase)
    for axis in (magnitude, phase):
        frequency_axis(axis, frequency)
    fit_labels(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()
