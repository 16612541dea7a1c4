"""Output spectrum analysis of one excitation level, as seed 000 Fig. 3 and Eq. (7).

Per line, averaged over the M realizations of a level (rms averaging: mean of the powers, because
the phase of a detection line is random from realization to realization, seed 000 Eq. (7) and book
Section 6.2):

- ``y_power = (1/M) sum_m |Y_hat^[m](k)|^2`` and ``u_power`` likewise (P-averaged spectra);
- ``y_noise = (1/M) sum_m sigma^2_{Y^[m],n}(k)``, the noise variance of the P-averaged spectrum
  (6-12), on the same scale as ``y_power``, and ``u_noise`` likewise.

The summary gives band-mean powers in dB (10 log10 of the mean power, DFT scaled as in
:mod:`nlsid.analysis.lines`) at the excited lines, at the in-band odd and even detection lines,
the noise in band, and the differences a user reads at a glance ("odd 20 dB above even, 30 dB above
the noise").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import EVEN, EXCITED, NONHARMONIC, ODD, Lines
from nlsid.analysis.period_stats import PeriodStats


def db(power: float) -> float:
    """10 log10 of a power; NaN for a non-positive or NaN power."""
    return float(10 * np.log10(power)) if power > 0 else float("nan")


@dataclass
class OutputSpectrum:
    """Rms-averaged line powers of one level (arrays indexed by bin, length N//2 + 1)."""

    u_power: np.ndarray
    u_noise: np.ndarray
    y_power: np.ndarray
    y_noise: np.ndarray

    def summary(self, lines: Lines) -> dict:
        """Band-mean levels (dB) of the output and the differences between them."""
        in_band = lines.in_band

        def level(values: np.ndarray, kind: int | None, band: bool | None = True) -> float:
            mask = (lines.kind >= 0) if kind is None else (lines.kind == kind)
            if band is not None:
                mask = mask & (in_band == band)
            return db(float(np.mean(values[mask]))) if mask.any() else float("nan")

        out = {
            "excited_db": level(self.y_power, EXCITED),
            "odd_db": level(self.y_power, ODD),
            "even_db": level(self.y_power, EVEN),
            "nonharmonic_db": level(self.y_power, NONHARMONIC),
            "noise_db": level(self.y_noise, None),
            "odd_out_of_band_db": level(self.y_power, ODD, False),
            "even_out_of_band_db": level(self.y_power, EVEN, False),
            "input_excited_db": level(self.u_power, EXCITED),
            "input_detection_db": float(np.fmax(level(self.u_power, ODD), level(self.u_power, EVEN))),
        }
        out["odd_above_even_db"] = out["odd_db"] - out["even_db"]
        out["odd_above_noise_db"] = out["odd_db"] - out["noise_db"]
        out["even_above_noise_db"] = out["even_db"] - out["noise_db"]
        out["excited_above_odd_db"] = out["excited_db"] - out["odd_db"]
        return out


class SpectrumAccumulator:
    """Accumulate the line powers of the realizations of one level."""

    def __init__(self, n_lines: int):
        self.n = 0
        self._sums = [np.zeros(n_lines) for _ in range(4)]

    def add(self, stats: PeriodStats) -> None:
        self.n += 1
        for total, value in zip(self._sums, (np.abs(stats.U) ** 2, stats.var_u, np.abs(stats.Y) ** 2, stats.var_y)):
            total += value

    def result(self) -> OutputSpectrum:
        return OutputSpectrum(*(total / self.n for total in self._sums))
