"""Nonlinear blocks of block-structured models: static maps and the backlash (play) operator.

Static maps y = f(x), applied sample by sample:

* ``polynomial``: y = sum_p a_p x^p, p = 0 .. P (seed 002, Eq. 1, with an optional a_0).
* ``saturation``: y = min(max(x, lower), upper).
* ``deadzone``: y = x - upper for x > upper, x - lower for x < lower, 0 in between.
* ``piecewise_linear``: straight lines through the points (x_i, y_i), continued beyond the first and
  last point by the first and last segment.

``backlash`` is a block with memory (the play operator of width w): the output stays where it is
while |x - y| <= w/2 and otherwise is dragged along, y[k] = x[k] -+ w/2. It starts at y = 0
(the play centred on the first input when |x[0]| <= w/2).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numba import njit


def static_map(config) -> Callable[[np.ndarray], np.ndarray]:
    """The block of ``config`` (a block config from :mod:`nlsid.io.model_config`) as a function of arrays."""
    kind = config.type
    if kind == "polynomial":
        coefficients = np.asarray(config.coefficients, dtype=float)
        return lambda x: np.polynomial.polynomial.polyval(x, coefficients)
    if kind == "saturation":
        return lambda x: np.clip(x, config.lower, config.upper)
    if kind == "deadzone":
        return lambda x: np.where(x > config.upper, x - config.upper, np.where(x < config.lower, x - config.lower, 0.0))
    if kind == "piecewise_linear":
        return _piecewise_linear(np.asarray(config.x, dtype=float), np.asarray(config.y, dtype=float))
    if kind == "backlash":
        return lambda x: play(np.ascontiguousarray(x, dtype=float), 0.5 * config.width)
    raise ValueError(f"unknown block type {kind!r}")


def _piecewise_linear(xp: np.ndarray, yp: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    slope_lo = (yp[1] - yp[0]) / (xp[1] - xp[0])
    slope_hi = (yp[-1] - yp[-2]) / (xp[-1] - xp[-2])

    def apply(x: np.ndarray) -> np.ndarray:
        y = np.interp(x, xp, yp)
        y = np.where(x < xp[0], yp[0] + slope_lo * (x - xp[0]), y)
        return np.where(x > xp[-1], yp[-1] + slope_hi * (x - xp[-1]), y)

    return apply


@njit(cache=True, nogil=True)
def play(x: np.ndarray, half_width: float) -> np.ndarray:
    """The play (backlash) operator with half width ``half_width``, starting from y = 0."""
    y = np.empty_like(x)
    out = 0.0
    for k in range(x.shape[0]):
        if x[k] - out > half_width:
            out = x[k] - half_width
        elif out - x[k] > half_width:
            out = x[k] + half_width
        y[k] = out
    return y
