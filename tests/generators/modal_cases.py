"""A structure of six modes with a cubic spring on one modal coordinate, measured with multisines
at several levels, written independently of nlsid's simulator.

Modal superposition (unit modal input participation, the output's participation in ``SHAPE``):

    q_i'' + 2 zeta_i w_i q_i' + w_i^2 q_i + k3_i q_i^3 + c3_i q_i'^3 = u,   y = sum_i SHAPE_i q_i,

u held over each sample (zero-order hold), from rest. The linear modes are stepped exactly
(the block exponential of Van Loan 1978, tests/generators/exact_zoh.py); the mode with a cubic
spring or damper (k3 or c3 != 0) by the classical Runge-Kutta method with ``substeps`` steps per
sample, all runs at once (:func:`response`; the caller checks the step by halving it).

The excitation (:func:`recording`): random-odd multisines (odd lines up to MAX_HZ of an N-sample
period at FS, one in three dropped at random as a detection line, the same grid in every
recording: the BLAs of all levels are compared on the lines excited at every level) at the given
rms levels, one transient period and two steady ones, two realizations a level. The recorded
output carries what a real measurement adds: a sensor offset, coloured noise (white noise through
0.6 / (1 - 0.8 z^-1), standard deviation ``noise``) and a mains line (a 50 Hz sine of amplitude
MAINS, on an unexcited even line).

The user's model (:func:`user_model`): the linear part with every mode's w^2, 2 zeta w and output
coefficient OFF off (alternating signs), in random orthogonal coordinates, as its exact ZOH
equivalent: a discrete ``state_space`` in no particular basis, as a fit from the BLA gives it.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter, ss2tf

from generators.exact_zoh import zoh
from nlsid.io.run import Run
from nlsid.signals.lines import random_grid
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize

FS, N = 256.0, 1024
MAX_HZ = 72.0
FREQUENCIES_HZ = np.array([7.5, 13.0, 21.0, 30.5, 42.0, 55.0])
DAMPING = np.array([0.03, 0.025, 0.03, 0.02, 0.025, 0.02])
SHAPE = np.array([1.0, -0.9, 1.2, 0.7, -0.6, 0.5])
MOVING = 2  # the mode with the cubic spring (21 Hz)
PERIODS, TRANSIENT = 2, 1
LEVELS, HELD_OUT = (0.25, 0.5, 0.75, 1.0), (0.375, 0.875)  # rms of u: the recording's, the held-out
NOISE = 1e-6  # coloured noise std: -57 dB of the highest level's output, -45 dB of the lowest's
OFFSET = 2e-4
MAINS = 6e-7
GRID_SEED = 7  # the excited lines' random grid (commands)
OFF = 0.03  # the user's model: every coefficient of the linear part off by this (user_model)


def omega() -> np.ndarray:
    return 2 * np.pi * FREQUENCIES_HZ


def response(U: np.ndarray, k3: float, substeps: int, c3: float = 0.0) -> np.ndarray:
    """The output of every run (rows of U) of the six modes with the cubic spring k3 and the cubic
    damper c3 on mode MOVING."""
    T = 1.0 / FS
    w, z = omega(), DAMPING
    y = np.zeros(U.shape, float)
    for i in range(w.size):
        a = np.array([[0.0, 1.0], [-w[i] ** 2, -2 * z[i] * w[i]]])
        if i != MOVING or k3 == c3 == 0:
            # x[k+1] = Phi x[k] + Gamma u[k], q[k] = x1[k]: q = (1, 0) (zI - Phi)^-1 Gamma u, run by lfilter
            Phi, Gamma = zoh(a, np.array([0.0, 1.0]), T)
            b, den = ss2tf(Phi, Gamma[:, None], np.array([[1.0, 0.0]]), np.zeros((1, 1)))
            q = lfilter(np.ravel(b), den, U, axis=1)
        else:
            q = _cubic_mode(U, w[i], z[i], k3, c3, T, substeps)
        y += SHAPE[i] * q
    return y


def _cubic_mode(U: np.ndarray, w: float, z: float, k3: float, c3: float, T: float, substeps: int) -> np.ndarray:
    """q'' + 2 z w q' + w^2 q + k3 q^3 + c3 q'^3 = u by RK4, u held over the sample; q sampled at k T."""
    h = T / substeps

    def rates(p, v, u):
        return v, u - 2 * z * w * v - w * w * p - k3 * p**3 - c3 * v**3

    p = np.zeros(U.shape[0])
    v = np.zeros(U.shape[0])
    q = np.zeros(U.shape)
    for k in range(U.shape[1]):
        q[:, k] = p
        u = U[:, k]
        for _ in range(substeps):
            k1p, k1v = rates(p, v, u)
            k2p, k2v = rates(p + h / 2 * k1p, v + h / 2 * k1v, u)
            k3p, k3v = rates(p + h / 2 * k2p, v + h / 2 * k2v, u)
            k4p, k4v = rates(p + h * k3p, v + h * k3v, u)
            p = p + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
            v = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return q


def blocks(off: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The six linear modes' block-diagonal (A, B, C), states (q_i, q_i'), each mode's w^2,
    2 zeta w and output coefficient off by +-``off`` (alternating signs)."""
    w, z, n = omega(), DAMPING, 2 * FREQUENCIES_HZ.size
    sign = np.array([1, -1, 1, -1, 1, -1])
    A, B, C = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    for i in range(FREQUENCIES_HZ.size):
        j = 2 * i
        A[j, j + 1] = 1.0
        A[j + 1, j] = -w[i] ** 2 * (1 + off * sign[i])
        A[j + 1, j + 1] = -2 * z[i] * w[i] * (1 - off * sign[i])
        B[j + 1] = 1.0
        C[j] = SHAPE[i] * (1 + off * sign[i])
    return A, B, C


