"""The gain on validation data: original against extended model, and how close to the noise floor.

On the validation runs (:mod:`nlsid.diagnose.split`, never seen by an estimate) the error of a
model is the mean steady-state period of the measured output minus the model's, without its mean
value (all lines but DC and Nyquist). Per model:

- ``error_rms``: the rms of that error, averaged in power over the runs; ``error_db`` = 20 log10;
- ``gain_db`` = 20 log10(error_rms of the original / error_rms of this model): > 0 is better;
- ``above_floor_db`` = 20 log10(error_rms / noise_rms): the noise floor ``noise_rms`` is the rms of
  the noise left in the averaged period (its period-to-period variance over P,
  :mod:`nlsid.diagnose.evidence`), the error a perfect model would show; 0 dB is the best possible;
- ``distortion_explained``: at the in-band odd and even detection lines of the validation
  multisines, the part of the residual's power above the noise that the model removes,
  ``(B - A) / (B - N)`` with B and A the residual powers before and after and N the noise power
  (1 = all of it; NaN when the original model leaves nothing above the noise there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import EVEN, ODD, classify_lines, spectra
from nlsid.diagnose.evidence import Residual, error_power, error_test
from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.io.run import Run


@dataclass(frozen=True)
class Score:
    error_rms: float
    noise_rms: float
    gain_db: float
    above_floor_db: float
    distortion_explained: float
    p_above_noise: float

    @property
    def error_db(self) -> float:
        return 20 * math.log10(self.error_rms)

    def summary(self) -> dict:
        return {"error_rms": self.error_rms, "error_db": self.error_db, "noise_rms": self.noise_rms,
                "noise_db": 20 * math.log10(self.noise_rms), "gain_db": self.gain_db,
                "above_floor_db": self.above_floor_db, "distortion_explained": self.distortion_explained,
                "p_above_noise": self.p_above_noise}


def model_errors(runner: ModelRunner, runs: list[Run], residuals: list[Residual]) -> list[np.ndarray]:
    """Mean error periods of ``runner``'s model on the validation ``runs`` (same order as ``residuals``)."""
    return [res.measured - steady_mean(run, runner.simulate(run).y) for run, res in zip(runs, residuals)]


def _detection_power(residuals: list[Residual], errors: list[np.ndarray] | None) -> tuple[float, float]:
    power = noise = 0.0
    for i, res in enumerate(residuals):
        if res.kind != "multisine":
            continue
        lines = classify_lines(res.period, res.fs, res.excited_bins)
        k = np.flatnonzero(((lines.kind == ODD) | (lines.kind == EVEN)) & lines.in_band)
        E = spectra(res.residual if errors is None else errors[i])[k]
        power += float(np.sum(np.abs(E) ** 2))
        noise += float(np.sum(res.noise_var[k]))
    return power, noise


def score(residuals: list[Residual], errors: list[np.ndarray] | None = None) -> Score:
    """The :class:`Score` of a model whose validation errors are ``errors`` (default: the original)."""
    original, noise = error_power(residuals)
    power, _ = error_power(residuals, errors)
    before, noise_lines = _detection_power(residuals, None)
    after, _ = _detection_power(residuals, errors)
    explained = (before - after) / (before - noise_lines) if before > noise_lines else float("nan")
    return Score(math.sqrt(power), math.sqrt(noise), 10 * math.log10(original / power),
                 10 * math.log10(power / noise), explained, error_test(residuals, errors).p_value)
