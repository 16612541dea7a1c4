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
