"""The exact ZOH step of x' = a x + b u, written independently of nlsid's simulator for the tests'
reference solutions."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def zoh(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(e^{a h}, int_0^h e^{a s} ds b) by the block exponential (Van Loan 1978)."""
    n = a.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n] = a * h, b * h
    e = expm(m)
    return e[:n, :n], e[:n, n]
