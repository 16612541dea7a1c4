"""Schema of the ``design`` config (keys documented in docs/configs.md)."""

from __future__ import annotations

from typing import Literal, Optional

import numpy as np
from pydantic import ConfigDict, Field

from nlsid.io.config import ConfigValueError, StrictModel
from nlsid.signals.lines import band_bins

class DesignModel(StrictModel):
    """A part of a design config: every number finite (a signal of an infinite rate or level is no design)."""

    model_config = ConfigDict(**StrictModel.model_config, allow_inf_nan=False)


class ValueRange(DesignModel):
    """``count`` values from ``start`` to ``stop`` (both included), log- or linearly spaced."""

    start: float = Field(gt=0)
    stop: float = Field(gt=0)
    count: int = Field(ge=1)
    spacing: Literal["log", "linear"] = "log"

    def values(self) -> np.ndarray:
        if self.spacing == "log":
            return np.geomspace(self.start, self.stop, self.count)
        return np.linspace(self.start, self.stop, self.count)

class FrequencySteps(DesignModel):
    """Frequencies ``start, start + step, ...`` up to and including ``stop`` (Hz)."""

    start: float = Field(gt=0)
    stop: float = Field(gt=0)
    step: float = Field(gt=0)

    def values(self) -> np.ndarray:
        count = int(np.floor((self.stop - self.start) / self.step + 1e-9)) + 1
        return self.start + self.step * np.arange(max(count, 0))

def _one_of(owner: tuple, a: str, va, b: str, vb) -> np.ndarray:
    if (va is None) == (vb is None):
        raise ConfigValueError(owner, f"give exactly one of '{a}' (a list) or '{b}' (start/stop/...)")
    values = np.asarray(va, dtype=float) if va is not None else vb.values()
    if values.size == 0:
        raise ConfigValueError(owner + ((a,) if va is not None else (b,)), "gives no values")
    return values

class MultisineConfig(DesignModel):
    period: int = Field(ge=8, description="samples per period N")
    band: list[float] = Field(min_length=2, max_length=2)
    lines: Literal["full", "odd", "random-full", "random-odd"] = "random-odd"
    group_size: int = Field(3, ge=2)
    grid: Literal["linear", "log"] = "linear"
    log_ratio: float = Field(1.05, gt=1)
    phases: Literal["random", "schroeder"] = "random"
    crest_factor_iterations: int = Field(0, ge=0)
    realizations: int = Field(1, ge=1)
    periods: int = Field(1, ge=1)
    transient_periods: int = Field(1, ge=0)
    rms_levels: Optional[list[float]] = Field(None, min_length=1)
    rms_range: Optional[ValueRange] = None
    inputs: int = Field(1, ge=1, description="n_u: >= 2 gives orthogonal random multisines, n_u experiments each")
    transform: Literal["auto", "hadamard", "dft"] = "auto"

    def levels(self) -> np.ndarray:
        return _one_of(("multisine",), "rms_levels", self.rms_levels, "rms_range", self.rms_range)

    def check(self, fs: float) -> None:
        key = ("multisine",)
        lo, hi = self.band
        if not 0 <= lo < hi:
            raise ConfigValueError(key + ("band",), f"expected [f_min, f_max] with 0 <= f_min < f_max, got {self.band}")
        if hi >= fs / 2:
            raise ConfigValueError(key + ("band",), f"f_max {hi:g} Hz must lie below Nyquist fs/2 = {fs / 2:g} Hz")
        if band_bins(self.period, fs, (lo, hi), self.lines in ("odd", "random-odd")).size == 0:
            raise ConfigValueError(key + ("band",), f"holds no {'odd ' if 'odd' in self.lines else ''}line of the "
                                   f"{self.period}-sample period (lines every {fs / self.period:g} Hz)")
        levels = self.levels()
        for i, level in enumerate(levels):
            if not 0 < level < np.inf:
                raise ConfigValueError(key + ("rms_levels", i), f"must be > 0 and finite, got {level:g}")
        if self.phases == "schroeder" and self.realizations > 1:
            raise ConfigValueError(key + ("realizations",),
                                   "Schroeder phases are deterministic: use realizations: 1 or phases: random")
        self.check_inputs()

    def check_inputs(self) -> None:
        """Orthogonal multisines (``inputs`` >= 2) draw their own random phases, per input and per
        experiment: Schroeder phases and crest-factor iterations would undo that design."""
        key = ("multisine",)
        if self.inputs == 1:
            if self.transform != "auto":
                raise ConfigValueError(key + ("transform",), "applies to orthogonal multisines: give inputs: 2 or more")
            return
        if self.phases != "random":
            raise ConfigValueError(key + ("phases",), f"orthogonal multisines (inputs: {self.inputs}) have random phases: "
                                                      "use phases: random")
        if self.crest_factor_iterations:
            raise ConfigValueError(key + ("crest_factor_iterations",),
                                   f"orthogonal multisines (inputs: {self.inputs}) keep their random phases: use 0")
        if self.transform == "hadamard" and self.inputs & (self.inputs - 1):
            raise ConfigValueError(key + ("transform",), f"a Hadamard matrix needs a power of two inputs, got "
                                                         f"{self.inputs}: use dft or auto")

