"""Frequency lines of a periodic experiment: one-period spectra and the class of every line.

DFT scaling (book Eq. (2-2) with S = 1/N, the scaling for periodic signals measured over whole
periods)::

    X(k) = (1/N) sum_{n=0}^{N-1} x(n) exp(-j 2 pi k n / N),   k = 0 .. N//2,

so that line k is the frequency k fs/N, a cosine ``A cos(2 pi k n/N + phi)`` gives
``|X(k)| = A/2`` whatever N, and white noise of variance s^2 gives ``E|X(k)|^2 = s^2/N``.

Line classes (book Sections 5.1 and 6.1.2, seed 000 Section IV-A). With ``d`` the greatest common
divisor of the excited bins, the harmonics of the excitation are the bins ``k = d j``:

- ``EXCITED``: the excited bins;
- ``ODD``: non-excited harmonics with odd ``j`` (odd detection lines of an odd multisine);
- ``EVEN``: non-excited harmonics with even ``j`` (even detection lines);
- ``NONHARMONIC``: bins that are not multiples of ``d`` (only noise for a PISPO system, whose
  steady-state response has the period of the input, book Section 5.1.2.A).

A line is in band when it lies between the lowest and the highest excited bin. DC and the Nyquist
line are never classified. The grid is *odd* when every excited harmonic ``j`` is odd (an odd or
odd-random multisine) and *full* otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, reduce

import numpy as np

EXCITED, ODD, EVEN, NONHARMONIC = 0, 1, 2, 3
CLASS_NAMES = ("excited", "odd", "even", "nonharmonic")


def spectra(periods: np.ndarray) -> np.ndarray:
    """One-period spectra (P, N//2 + 1) of a (P, N) array, scaled by 1/N as in the module docstring."""
    n = periods.shape[-1]
    return np.fft.rfft(periods, axis=-1) * (1.0 / n)


@dataclass(frozen=True)
class Lines:
    """The lines of one period of ``period`` samples at ``fs``, classified against ``excited``.

    ``kind`` and ``in_band`` are indexed by bin number (length N//2 + 1); DC and Nyquist get
    ``kind = -1``.
    """

    period: int
    fs: float
    excited: np.ndarray
    base: int
    kind: np.ndarray
    in_band: np.ndarray

    @cached_property
    def odd_grid(self) -> bool:
        """True when only odd harmonics are excited (odd/even classification is possible)."""
        return bool(np.all((self.excited // self.base) % 2 == 1))

    def frequency(self, bins: np.ndarray) -> np.ndarray:
        """Frequencies in Hz of integer ``bins``: k fs / N."""
        return np.asarray(bins) * (self.fs / self.period)

    @property
    def bins(self) -> np.ndarray:
        """Every classified bin: 1 .. (N-1)//2."""
        return np.arange(1, (self.period - 1) // 2 + 1)

    def detection(self, kind: int | tuple[int, ...], in_band: bool | None = True) -> np.ndarray:
        """Bins of class ``kind`` (ODD, EVEN or NONHARMONIC, or a tuple of classes), in band, out of
        band (False) or all (None), in increasing order.

        Computed once per ``(kind, in_band)`` and returned read-only: the lines of a level serve
        every one of its runs."""
        cache = self.__dict__.setdefault("_detection", {})  # a frozen dataclass: not through __setattr__
        if (kind, in_band) not in cache:
            mask = reduce(np.logical_or, [self.kind == k for k in (kind if isinstance(kind, tuple) else (kind,))])
            if in_band is not None:
                mask &= self.in_band == in_band
            bins = np.flatnonzero(mask)
            bins.flags.writeable = False
            cache[kind, in_band] = bins
        return cache[kind, in_band]

    def bla_detection(self) -> np.ndarray:
        """In-band detection lines that measure the distortion at the excited lines (Section 6.2, (6-54)).

        Odd grid: only the odd detection lines (odd excited lines carry only odd distortion).
        Full grid: every in-band harmonic detection line.
        """
        return self.detection(ODD if self.odd_grid else (ODD, EVEN))

    @property
    def grid_factor(self) -> float:
        """F_group/(F_group - 1): in-band candidate harmonics per excited line ((6-97), (6-100)).

        The candidates are the in-band odd harmonics of an odd grid, all in-band harmonics of a full
        grid. 1 for a multisine without detection lines.
        """
        candidates = self.excited.size + self.bla_detection().size
        return candidates / self.excited.size


def classify_lines(period: int, fs: float, excited_bins: np.ndarray) -> Lines:
    """Classify the lines of a period of ``period`` samples against the (sorted) excited bins."""
    excited = np.asarray(excited_bins, dtype=np.int64)
    base = int(reduce(math.gcd, excited.tolist()))
    n_lines = period // 2 + 1
    kind = np.full(n_lines, -1, dtype=np.int8)
    bins = np.arange(1, (period - 1) // 2 + 1)
    harmonic = bins % base == 0
    kind[bins] = np.where(harmonic, np.where((bins // base) % 2 == 1, ODD, EVEN), NONHARMONIC)
    kind[excited] = EXCITED
    k = np.arange(n_lines)
    in_band = (k >= excited[0]) & (k <= excited[-1]) & (kind >= 0)
    return Lines(period=period, fs=fs, excited=excited, base=base, kind=kind, in_band=in_band)
