"""Figures of a diagnosis folder (PNG bytes, matplotlib's off-screen Figure; imported lazily).

- ``model_vs_bla``: |G| and phase of the measured BLA with its 95% confidence circle's bounds and
  the model's BLA on the same lines; lines where the model lies outside the circle are marked.
- ``spectrum``: the measured output spectrum at the excited, odd and even lines, the model's at
  the same lines and the measured noise variance (seed 000 Fig. 3 with the model added).
- ``bla_vs_level``: |G_BLA| of every level, measured (solid) and model (dashed).
- ``residual_vs_state``: the mean residual period against the model's velocity and position
  (mechanical models) or its input: a jump at zero velocity, a cubic trend, a threshold.
- ``before_after``: one validation period's error of the original and of the extended model.
"""

from __future__ import annotations

import numpy as np

from nlsid.analysis.lines import EVEN, EXCITED, ODD
from nlsid.report.axes import plain_log_ticks, unwrapped_phase
from nlsid.report.html import png


def _figure(rows: int = 1, cols: int = 1, height: float = 3.0):
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8, height * rows), layout="constrained")
    return figure, [figure.add_subplot(rows, cols, i + 1) for i in range(rows * cols)]


def _db(x: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return 10 * np.log10(np.asarray(x, dtype=float))


def model_vs_bla(level: dict) -> bytes:
    figure, (mag, phase) = _figure(2)
    f, G, Gm, radius = level["frequency"], level["G"], level["G_model"], level["radius"]
    lo = np.maximum(np.abs(G) - radius, np.abs(G) * 1e-3)
    mag.fill_between(f, 20 * np.log10(lo), 20 * np.log10(np.abs(G) + radius), color="C0", alpha=0.25,
                     label="BLA 95% bounds")
    mag.plot(f, 20 * np.log10(np.abs(G)), "C0.-", label="measured BLA")
    mag.plot(f, 20 * np.log10(np.abs(Gm)), "C3--", label="model")
    out = level["outside"].astype(bool)
    mag.plot(f[out], 20 * np.log10(np.abs(G[out])), "kx", label="model outside bounds")
    mag.set_ylabel("|G| (dB)")
    mag.legend(fontsize=8)
    phase.plot(f, unwrapped_phase(G)[0], "C0.-")
    phase.plot(f, unwrapped_phase(Gm)[0], "C3--")
    phase.set_ylabel("phase (deg)")
    phase.set_xlabel("frequency (Hz)")
    for axis in (mag, phase):
        axis.set_xscale("log")
        axis.grid(True, alpha=0.3)
        plain_log_ticks(axis.xaxis)
    return png(figure)


def spectrum(level: dict) -> bytes:
    figure, (axis,) = _figure(height=3.4)
    f, kind, band = level["frequency"], level["kind"], level["in_band"].astype(bool)
    for cls, style, name in ((EXCITED, "C0o", "excited"), (ODD, "C3s", "odd"), (EVEN, "C2^", "even")):
        k = kind == cls
        axis.plot(f[k], _db(level["y_power"][k]), style, ms=3.5, label=f"measured, {name}")
    k = kind >= 0
    axis.plot(f[k], _db(level["model_power"][k]), "k.", ms=2, alpha=0.6, label="model")
    axis.plot(f[k], _db(level["noise"][k]), color="0.5", lw=1, label="noise variance")
    if band.any():
        axis.axvspan(f[band].min(), f[band].max(), color="C0", alpha=0.05)
    axis.set_xlabel("frequency (Hz)")
    axis.set_ylabel("power (dB)")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8, ncol=3)
    return png(figure)


def bla_vs_level(levels: list[dict]) -> bytes:
    figure, (axis,) = _figure(height=3.2)
    for i, level in enumerate(levels):
        name = "-" if np.isnan(level["level"]) else f"{level['level']:g}"
        axis.plot(level["frequency"], 20 * np.log10(np.abs(level["G"])), f"C{i}-", label=f"measured, level {name}")
        axis.plot(level["frequency"], 20 * np.log10(np.abs(level["G_model"])), f"C{i}--", label=f"model, level {name}")
    axis.set_xscale("log")
    plain_log_ticks(axis.xaxis)
    axis.set_xlabel("frequency (Hz)")
    axis.set_ylabel("|G| (dB)")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8, ncol=2)
    return png(figure)


def residual_vs_state(time: dict) -> bytes:
    states = [name for name in ("velocity", "position", "input") if name in time]
    figure, axes = _figure(1, len(states), height=3.2)
    for axis, name in zip(axes, states):
        axis.plot(time[name], time["residual"], ".", ms=2, alpha=0.5)
        axis.set_xlabel(f"model {name}")
        axis.grid(True, alpha=0.3)
    axes[0].set_ylabel("residual y - y_model")
    return png(figure)


def before_after(validation: dict) -> bytes:
    figure, (axis,) = _figure(height=3.0)
    t = np.arange(validation["original_error"].size) / float(validation["fs"])
    axis.plot(t, validation["original_error"], "C3", lw=1, label="original model")
    if "extended_error" in validation:
        axis.plot(t, validation["extended_error"], "C0", lw=1, label="extended model")
    axis.set_xlabel("time in the period (s)")
    axis.set_ylabel("error y - y_model")
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=8)
    return png(figure)