def user_model(off: float = OFF, seed: int = 5) -> dict:
    """The linear part ``off`` off in random orthogonal coordinates, as its ZOH equivalent at FS: a
    discrete ``state_space`` as a fit from the BLA gives a model, in no particular basis."""
    A, B, C = blocks(off)
    Q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal(A.shape))
    Phi, Gamma = zoh(Q.T @ A @ Q, Q.T @ B, 1 / FS)
    return {"model": {"type": "state_space", "domain": "discrete", "A": Phi.tolist(), "B": Gamma.tolist(),
                      "C": (C @ Q).tolist(), "D": 0.0}}


def commands(seed: int, levels: tuple[float, ...], realizations: int) -> tuple[list[tuple], np.ndarray]:
    """(level, realization, u) of every run and the excited bins: one design (the grid of GRID_SEED,
    the same for every recording, as one experiment's multisines share it), the phases of ``seed``."""
    lines = np.arange(1, int(MAX_HZ * N / FS), 2)
    bins, _ = random_grid(lines, 3, np.random.default_rng(GRID_SEED))
    rng = np.random.default_rng(seed)
    out = [(level, m, np.tile(synthesize(N, bins, flat_amplitudes(bins.size, level), random_phases(bins.size, rng)),
                              PERIODS + TRANSIENT))
           for level in levels for m in range(realizations)]
    return out, bins


def recording(seed: int, levels: tuple[float, ...], realizations: int, outputs, noise: float,
              prefix: str = "r") -> list[Run]:
    """The runs: the commands through ``outputs`` (U -> Y, the true structure), plus the offset,
    coloured noise of std ``noise`` and the mains line."""
    runs_in, bins = commands(seed, levels, realizations)
    Y = outputs(np.stack([u for _, _, u in runs_in]))
    rng = np.random.default_rng(seed + 1000)
    t = np.arange(Y.shape[1]) / FS
    runs = []
    for i, ((level, m, u), y) in enumerate(zip(runs_in, Y)):
        coloured = lfilter([0.6], [1.0, -0.8], rng.standard_normal(y.size))
        coloured *= noise / np.std(coloured)
        mains = MAINS * np.sin(2 * np.pi * 50.0 * t + rng.uniform(0, 2 * np.pi))
        runs.append(Run(f"{prefix}{i}", FS, "multisine", u, y=y + coloured + mains + OFFSET, period=N,
                        transient_periods=TRANSIENT, realization=m, level=level, excited_bins=bins))
    return runs
