"""Multi-input multi-output test systems, simulated independently of nlsid (scipy.signal.lfilter).

Every entry G_ia of a system is a discrete transfer function (b, a) from scipy's filter designs
(the book's Ex. 53 uses cheby1/butter filters for a 2x2 system). A record is the periodic input
repeated over ``transient + P`` periods and filtered from rest; the first periods are dropped, so
what is kept is the periodic steady state to within max|pole|^(transient N), which
:func:`transient_periods` makes smaller than 1e-16. The truth G(exp(j 2 pi k / N)) comes from
scipy.signal.freqz.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

#: Single-input single-output entries to build systems from (max |pole| 0.52 .. 0.95).
FILTERS = (
    scipy.signal.cheby1(2, 10, 0.2),
    scipy.signal.cheby1(2, 20, 0.5),
    scipy.signal.butter(4, 0.6),
    scipy.signal.cheby1(2, 15, 0.8),
    scipy.signal.butter(2, 0.3),
    scipy.signal.cheby1(3, 3, 0.4),
)


def system(n_outputs: int, n_inputs: int, offset: int = 0) -> list[list[tuple]]:
    """An n_y x n_u table of (b, a) filters taken in turn from :data:`FILTERS`."""
    return [[FILTERS[(offset + i * n_inputs + a) % len(FILTERS)] for a in range(n_inputs)] for i in range(n_outputs)]


def transient_periods(filters, period: int, floor: float = 1e-16) -> int:
    """Periods to drop so that the slowest pole has decayed below ``floor``."""
    radius = max(np.abs(np.roots(a)).max() for row in filters for _, a in row)
    return max(1, math.ceil(math.log(floor) / (period * math.log(radius))))


def truth(filters, bins: np.ndarray, period: int) -> np.ndarray:
    """G(exp(j 2 pi k / N)) at ``bins``, shape (F, n_y, n_u)."""
    w = 2 * np.pi * np.asarray(bins) / period
    return np.array([[scipy.signal.freqz(b, a, worN=w)[1] for b, a in row] for row in filters]).transpose(2, 0, 1)


def linear_outputs(filters, u_period: np.ndarray, n_periods: int) -> np.ndarray:
    """Steady-state outputs of the linear system: u_period (..., n_u, N) -> y (..., n_y, P, N)."""
    period = u_period.shape[-1]
    skip = transient_periods(filters, period)
    record = np.tile(u_period, skip + n_periods)
    outputs = []
    for row in filters:
        y = sum(scipy.signal.lfilter(b, a, record[..., r, :], axis=-1) for r, (b, a) in enumerate(row))
        outputs.append(y[..., skip * period:].reshape(y.shape[:-1] + (n_periods, period)))
    return np.stack(outputs, axis=-3)
