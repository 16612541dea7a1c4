"""Changing the sample grid of imported records: decimation, and signals of another clock onto the input's.

Decimation by an integer K (``nlsid import --decimate K``) keeps every K-th sample after a linear-phase
anti-alias FIR low-pass, applied without delay (:func:`scipy.signal.resample_poly`, which removes the
filter's group delay). The filter is a Kaiser-window design (Oppenheim and Schafer, *Discrete-Time
Signal Processing*, 3rd ed., Sec. 7.6) with

- the pass band up to ``PASS_FRACTION`` of the new Nyquist frequency fs / (2K),
- the stop band from the new Nyquist frequency on, attenuated by ``STOP_DB``,

so a component that would alias lands at most ``STOP_DB`` below its level. Every signal of a record
(u, y, r, channels) goes through the same filter: a frequency response Y/U in the pass band is
unchanged by it. The filter reaches past the record's ends for ``(taps - 1) / 2`` input samples; the
output samples that see past an end are dropped, and the count is reported.

Signals logged by another instrument (``nlsid import U_FILE Y_FILE``, each file with its own time
vector) are moved onto the time grid of the file that holds u: low-passed as above when their rate is
higher than u's (anti-alias), then interpolated by a cubic spline at u's sample times
(:class:`scipy.interpolate.CubicSpline`, not-a-knot ends). Only the time span that both clocks cover is
kept. A cubic spline reproduces a sine of f Hz sampled at rate fs with an error of order
``(2 pi f / fs)^4`` relative (de Boor, *A Practical Guide to Splines*, Ch. V): below 1e-3 for
f < fs / 20; the report says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PASS_FRACTION = 0.8
STOP_DB = 80.0


@dataclass(frozen=True)
class AntiAlias:
    """A linear-phase low-pass FIR for a rate reduction by ``factor`` (possibly not an integer)."""

    taps: np.ndarray
    factor: float

    @property
    def half_length(self) -> int:
        """Input samples the filter reaches on either side of its centre."""
        return (self.taps.size - 1) // 2

    def describe(self) -> str:
        return (f"anti-alias FIR of {self.taps.size} taps (Kaiser window, pass band to {PASS_FRACTION:g} of the new "
                f"Nyquist frequency, {STOP_DB:g} dB from it on), zero phase")


def anti_alias(factor: float) -> AntiAlias:
    """The low-pass that keeps a rate reduction by ``factor`` free of aliasing to ``STOP_DB``.

    Cut-off (in units of the input Nyquist frequency): pass edge ``PASS_FRACTION / factor``, stop
    edge ``1 / factor``; the Kaiser order and beta from :func:`scipy.signal.kaiserord`, the length made
    odd so that the delay is a whole number of samples.
    """
    from scipy.signal import firwin, kaiserord

    width = (1.0 - PASS_FRACTION) / factor
    numtaps, beta = kaiserord(STOP_DB + 1.0, width)  # the Kaiser formulas fall short by a few tenths of a dB
    numtaps += 1 - numtaps % 2
    cutoff = (1.0 + PASS_FRACTION) / (2.0 * factor)
    return AntiAlias(firwin(numtaps, cutoff, window=("kaiser", beta)), factor)


def decimate(x: np.ndarray, factor: int, fir: AntiAlias) -> np.ndarray:
    """Every ``factor``-th sample of ``x`` (along its last axis) after the zero-phase low-pass ``fir``;
    output sample n is the filtered input at sample n * factor."""
    from scipy.signal import resample_poly

    return resample_poly(x, 1, factor, axis=-1, window=fir.taps.copy())


def edge_samples(factor: int, fir: AntiAlias) -> int:
    """Decimated samples at each end of a record that the filter computes from samples beyond the end."""
    return -(-fir.half_length // factor)


def onto_grid(t_from: np.ndarray, x: np.ndarray, t_to: np.ndarray) -> tuple[np.ndarray, str]:
    """Samples ``x`` (last axis along ``t_from``, uniform) at the times ``t_to``, inside ``t_from``'s span.

    Returns the resampled array and the method in words. A higher rate is first low-passed for the
    lower one (:func:`anti_alias`); then a cubic spline through the samples is evaluated at ``t_to``.
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import filtfilt

    fs_from = (t_from.size - 1) / (t_from[-1] - t_from[0])
    fs_to = (t_to.size - 1) / (t_to[-1] - t_to[0]) if t_to.size > 1 else fs_from
    method = "cubic-spline interpolation"
    if fs_from > fs_to * (1 + 1e-3):
        fir = anti_alias(fs_from / fs_to)
        # filtfilt squares the magnitude (the pass band stays within 2 x its ripple) and has zero phase
        x = filtfilt(fir.taps, [1.0], x, axis=-1, padtype="odd", padlen=min(3 * fir.taps.size, x.shape[-1] - 1))
        method = f"{fir.describe()} applied forward and backward, then {method}"
    return CubicSpline(t_from, x, axis=-1)(t_to), method