class SinesConfig(DesignModel):
    period: int = Field(ge=8, description="samples per period N")
    frequencies: Optional[list[float]] = Field(None, min_length=1)
    frequency_steps: Optional[FrequencySteps] = None
    amplitudes: Optional[list[float]] = Field(None, min_length=1)
    amplitude_range: Optional[ValueRange] = None
    repeats: int = Field(1, ge=1)
    periods: int = Field(1, ge=1)
    transient_periods: int = Field(1, ge=0)

    def frequency_values(self) -> np.ndarray:
        return _one_of(("sines",), "frequencies", self.frequencies, "frequency_steps", self.frequency_steps)

    def amplitude_values(self) -> np.ndarray:
        return _one_of(("sines",), "amplitudes", self.amplitudes, "amplitude_range", self.amplitude_range)

    def bins(self, fs: float) -> np.ndarray:
        """The bin of each frequency in an N-sample period; every frequency must sit on one."""
        key = ("sines", "frequencies" if self.frequencies is not None else "frequency_steps")
        freqs = self.frequency_values()
        exact = freqs * self.period / fs
        bins = np.round(exact).astype(np.int64)
        for i, (f, k, x) in enumerate(zip(freqs, bins, exact)):
            if not 0 < f < fs / 2:
                raise ConfigValueError(key + (i,), f"{f:g} Hz must lie in (0, fs/2 = {fs / 2:g}) Hz")
            if abs(x - k) > 1e-9 * max(1.0, abs(x)) or k < 1 or k >= self.period / 2:
                raise ConfigValueError(
                    key + (i,),
                    f"{f:g} Hz is not on a bin of the {self.period}-sample period at fs = {fs:g} Hz "
                    f"(bins every {fs / self.period:g} Hz; nearest {max(k, 1) * fs / self.period:g} Hz)",
                )
        return bins

    def check(self, fs: float) -> None:
        self.bins(fs)
        for i, amplitude in enumerate(self.amplitude_values()):
            if not 0 < amplitude < np.inf:
                raise ConfigValueError(("sines", "amplitudes", i), f"must be > 0 and finite, got {amplitude:g}")

class DesignConfig(DesignModel):
    """Top level of a design config: a sample rate, a seed, and a multisine and/or a sine grid."""

    fs: float = Field(gt=0)
    seed: int = Field(ge=0)
    unit: str = "V"
    multisine: Optional[MultisineConfig] = None
    sines: Optional[SinesConfig] = None

    def check(self) -> None:
        if self.multisine is None and self.sines is None:
            raise ConfigValueError((), "give 'multisine', 'sines' or both")
        for part in (self.multisine, self.sines):
            if part is not None:
                part.check(self.fs)
