"""Figures of a diagnosis folder (matplotlib figures, off-screen; matplotlib imported lazily).

- ``model_vs_bla``: |G| and phase of the measured BLA with its 95% confidence circle's bounds and
  the model's BLA on the same lines; lines where the model lies outside the circle are marked.
- ``spectrum``: the measured output spectrum at the excited, odd and even lines, the model's at
  the same lines and the measured noise variance (seed 000 Fig. 3 with the model added).
- ``bla_vs_level``: |G_BLA| of every level, measured (solid) and model (dashed).
- ``residual_vs_state``: the mean residual period against the model's velocity and position
  (mechanical models, in the templates' SI units m and m/s) or its input: a jump at zero
  velocity, a cubic trend, a threshold.
- ``before_after``: one validation period's error of the original and of the extended model.

Axis labels carry the units of the recording (:class:`~nlsid.report.units.Units`).
"""

from __future__ import annotations

import numpy as np

from nlsid.analysis.lines import EVEN, EXCITED, ODD
from nlsid.report.axes import (above_floor, band_limits, frequency_axis, legend_outside, phase_axis,
                               wrapped_phase)
from nlsid.report.units import Units
from nlsid.report.vector import band, new_figure

#: units of the mechanical templates' internal signals (docs/configs.md: masses in kg, forces in N)
STATE_UNITS = {"position": "m", "velocity": "m/s"}


def _db(x: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return 10 * np.log10(np.asarray(x, dtype=float))


def _gain_db(G: np.ndarray) -> np.ndarray:
    """20 log10 |G|; a gain of exactly zero (a measured output that did not respond: the findings
    say so) is left out of the curve rather than drawn at -inf."""
    magnitude = np.abs(np.asarray(G))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(magnitude > 0, 20 * np.log10(magnitude), np.nan)


def _frequency_axes(frequency: np.ndarray, *axes) -> None:
    for axis in axes:
        frequency_axis(axis, frequency)


def model_vs_bla(level: dict, units: Units):
    figure, (mag, phase) = new_figure(2)
    f, G, Gm, radius = level["frequency"], level["G"], level["G_model"], level["radius"]
    lo = np.maximum(np.abs(G) - radius, np.abs(G) * 1e-3)
    band(mag, f, _gain_db(lo), _gain_db(np.abs(G) + radius), "BLA 95% bounds", color="C0", alpha=0.25)
    mag.plot(f, _gain_db(G), "C0.-", label="measured BLA")
    mag.plot(f, _gain_db(Gm), "C3--", label="model")
    out = level["outside"].astype(bool)
    mag.plot(f[out], _gain_db(G[out]), "kx", label="model outside bounds")
    mag.set_ylabel(f"|G| ({units.ratio_db('y', 'u')})")
    legend_outside(mag, fontsize=8)
    phase.plot(*wrapped_phase(f, G), "C0.-", label="measured BLA")
    phase.plot(*wrapped_phase(f, Gm), "C3--", label="model")
    phase_axis(phase)
    _frequency_axes(f, mag, phase)
    return figure


def spectrum(level: dict, units: Units):
    figure, (axis,) = new_figure(height=3.4)
    f, kind, band_ = level["frequency"], level["kind"], level["in_band"].astype(bool)
    for cls, style, name in ((EXCITED, "C0o", "excited"), (ODD, "C3s", "odd"), (EVEN, "C2^", "even")):
        k = kind == cls
        axis.plot(f[k], _db(level["y_power"][k]), style, ms=3.5, label=f"measured, {name}")
    k = kind >= 0
    measured = np.asarray(level["y_power"], dtype=float)[kind == EXCITED]
    reference = np.nanmax(measured) if np.isfinite(measured).any() else np.nan
    model, floor = above_floor(np.asarray(level["model_power"], dtype=float)[k], reference,
                               np.asarray(level["noise"], dtype=float)[k])
    axis.plot(f[k], _db(model), "k.", ms=2, alpha=0.6, label="model")
    if np.isfinite(floor) and np.any(np.asarray(level["model_power"])[k] < floor):
        # the model's lines under its round-off level are not data: one labelled line stands for them
        axis.axhline(_db(floor), color="k", lw=0.8, ls=":", label="model's numerical floor (lines below not drawn)")
    axis.plot(f[k], _db(level["noise"][k]), color="0.5", lw=1, label="noise variance")
    excited = f[kind == EXCITED]
    frequency_axis(axis, excited)
    if band_.any():
        axis.axvspan(f[band_].min(), f[band_].max(), color="C0", alpha=0.05)
    band_limits(axis, excited)
    axis.set_ylabel(f"output power ({units.power_db('y')})")
    legend_outside(axis, fontsize=8)
    return figure


def bla_vs_level(levels: list[dict], units: Units):
    figure, (axis,) = new_figure(height=3.2)
    for i, level in enumerate(levels):
        name = "-" if np.isnan(level["level"]) else f"{level['level']:g}"
        axis.plot(level["frequency"], _gain_db(level["G"]), f"C{i}-", label=f"measured, level {name}")
        axis.plot(level["frequency"], _gain_db(level["G_model"]), f"C{i}--", label=f"model, level {name}")
    axis.set_ylabel(f"|G| ({units.ratio_db('y', 'u')})")
    _frequency_axes(np.concatenate([level["frequency"] for level in levels]), axis)
    legend_outside(axis, fontsize=8)
    return figure


def residual_vs_state(time: dict, units: Units, signal: str = "y"):
    states = [name for name in ("velocity", "position", "input") if name in time]
    figure, axes = new_figure(1, len(states), height=3.2)
    for axis, name in zip(axes, states):
        axis.plot(time[name], time["residual"], ".", ms=2, alpha=0.5, label="residual")
        unit = units.unit("u") if name == "input" else STATE_UNITS[name]
        axis.set_xlabel(f"model {name} ({unit})")
        axis.set_ylabel(units.label(f"residual {signal} - {signal}_model", signal))  # signal: the judged one
        axis.grid(True, alpha=0.3)
    return figure


def before_after(validation: dict, units: Units, signal: str = "y"):
    figure, (axis,) = new_figure(height=3.0)
    t = np.arange(validation["original_error"].size) / float(validation["fs"])
    axis.plot(t, validation["original_error"], "C3", lw=1, label="original model")
    if "extended_error" in validation:
        axis.plot(t, validation["extended_error"], "C0", lw=1, label="extended model")
    axis.set_xlabel("time in the period (s)")
    axis.set_ylabel(units.label(f"error {signal} - {signal}_model", signal))
    axis.grid(True, alpha=0.3)
    legend_outside(axis, fontsize=8)
    return figure
