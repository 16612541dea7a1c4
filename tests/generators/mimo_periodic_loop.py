"""The 2x2 plant of ``generators.mimo_loop`` in its closed loop, driven by orthogonal multisine
references, simulated sample by sample independently of nlsid's simulator into the periodic steady state.

The plant (order 3, truth C (zI - A)^-1 B) is under the diagonal proportional controller
u = r - K y, run from rest over TRANSIENT periods (closed-loop poles of modulus <= 0.58: after two
periods of 64 samples the transient is below 1e-30). The references r are orthogonal random
multisines (nlsid's design, Hadamard pairs) on the lines 1..31 of N = 64 samples. The output noise
v, coloured by a first-order filter, enters the loop, so the controller feeds it into u. The
measured u and y carry offsets (DC, not an excited line).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from generators.mimo_loop import A, B, C, K
from nlsid.signals.orthogonal_multisine import orthogonal_multisine

N, BINS, P, TRANSIENT = 64, np.arange(1, 32), 2, 2


def closed_loop(r: np.ndarray, sigma: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """u, y (..., 2, P, N) of the loop driven by the periods r (..., 2, N), from rest, with the
    TRANSIENT periods dropped; output noise of std ``sigma`` through 0.8 / (1 - 0.5 z^-1), offsets added."""
    drive = np.tile(r, TRANSIENT + P)
    v = sigma * signal.lfilter([0.8], [1.0, -0.5], rng.standard_normal(drive.shape), axis=-1)
    x = np.zeros(drive.shape[:-2] + (3,))
    u, y = np.empty_like(drive), np.empty_like(drive)
    for k in range(drive.shape[-1]):
        y[..., k] = x @ C.T + v[..., k]
        u[..., k] = drive[..., k] - y[..., k] @ K.T
        x = x @ A.T + u[..., k] @ B.T

    def steady(x_: np.ndarray) -> np.ndarray:
        return x_[..., TRANSIENT * N:].reshape(x_.shape[:-1] + (P, N))

    return steady(u) + 0.3, steady(y) - 0.2


def references(rng, shape: tuple[int, ...], designs: int) -> np.ndarray:
    """``shape`` realizations of ``designs`` orthogonal pairs as experiments: (*shape, 2 designs, 2, N)."""
    count = int(np.prod(shape))
    r = np.array([np.concatenate([orthogonal_multisine(N, BINS, 2, rng=rng).signals() for _ in range(designs)])
                  for _ in range(count)])
    return r.reshape(shape + r.shape[1:])


def periods(r: np.ndarray) -> np.ndarray:
    """One period (..., N) repeated as the P steady-state periods (..., P, N)."""
    return np.broadcast_to(r[..., None, :], r.shape[:-1] + (P, N))
