"""Axis conventions shared by the report's figures: phase without 360-degree jumps, log axes with
plain-number tick labels."""

from __future__ import annotations

import numpy as np


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
    powers of ten; while it spans less than a decade the minor ticks (2, 3, 4, ...) are labelled
    too, so that a narrow range such as rms levels 1 .. 4 still shows numbers."""
    from matplotlib.ticker import FuncFormatter, NullFormatter

    label = FuncFormatter(lambda value, _: f"{value:g}")
    axis.set_major_formatter(label)
    low, high = sorted(axis.get_view_interval())
    axis.set_minor_formatter(label if 0 < low and high < 10 * low else NullFormatter())
