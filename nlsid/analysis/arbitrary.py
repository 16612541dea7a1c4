"""The BLA of arbitrarily excited runs (noise, sweeps, steps, trajectories) by the Local Polynomial Method.

Runs of kind ``arbitrary`` are grouped by their level attribute, like multisine runs. The runs of a
level are records of one experiment that share the FRF (:mod:`nlsid.analysis.lpm`, jointly, each
with its own transient); records of different lengths are cut to the shortest. With a recorded
reference r (closed loop, or a noisy input) the FRF is the indirect ratio from r; otherwise u is
taken as known (its noise biases G towards zero: say so where it matters).

The band of a level is where the input (or reference) carries power: the lines whose power,
smoothed over the LPM window, is within ``BAND_DB`` of the largest. Outside it the FRF is not
excited and is not reported. The LPM's residual variance is noise plus the stochastic nonlinear
distortion, so the level's floor is an upper bound of the noise, never a noise level.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.analysis.confidence import Bounds
from nlsid.analysis.lpm import DEFAULT_DEGREE, DEFAULT_HALF_WIDTH, LPMResult, lpm
from nlsid.analysis.output_spectrum import db
from nlsid.errors import InputError
from nlsid.io.run import Run

BAND_DB = 40.0            # lines within 40 dB of the strongest input line form the band
RATIO_RELATIVE_STD = 0.3  # above this relative std of G_ur the first-order ratio variance is not valid


@dataclass
class LPMLevel:
    """The LPM result of the arbitrary runs of one level, restricted to the excited band."""

    level: float | None
    run_ids: list[str]
    u_rms: float
    result: LPMResult
    band: np.ndarray           # indices into result.lines of the reported lines
    probability: float
    uses_reference: bool
    warnings: list[str] = field(default_factory=list)
    excited: np.ndarray | None = None  # indices into result.lines of the band's excited lines (None: the band)

    @property
    def excited_lines(self) -> np.ndarray:
        """Indices into ``result.lines`` of the lines that carry input power themselves
        (:func:`excited_lines`): the band statistics are taken over these."""
        return self.band if self.excited is None else self.excited

    @property
    def bins(self) -> np.ndarray:
        return self.result.lines[self.band]

    @property
    def frequency(self) -> np.ndarray:
        return self.result.frequencies[self.band]

    @property
    def G(self) -> np.ndarray:
        return self.result.G[self.band]

    @property
    def var_G(self) -> np.ndarray:
        return self.result.var_G[self.band]

    @property
    def bounds(self) -> Bounds:
        full = self.result.bounds(self.probability)
        return Bounds(*(getattr(full, name)[self.band] for name in ("radius", "mag_lo", "mag_hi", "phase_lo", "phase_hi")))

    @property
    def method(self) -> str:
        return "lpm_reference" if self.uses_reference else "lpm"

    def summary(self) -> dict:
        """Scalars for tables and ``--json`` (docs/formats.md, bla.h5 version 2).

        The band means (``bla_db``, ``total_var_db``) are over the excited lines only
        (:attr:`excited_lines`, counted in ``excited_lines``): the band, found on the window-smoothed
        input power, also holds the unexcited lines next to its edges, where G and its variance are
        the local polynomial's extrapolation."""
        excited = self.excited_lines
        G2 = float(np.nanmean(np.abs(self.result.G[excited]) ** 2))
        return {
            "level": self.level,
            "u_rms": self.u_rms,
            "realizations": len(self.run_ids),
            "periods": 0,
            "method": self.method,
            "excited_lines": int(excited.size),
            "band_hz": [float(self.frequency[0]), float(self.frequency[-1])] if self.band.size else None,
            "bla_db": db(G2),
            "total_var_db": db(float(np.nanmean(self.result.var_G[excited]))) - db(G2),
            "nl_var_db": float("nan"),
            "noise_var_db": float("nan"),
            "noise_floor": "upper_bound",
            "floor_source": "LPM residual: noise plus nonlinear distortion",
            "lpm": {"lines": 2 * self.result.half_width + 1, "degree": self.result.degree, "dof": self.result.dof,
                    "samples": self.result.n_samples},
            "warnings": list(self.warnings),
        }


