"""The gain on validation data: original against extended model, and how close to the noise floor.

On the validation runs (:mod:`nlsid.diagnose.split`, never seen by an estimate) the error of a
model M is the mean steady-state period of its residual ``y - y_M`` without its mean value (all
lines but DC and Nyquist); with ``fit_on="u"`` (closed loop) of ``u - u_M`` in the same way
(:mod:`nlsid.diagnose.evidence`, "The judged signal"). Per model:

- ``error_rms``: the rms of that error, averaged in power over the runs; ``error_db`` = 20 log10;
- ``gain_db`` = 20 log10(error_rms of the original / error_rms of this model): > 0 is better;
- ``noise_rms``, the noise floor: the error the true system's model would show on these runs.
  The true model's residual is ``n_y - G n_u`` (open loop: output noise and the model's response
  to the input's measurement noise; closed loop: the noise as the loop passes it), with no
  systematic part, so its P-averaged period has the power ``sum_k s2(k)`` of
  :mod:`nlsid.diagnose.evidence`, s2 estimated from the period-to-period variance of the
  residual. That estimate is taken on the residual of the model being scored, for two reasons the
  original model's residual cannot serve: the response to input noise depends on the model (a
  resonance without its friction amplifies it), and a transient of the measured output that
  outlasts the transient periods (friction settling on a sine) varies from period to period
  unless the model reproduces it. For the true model (and a correct extension) the estimate is
  its own error's noise, so ``error_rms / noise_rms`` squared follows the F distribution of
  :func:`nlsid.diagnose.significance.power_test`: 0 dB within a fraction of a dB at these degrees
  of freedom;
- ``above_floor_db`` = 20 log10(error_rms / noise_rms): 0 dB is the best possible, and
  ``p_above_noise`` its p-value under that F distribution;
- ``distortion_explained``: at the in-band odd and even detection lines of the validation
  multisines, the part of the original residual's power above the noise that the model removes,
  ``(B - A) / (B - N)`` with B and A the residual powers of the original and of this model and N
  this model's noise power there (1 = all of it; NaN when the original model leaves nothing above
  the noise there). It is negative when the model adds distortion there: -0.48 is an excess above
  the noise 48 % larger than the original's, a share that readers misread;
- ``distortion_gain_db`` = 10 log10(B / A), the same two powers as a change in dB with the sign
  of ``gain_db``: > 0 the model leaves less at the detection lines than the original (+60 dB: it
  removes the distortion down to the noise), < 0 more (-1.7 dB: it adds distortion). 0 for the
  original; NaN without detection lines or when either power is zero.

With a zero noise floor (noise-free data, :mod:`nlsid.diagnose.evidence`) ``noise_zero`` is set,
``above_floor_db`` is NaN (no ratio to a zero floor) and ``p_above_noise`` is 0, or NaN with
``exact`` set when the model's error is zero within numerical precision as well; ``gain_db`` of
such an exact model is NaN too (its error has no size to compare), and ``error_db``/``noise_db``
of a zero rms are NaN. NaN is written as null.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import EVEN, ODD, classify_lines
from nlsid.diagnose.residual import Residual, residual_of
from nlsid.diagnose.significance import ALPHA, error_power, error_test
from nlsid.diagnose.simulation import ModelRunner
from nlsid.io.run import Run


@dataclass(frozen=True)
class Score:
    error_rms: float
    noise_rms: float
    gain_db: float
    above_floor_db: float
    distortion_explained: float
    distortion_gain_db: float
    p_above_noise: float
    noise_zero: bool = False   # the noise floor is zero within numerical precision (noise-free data)
    exact: bool = False        # ... and so is this model's error

    @property
    def error_db(self) -> float:
        return _db20(self.error_rms)

    @property
    def within_floor(self) -> bool:
        """The error is not significantly above the noise floor (an exact match on noise-free data)."""
        return self.exact or (math.isfinite(self.p_above_noise) and self.p_above_noise >= ALPHA)

    def summary(self) -> dict:
        return {"error_rms": self.error_rms, "error_db": self.error_db, "noise_rms": self.noise_rms,
                "noise_db": _db20(self.noise_rms), "gain_db": self.gain_db,
                "above_floor_db": self.above_floor_db, "distortion_explained": self.distortion_explained,
                "distortion_gain_db": self.distortion_gain_db, "p_above_noise": self.p_above_noise,
                "noise_floor_zero": self.noise_zero, "exact_match": self.exact}


def _db20(rms: float) -> float:
    """20 log10 of an rms value; NaN for zero (no finite level in dB)."""
    return 20 * math.log10(rms) if rms > 0 else float("nan")


def model_residuals(runner: ModelRunner, runs: list[Run], residuals: list[Residual],
                    signal: str = "y") -> list[Residual]:
    """The residuals of ``runner``'s model on the validation ``runs`` (same order and roles as
    ``residuals``), of the judged ``signal`` (``y``, or in closed loop ``u``)."""
    return [residual_of(run, x, res.role, signal)
            for run, x, res in zip(runs, runner.simulate_each(runs, signal), residuals)]


def _detection_power(residuals: list[Residual]) -> tuple[float, float]:
    power = noise = 0.0
    for res in residuals:
        if res.kind != "multisine":
            continue
        lines = classify_lines(res.period, res.fs, res.excited_bins)
        k = np.flatnonzero(((lines.kind == ODD) | (lines.kind == EVEN)) & lines.in_band)
        power += float(np.sum(np.abs(res.spectrum[k]) ** 2))
        noise += float(np.sum(res.noise_var[k]))
    return power, noise


def score(original: list[Residual], model: list[Residual] | None = None) -> Score:
    """The :class:`Score` of a model whose validation residuals are ``model`` (default: the original's)."""
    model = original if model is None else model
    original_power, _ = error_power(original)
    power, noise = error_power(model)
    before, _ = _detection_power(original)
    after, noise_lines = _detection_power(model)
    explained = (before - after) / (before - noise_lines) if before > noise_lines else float("nan")
    distortion_gain = 10 * math.log10(before / after) if before > 0 and after > 0 else float("nan")
    test = error_test(model)
    if model is original:
        gain = 0.0
    elif test.exact or not (power > 0 and original_power > 0):
        gain = float("nan")
    else:
        gain = 10 * math.log10(original_power / power)
    above = 10 * math.log10(power / noise) if power > 0 and noise > 0 and not test.noise_zero else float("nan")
    return Score(math.sqrt(power), math.sqrt(noise), gain, above, explained, distortion_gain, test.p_value,
                 test.noise_zero, test.exact)
