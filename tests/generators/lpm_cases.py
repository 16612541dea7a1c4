"""Test material for the LPM and arbitrary-excitation BLA tests, made without nlsid's simulator.

A continuous-time resonance discretised exactly for a zero-order-hold input (matrix exponential),
its output sampled a fraction of a sample late (converter skew), DC offsets on both channels,
coloured output noise, a random start state (a transient), band-limited noise excitation that is
not periodic; and a proportional loop around it with a one-sample computation delay. The FRF of
the sampled system is known in closed form (``true_frf``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal

FS = 1000.0
N = 4096
SKEW = 0.37          # the output is sampled 0.37 samples after the input is updated
WN, ZETA = 2 * np.pi * 50.0, 0.2
A_C = np.array([[0.0, 1.0], [-WN ** 2, -2 * ZETA * WN]])
B_C = np.array([[0.0], [WN ** 2]])
C_C = np.array([[1.0, 0.0]])


def zoh(tau: float) -> tuple[np.ndarray, np.ndarray]:
    """exp(A tau) and int_0^tau exp(A s) ds B, from the exponential of the augmented matrix."""
    aug = np.zeros((3, 3))
    aug[:2, :2], aug[:2, 2:] = A_C, B_C
    e = linalg.expm(aug * tau)
    return e[:2, :2], e[:2, 2:]


PHI, GAMMA = zoh(1 / FS)
PHI_SKEW, GAMMA_SKEW = zoh(SKEW / FS)


def true_frf(lines: np.ndarray) -> np.ndarray:
    """y[k] = C x(t_k + skew) with x(t_k + skew) = Phi_skew x[k] + Gamma_skew u[k]:
    G(z) = C (Phi_skew (zI - Phi)^-1 Gamma + Gamma_skew)."""
    z = np.exp(2j * np.pi * lines / N)
    out = np.empty(lines.size, dtype=complex)
    for i, zi in enumerate(z):
        out[i] = (C_C @ (PHI_SKEW @ np.linalg.solve(zi * np.eye(2) - PHI, GAMMA) + GAMMA_SKEW))[0, 0]
    return out


def plant(u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """The skewed output samples of the ZOH-driven resonance, stepped exactly."""
    x = x0.copy()
    y = np.empty(u.size)
    for k, uk in enumerate(u):
        y[k] = (C_C @ (PHI_SKEW @ x + GAMMA_SKEW[:, 0] * uk))[0]
        x = PHI @ x + GAMMA[:, 0] * uk
    return y


NOISE_B, NOISE_A = [1.0], [1.0, -0.8]   # coloured output noise: first-order low-pass of white noise
INPUT_B, INPUT_A = signal.butter(4, 200.0, fs=FS)


def excitation(rng) -> np.ndarray:
    """Band-limited (0-200 Hz) Gaussian noise, from a filter started long before the record."""
    return signal.lfilter(INPUT_B, INPUT_A, rng.standard_normal(N + 2000))[2000:]


def coloured_noise(rng, sigma: float) -> np.ndarray:
    return signal.lfilter(NOISE_B, NOISE_A, sigma * rng.standard_normal(N + 2000))[2000:]


def noise_variance_per_line(lines: np.ndarray, sigma: float) -> np.ndarray:
    """E|V(k)|^2 with V = rfft(v)/N of stationary noise of spectrum sigma^2 |H(e^jw)|^2: that over N."""
    _, h = signal.freqz(NOISE_B, NOISE_A, worN=2 * np.pi * lines / N)
    return sigma ** 2 * np.abs(h) ** 2 / N


def band(result, lo=5.0, hi=180.0, step=7) -> np.ndarray:
    """Lines inside the excited band, one window (7 lines) apart, so their windows do not overlap."""
    f = result.frequencies
    return np.flatnonzero((f >= lo) & (f <= hi))[::step]


def measured_record(rng, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    u = excitation(rng)
    y = plant(u, x0=rng.normal(scale=2.0, size=2)) + coloured_noise(rng, sigma)
    return u + 0.31, y - 1.7   # DC offsets of the two converters


def binomial_band(p: float, trials: int, sds: float = 4.0) -> float:
    return sds * math.sqrt(p * (1 - p) / trials)


def closed_loop_record(rng, sigma_y: float, sigma_u: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A proportional loop around the resonance with a one-sample computation delay:
    u[k] = kp (r[k] - y_meas[k-1]); the recorded u carries its own sensor noise (not fed back)."""
    kp = 0.6
    r = excitation(rng)
    v = coloured_noise(rng, sigma_y)
    x = rng.normal(scale=1.0, size=2)
    u = np.empty(N)
    y = np.empty(N)
    previous = 0.0
    for k in range(N):
        u[k] = kp * (r[k] - previous)
        y[k] = (C_C @ (PHI_SKEW @ x + GAMMA_SKEW[:, 0] * u[k]))[0] + v[k]
        x = PHI @ x + GAMMA[:, 0] * u[k]
        previous = y[k]
    return r, y + 0.4, u + sigma_u * rng.standard_normal(N) - 0.05