def excited_band(result: LPMResult, power: np.ndarray) -> np.ndarray:
    """Indices of the lines whose window-smoothed input power is within BAND_DB of the largest."""
    width = 2 * result.half_width + 1
    smooth = np.convolve(power, np.ones(width) / width, mode="same")
    top = float(np.max(smooth)) if smooth.size else 0.0
    if not top > 0:
        return np.zeros(0, dtype=int)
    keep = (smooth >= top * 10 ** (-BAND_DB / 10)) & np.isfinite(result.G) & np.isfinite(result.var_G)
    return np.flatnonzero(keep)


def excited_lines(band: np.ndarray, power: np.ndarray, width: int) -> np.ndarray:
    """The lines of ``band`` whose own input power (not smoothed) is within BAND_DB of the largest
    window-smoothed power, the reference :func:`excited_band` uses. Smoothing spreads the power of
    the band's edge lines over the window, so the band reaches unexcited lines up to half a window
    beyond its edges; those are left out here."""
    smooth = np.convolve(power, np.ones(width) / width, mode="same")
    top = float(np.max(smooth)) if smooth.size else 0.0
    return band[power[band] >= top * 10 ** (-BAND_DB / 10)]


def analyse_level(runs: list[Run], where: str, probability: float, half_width: int = DEFAULT_HALF_WIDTH,
                  degree: int = DEFAULT_DEGREE, use_reference: bool | None = None) -> LPMLevel:
    """The LPM of the arbitrary runs of one level (module docstring)."""
    if use_reference is None:
        use_reference = all(run.r is not None for run in runs)
    length = min(run.n_samples for run in runs)
    warnings = []
    if any(run.n_samples != length for run in runs):
        warnings.append(f"records of different lengths: all cut to the shortest, {length} samples")
    x = np.array([(run.r if use_reference else run.u)[:length] for run in runs])
    if use_reference:
        z = np.array([[run.y[:length], run.u[:length]] for run in runs])
    else:
        z = np.array([run.y[:length] for run in runs])
    if not np.any(np.ptp(x, axis=1) > 0):
        raise InputError(where, f"the {'reference r' if use_reference else 'input u'} is constant: it excites nothing")
    try:
        result = lpm(x, z, runs[0].fs, half_width, degree)
    except ValueError as exc:
        raise InputError(where, f"the Local Polynomial Method cannot run: {exc}; record longer or choose "
                                f"fewer --lpm-lines / a lower --lpm-degree") from None
    power = np.mean(np.abs(np.fft.rfft(x, axis=-1)[:, 1:result.lines.size + 1]) ** 2, axis=0)
    band = excited_band(result, power)
    if band.size == 0:
        raise InputError(where, "no line carries input power: the records excite nothing the LPM can use")
    if use_reference:
        relative = np.sqrt(result.var_G[band]) / np.abs(result.G[band])
        shaky = band[relative > RATIO_RELATIVE_STD]
        if shaky.size:
            warnings.append(f"{shaky.size} of {band.size} lines have a relative std of G above {RATIO_RELATIVE_STD}: "
                            f"their first-order variance and bounds are not valid (e.g. "
                            f"{result.frequencies[shaky[0]]:.4g} Hz)")
    elif any(run.r is not None for run in runs):
        warnings.append("some runs carry no reference r: the FRF is taken from u as if u were noise-free")
    u_rms = math.sqrt(float(np.mean([np.mean((run.u[:length] - run.u[:length].mean()) ** 2) for run in runs])))
    excited = excited_lines(band, power, 2 * half_width + 1)
    if excited.size == 0:  # a spread-out input whose every line is far below its smoothed peak
        excited = band
    return LPMLevel(runs[0].level, [run.run_id for run in runs], u_rms, result, band, probability,
                    use_reference, warnings, excited)
