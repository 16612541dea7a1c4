"""The 2x2 discrete state-space plant of the MIMO diagnosis tests, run by a plain loop written
here (independent of nlsid's simulator): x[k+1] = A x[k] + B u[k], y[k] = C x[k], from rest.
:data:`CONFIG` is the same plant as a ``mimo_state_space`` model config (inputs u, u2; outputs y, y2)."""

from __future__ import annotations

import numpy as np

A = np.array([[0.6, 0.2], [-0.3, 0.5]])
B = np.array([[1.0, 0.3], [0.2, 0.8]])
C = np.array([[1.0, 0.0], [0.4, 1.0]])
CONFIG = {"model": {"type": "mimo_state_space", "domain": "discrete", "fs": 100.0, "A": A.tolist(),
                    "B": B.tolist(), "C": C.tolist()}}


def loop(U: np.ndarray) -> np.ndarray:
    """The outputs (2, n) of the plant driven by U (2, n) from rest."""
    x, Y = np.zeros(2), np.empty((2, U.shape[1]))
    for k in range(U.shape[1]):
        Y[:, k] = C @ x
        x = A @ x + B @ U[:, k]
    return Y
