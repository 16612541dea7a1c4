"""The residual of a model on a measured periodic run: its mean period, spectrum and noise.

Residual. For every periodic run the model is simulated on the measured excitation
(:mod:`nlsid.diagnose.simulation`) and the residual ``e = y - y_model`` is taken over the
steady-state periods. Its P-averaged one-period spectrum ``E(k)`` (DFT scaled by 1/N,
:mod:`nlsid.analysis.lines`) holds what the model misses plus noise; the noise variance of
``E(k)``, ``s2(k)``, is the period-to-period variance of the residual (book (6-12), seed 000
Eq. (3)): the model is noise-free, so this is the noise of the measurement as it reaches the
residual (output noise, and in open loop the model's response to the input noise). It also holds
whatever part of the measured output is not periodic yet and the model does not reproduce (a
friction transient that outlasts the transient periods): the noise of a wrong model is then
overestimated and its test is conservative (:mod:`nlsid.diagnose.gain` takes each model's own).

The judged signal. In closed loop the controller keeps the position error small, and what the
plant gets wrong shows in the command it needs: with ``fit_on="u"`` (``diagnose --fit-on u``) the
residual is ``e = u - u_model``, u_model the plant input as the simulated controller computes it
(the loop closed in the simulation), and everything below (its noise from the period-to-period
variance of that residual, the tests, the time signals) is of u. The BLA comparison stays that of
the output.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import spectra
from nlsid.diagnose.simulation import steady_mean, steady_periods
from nlsid.io.run import Run


@dataclass
class Residual:
    """One run's mean steady-state period: measured, model, and the residual's spectrum and noise."""

    run_id: str
    role: str
    kind: str
    level: float | None
    fs: float
    period: int
    n_periods: int
    excited_bins: np.ndarray | None
    measured: np.ndarray
    model: np.ndarray
    noise_var: np.ndarray

    @property
    def residual(self) -> np.ndarray:
        return self.measured - self.model

    @property
    def spectrum(self) -> np.ndarray:
        return spectra(self.residual)

    @property
    def output_power(self) -> float:
        """Power of the measured mean period at every AC line, sum |Y(k)|^2 (the scale of
        numerical precision for this run's residual and noise, :mod:`nlsid.analysis.precision`)."""
        return float(np.sum(np.abs(spectra(self.measured)[ac_lines(self.period)]) ** 2))


def residual_of(run: Run, model_y: np.ndarray, role: str, signal: str = "y") -> Residual:
    """The :class:`Residual` of a measured run and the model's simulation of its ``signal`` on it
    (same length): the output ``y``, or in closed loop the command ``u`` (the residual
    ``u - u_model``, its noise the period-to-period variance of that residual)."""
    measured = run.periods(signal)
    e = measured - steady_periods(run, model_y)
    P = e.shape[0]
    if P > 1:
        deviation = spectra(e - e.mean(axis=0))
        noise_var = np.sum(np.abs(deviation) ** 2, axis=0) / (P * (P - 1))
    else:
        noise_var = np.full(run.period // 2 + 1, np.nan)
    return Residual(run.run_id, role, run.kind, run.level, run.fs, run.period, P, run.excited_bins,
                    measured.mean(axis=0), steady_mean(run, model_y), noise_var)


def ac_lines(period: int) -> np.ndarray:
    """Lines 1 .. (N-1)//2: every line of the period but DC and Nyquist."""
    return np.arange(1, (period - 1) // 2 + 1)




def measured_power(residuals: list[Residual]) -> float:
    """The measured output's power over these runs (the scale of numerical precision)."""
    return sum(res.output_power for res in residuals)
