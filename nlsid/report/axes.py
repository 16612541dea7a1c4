"""Axis conventions shared by the report's figures: phase without 360-degree jumps, log axes with
plain-number tick labels."""

from __future__ import annotations

import math

import numpy as np

FEW_DECADES = 2.5
FIGURE_HEIGHT = 3.2  # inches per row of the BLA and LPM figures


def unwrapped_phase(G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The phase of G along its (frequency) axis in degrees without 360-degree jumps, and the
    shift in radians added to ``np.angle(G)`` (for bounds computed around the wrapped phase).
    Lines with a non-finite G keep NaN and do not break the unwrapping of the others."""
    wrapped = np.angle(G)
    unwrapped = wrapped.copy()
    finite = np.isfinite(wrapped)
    unwrapped[finite] = np.unwrap(wrapped[finite])
    return np.degrees(unwrapped), unwrapped - wrapped


def plain_log_ticks(axis) -> None:
    """Label a log-scaled axis (``ax.xaxis`` or ``ax.yaxis``) with plain numbers (0.5, 2, 100), not
    powers of ten, and with enough of them: while it spans less than a decade every minor tick
    (2, 3, 4, ...) is labelled, while it spans less than :data:`FEW_DECADES` the minor ticks at 2
    and 5 times a power of ten, so that 1.5 to 60 Hz reads 2, 5, 10, 20, 50 rather than a lone 10.
    The span is judged when the axis is drawn, after every curve is in."""
    from matplotlib.ticker import FuncFormatter

    def minor(value: float, _) -> str:
        low, high = sorted(axis.get_view_interval())
        decades = math.log10(high / low) if low > 0 else math.inf
        mantissa = round(value / 10 ** math.floor(math.log10(value)), 6) if value > 0 else 0.0
        return f"{value:g}" if decades < 1 or (decades < FEW_DECADES and mantissa in (2.0, 5.0)) else ""

    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    axis.set_minor_formatter(FuncFormatter(minor))


def power_db(power: np.ndarray) -> np.ndarray:
    """10 log10 of a power (or variance), NaN where it is not positive (no point drawn there)."""
    power = np.asarray(power, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(power > 0, 10 * np.log10(power), np.nan)


PHASE_LIMITS = (-180.0, 180.0)
#: a band spanning this ratio of its highest to its lowest frequency (a decade) is drawn on a log axis
LOG_SPAN = 10.0
#: a model's power below this fraction of the measured signal's largest line power is its numerical
#: floor (round-off of the simulation, 90 dB down), not a level the model predicts
NUMERICAL_FLOOR = 1e-9
#: the margin around the excited band on a spectrum's frequency axis (a factor on a log axis)
BAND_MARGIN = 1.5


def wrapped_phase(frequency: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The phase of G in degrees wrapped to [-180, 180], as (frequency, degrees) to plot: where two
    neighbouring lines differ by more than 180 degrees (the wrap, or noise where the estimate is not
    coherent) a NaN point is put between them, so the curve breaks there instead of drawing a
    vertical stroke across the panel. Unlike :func:`unwrapped_phase`, noise cannot accumulate into
    thousands of degrees that flatten the coherent part of the curve."""
    frequency = np.asarray(frequency, dtype=float)
    degrees = np.degrees(np.angle(np.asarray(G)))
    degrees = np.where(degrees <= -180.0, 180.0, degrees)
    jumps = np.flatnonzero(np.abs(np.diff(degrees)) > 180.0) + 1
    return np.insert(frequency, jumps, np.nan), np.insert(degrees, jumps, np.nan)


def wrapped_band(frequency: np.ndarray, G: np.ndarray, low: np.ndarray, high: np.ndarray):
    """Bounds of the phase (``low`` and ``high`` in radians, around ``np.angle(G)``) in degrees,
    as (frequency, low, high) broken by NaN where :func:`wrapped_phase` breaks the curve, so that no
    band is drawn across the panel at a wrap."""
    frequency = np.asarray(frequency, dtype=float)
    degrees = np.degrees(np.angle(np.asarray(G)))
    shift = np.where(degrees <= -180.0, 360.0, 0.0)  # as wrapped_phase moves -180 to +180
    degrees = degrees + shift
    jumps = np.flatnonzero(np.abs(np.diff(degrees)) > 180.0) + 1
    low, high = np.degrees(np.asarray(low)) + shift, np.degrees(np.asarray(high)) + shift
    return (np.insert(frequency, jumps, np.nan), np.insert(low, jumps, np.nan), np.insert(high, jumps, np.nan))


def phase_axis(axis) -> None:
    """A phase panel in degrees held to [-180, 180] with ticks every 90 degrees."""
    axis.set_ylim(*PHASE_LIMITS)
    axis.set_yticks([-180, -90, 0, 90, 180])
    axis.set_ylabel("phase (deg)")


def spans_decades(frequency: np.ndarray) -> bool:
    """True when the positive, finite frequencies span a decade or more (:data:`LOG_SPAN`)."""
    f = np.asarray(frequency, dtype=float)
    f = f[np.isfinite(f)]
    return bool(f.size and f.min() > 0 and f.max() / f.min() >= LOG_SPAN)


def frequency_axis(axis, frequency: np.ndarray) -> None:
    """Label ``axis``' x axis as frequency in Hz, on a log scale with plain tick labels when
    ``frequency`` spans a decade or more, with a grid at every tick."""
    axis.set_xlabel("frequency (Hz)")
    if spans_decades(frequency):
        axis.set_xscale("log")
        plain_log_ticks(axis.xaxis)
    axis.grid(True, which="both", alpha=0.3)


def band_limits(axis, band: np.ndarray) -> None:
    """Hold the frequency axis to the excited ``band`` plus a margin: a factor :data:`BAND_MARGIN`
    either side on a log axis, half the band's width either side on a linear one (not 0 to fs/2,
    where a band of 1.5-60 Hz in 512 Hz fills the left eighth)."""
    band = np.asarray(band, dtype=float)
    band = band[np.isfinite(band) & (band > 0)]
    if not band.size:
        return
    low, high = band.min(), band.max()
    if axis.get_xscale() == "log":
        axis.set_xlim(low / BAND_MARGIN, high * BAND_MARGIN)
    else:
        margin = 0.5 * (high - low) or 0.5 * high
        axis.set_xlim(max(low - margin, 0.0), high + margin)


#: a model line this far under the lowest measured noise variance (30 dB) could not be seen in any data
BELOW_NOISE = 1e-3


def above_floor(power: np.ndarray, reference: float, noise: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """``power`` with NaN where it lies below the numerical floor, and that floor: :data:`NUMERICAL_FLOOR`
    times ``reference`` (the measured signal's largest line power), or, when lower, :data:`BELOW_NOISE`
    times the lowest positive ``noise`` variance (data of more than 90 dB range keep every line
    they could show). A model line at -200 dB is the simulation's round-off, not a prediction: it is
    not drawn as data."""
    power = np.asarray(power, dtype=float)
    floor = NUMERICAL_FLOOR * float(reference)
    if noise is not None:
        noise = np.asarray(noise, dtype=float)
        positive = noise[np.isfinite(noise) & (noise > 0)]
        if positive.size:
            floor = min(floor, BELOW_NOISE * float(positive.min()))
    with np.errstate(invalid="ignore"):
        return np.where(power >= floor, power, np.nan), floor


def legend_outside(axis, **style):
    """The legend of ``axis`` beside it, right of the panel, where it hides no data point."""
    style.setdefault("fontsize", "small")
    return axis.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **style)
