"""A 2x2 plant in a closed loop, simulated sample by sample independently of nlsid's simulator.

The plant is discrete, of order 3 (x[k+1] = A x[k] + B u[k], y[k] = C x[k] + v[k]), under a
diagonal proportional controller u[k] = r[k] - K y[k], with two independent white-noise
references r. The output noise v is coloured (first-order lfilter) and enters the loop: the
controller feeds it back into u, so u is correlated with the disturbance. The records start from
a random state (a transient), and the measured u and y carry offsets (DC, a line the LPM does not
use). The truth is G(z) = C (zI - A)^-1 B at z = exp(j 2 pi k / N).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

A = np.array([[0.7, 0.2, 0.0], [-0.2, 0.7, 0.0], [0.0, 0.0, 0.5]])
B = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 1.0]])
C = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 1.0]])
K = np.diag([0.6, 0.5])            # closed-loop poles of modulus <= 0.58: a stable, well damped loop
SIGMA = 1.0                         # output noise std, the references': the loop feeds much of it back
M, N = 4, 4096


def closed_loop(rng, records: int = M, samples: int = N,
                sigma: float = SIGMA) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r, u, y (records, 2, samples) of the loop (module docstring), output noise std ``sigma``."""
    r = rng.standard_normal((records, 2, samples))
    v = sigma * signal.lfilter([1.0], [1.0, -0.5], rng.standard_normal((records, 2, samples)), axis=-1)
    x = rng.standard_normal((records, 3))
    u, y = np.empty((records, 2, samples)), np.empty((records, 2, samples))
    for k in range(samples):
        y[:, :, k] = x @ C.T + v[:, :, k]
        u[:, :, k] = r[:, :, k] - y[:, :, k] @ K.T
        x = x @ A.T + u[:, :, k] @ B.T
    return r, u + 0.3, y - 0.2


def truth(frequencies: np.ndarray) -> np.ndarray:
    """G at ``frequencies`` in cycles per sample, shape (F, 2, 2)."""
    return np.array([C @ np.linalg.solve(z * np.eye(3) - A, B) for z in np.exp(2j * np.pi * frequencies)])
