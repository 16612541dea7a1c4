"""Multisine synthesis (book (2-8), (5-52)) with random or Schroeder phases and crest-factor reduction.

A multisine on the excited bins K of an N-sample period is

    u(n) = sum_{k in K} A_k cos(2 pi k n / N + phi_k),     n = 0 .. N-1,

built exactly by an inverse real FFT with X(k) = (N/2) A_k exp(j phi_k) (book digest 1.1, Ex 19). Its
rms over one period is sqrt(sum A_k^2 / 2) exactly, since no bin is DC or Nyquist.
"""

from __future__ import annotations

import numpy as np


def flat_amplitudes(n_lines: int, rms: float) -> np.ndarray:
    """Equal amplitudes A_k = rms sqrt(2 / F) that give exactly the requested rms."""
    return np.full(n_lines, rms * np.sqrt(2.0 / n_lines))


def random_phases(n_lines: int, rng: np.random.Generator) -> np.ndarray:
    """Independent phases phi_k ~ U[0, 2 pi), so that E{exp(j phi_k)} = 0 (book (5-39))."""
    return rng.uniform(0.0, 2.0 * np.pi, n_lines)


def schroeder_phases(n_lines: int) -> np.ndarray:
    """Schroeder phases phi_i = -pi i (i - 1) / F for the i-th of F excited lines (book (5-5))."""
    i = np.arange(1, n_lines + 1)
    return -np.pi * i * (i - 1) / n_lines


def synthesize(period: int, bins: np.ndarray, amplitudes: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """One period of sum_k A_k cos(2 pi k n/N + phi_k), exact to rounding, by inverse real FFT."""
    spectrum = np.zeros(period // 2 + 1, dtype=complex)
    spectrum[bins] = 0.5 * period * amplitudes * np.exp(1j * phases)
    return np.fft.irfft(spectrum, period)


def crest_factor(u: np.ndarray) -> float:
    """Cr = max|u| / rms(u) (book (2-9))."""
    return float(np.max(np.abs(u)) / np.sqrt(np.mean(u**2)))


def reduce_crest_factor(period: int, bins: np.ndarray, amplitudes: np.ndarray, phases: np.ndarray,
                        iterations: int, clip_level: float = 1.4) -> np.ndarray:
    """Lower the crest factor by iterative clipping with spectrum restoration; return the phases.

    Van der Ouderaa, Schoukens and Renneboog (1988), the replacement the book digest (1.5) suggests
    for the book's cited "crestmin": clip the signal at ``clip_level`` times its rms, keep the phases
    of the clipped signal at the excited bins, restore the amplitudes and discard every other bin;
    repeat. The amplitude spectrum (so the rms) never changes; the phases with the lowest crest factor
    seen are returned. From random phases, 100 iterations reach about 1.6 for 250 lines (Schroeder:
    1.69), against about 3.5 before.
    """
    best_phases, current = phases, phases
    best = crest_factor(synthesize(period, bins, amplitudes, phases))
    for _ in range(iterations):
        u = synthesize(period, bins, amplitudes, current)
        clip = clip_level * np.sqrt(np.mean(u**2))
        current = np.angle(np.fft.rfft(np.clip(u, -clip, clip))[bins])
        cf = crest_factor(synthesize(period, bins, amplitudes, current))
        if cf < best:
            best, best_phases = cf, current
    return best_phases
