"""Whether a residual stands above the noise: the F test of its power on a set of lines.

Size and significance against noise. For a set S of lines (and runs) the residual power relative
to the noise is ``ratio = sum_S |E|^2 / sum_S s2`` (shown in dB). If the model is right, each
``|E(k)|^2`` is ``s2(k)`` times a chi-square with 2 degrees of freedom over 2, so the numerator is
a weighted sum of chi-squares with ``nu = 2 (sum s2)^2 / sum s2^2`` equivalent degrees of freedom
(Satterthwaite), and the noise estimate has ``nu (P - 1)``: ``ratio ~ F(nu, nu (P - 1))``. A
discrepancy is *significant* when its p-value is below :data:`ALPHA` = 0.001; so "nothing beyond
noise" comes out as the answer when it is the truth (with probability 0.999 per test).

A zero noise floor. Noise-free data (a simulation without disturbances) repeat from period to
period up to rounding: ``sum_S s2`` is zero within numerical precision next to the measured output's
power over the same runs (:mod:`nlsid.analysis.precision`). The ratio then has no finite value and
no F distribution: the test says so (``noise_zero``) and is decided by the residual alone. A
residual that is zero within the same precision is an *exact match* (not significant, no p-value);
any larger residual cannot be zero noise (p = 0, significant). Its size above the noise has no
value in dB (``above_noise_db`` is NaN, written as null).

At the odd and even detection lines (book Section 6.1.2, seed 000 Fig. 3) the residual is the
distortion the model does not produce.

On single-sine runs (the HOSIDF excitation, seed 000 Eqs. 8-12) the residual at the harmonics
h k0 of the tone's line k0 is what the model misses of each HOSIDF (the first, h = 1, its
describing function): per sine (frequency and amplitude, all its runs) the same F test at the
fundamental, at the odd harmonics 3, 5, ... and at the even harmonics 2, 4, ... up to
:data:`HARMONICS` (or the last line below Nyquist), and the size of each harmonic above the noise.
Odd harmonics point to an odd nonlinearity (friction, a cubic spring, saturation), even ones to
an even one (a quadratic output).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlsid.analysis.lines import EVEN, EXCITED, ODD, classify_lines
from nlsid.analysis.output_spectrum import db
from nlsid.analysis.precision import negligible
from nlsid.diagnose.residual import Residual, ac_lines, measured_power
from nlsid.io.run import Run

ALPHA = 0.001
HARMONICS = 9  # sine harmonics tested (the fundamental included)


@dataclass(frozen=True)
class Test:
    """Residual power of a set of lines against the noise: ratio (dB), degrees of freedom, p-value.

    ``noise_zero``: the noise is zero within numerical precision (noise-free data; the ratio is
    NaN); ``residual_zero``: so is the residual (with ``noise_zero``: an exact match)."""

    above_noise_db: float
    dof: float
    noise_dof: float
    p_value: float
    noise_zero: bool = False
    residual_zero: bool = False

    @property
    def significant(self) -> bool:
        return math.isfinite(self.p_value) and self.p_value < ALPHA

    @property
    def exact(self) -> bool:
        return self.noise_zero and self.residual_zero

    @property
    def noise_known(self) -> bool:
        """False when no noise level could be estimated (P = 1, no periods): nothing can then be
        "within the noise", and the test is undecided (NaN), not passed."""
        return self.noise_zero or math.isfinite(self.p_value)

    def summary(self) -> dict:
        return {"above_noise_db": self.above_noise_db, "dof": self.dof, "noise_dof": self.noise_dof,
                "p_value": self.p_value, "significant": self.significant, "noise_floor_zero": self.noise_zero,
                "exact_match": self.exact, "noise_known": self.noise_known}


def power_test(power: float, noise: np.ndarray, n_periods: int, reference: float = float("nan")) -> Test:
    """The F test of the module docstring for a residual ``power`` = sum |E|^2 over lines whose
    noise variances are ``noise`` (one value per line and run); ``reference`` is the measured
    output's power over the same runs (:attr:`Residual.output_power`), the scale of numerical
    precision for a zero noise floor (without it a zero noise gives an undecided, NaN test)."""
    from scipy.stats import f as f_dist

    noise = noise[np.isfinite(noise)]
    total = float(np.sum(noise))
    if noise.size == 0 or n_periods < 2:
        return Test(float("nan"), float("nan"), float("nan"), float("nan"))
    if negligible(total, reference):
        exact = negligible(power, reference)
        return Test(float("nan"), float("nan"), float("nan"), float("nan") if exact else 0.0, True, exact)
    if total <= 0:
        return Test(float("nan"), float("nan"), float("nan"), float("nan"))
    dof = 2 * total**2 / float(np.sum(noise**2))
    noise_dof = dof * (n_periods - 1)
    ratio = power / total
    return Test(db(ratio), dof, noise_dof, float(f_dist.sf(ratio, dof, noise_dof)))


def error_power(residuals: list[Residual]) -> tuple[float, float]:
    """Mean power per run of the residual's mean period without its mean value (all AC lines), and
    of the noise in it (its variance ``noise_var`` summed over the same lines)."""
    e_power = n_power = 0.0
    for res in residuals:
        k = ac_lines(res.period)
        e_power += 2 * float(np.sum(np.abs(res.spectrum[k]) ** 2))
        n_power += 2 * float(np.sum(res.noise_var[k]))
    return e_power / len(residuals), n_power / len(residuals)


def error_test(residuals: list[Residual]) -> Test:
    """:func:`power_test` of the whole residual (all AC lines of all the runs) against its noise."""
    power = sum(float(np.sum(np.abs(res.spectrum[ac_lines(res.period)]) ** 2)) for res in residuals)
    noise = np.concatenate([res.noise_var[ac_lines(res.period)] for res in residuals])
    return power_test(power, noise, min(res.n_periods for res in residuals), measured_power(residuals))


def verdict_dof(residuals: list[Residual]) -> float:
    """Degrees of freedom of the noise behind the verdict's F rule: the Satterthwaite value of
    :func:`error_test`; with a zero noise floor (no noise to count) its upper limit, 2 per AC line
    (equal variances on every line), so that an improvement must still exceed the spread a
    residual of that many lines would show; with no noise level at all, that of the validation
    error (:func:`residual_dof`)."""
    test = error_test(residuals)
    if test.noise_zero:
        return 2.0 * sum(ac_lines(res.period).size for res in residuals)
    if not test.noise_known:
        return residual_dof(residuals)
    return test.dof


def residual_dof(residuals: list[Residual]) -> float:
    """Degrees of freedom of the validation error itself when no noise level is known (P = 1):
    the Satterthwaite value ``2 (sum P_k)^2 / sum P_k^2`` of its line powers P_k over the AC lines
    of the validation runs. An error concentrated on a few lines (harmonics of friction) gets few
    degrees of freedom, so the F rule between two models' errors stays conservative."""
    powers = np.concatenate([np.abs(res.spectrum[ac_lines(res.period)]) ** 2 for res in residuals])
    total = float(np.sum(powers))
    return 2.0 * total ** 2 / float(np.sum(powers ** 2)) if total > 0 else float("nan")


def line_tests(residuals: list[Residual]) -> dict[str, dict]:
    """Residual at the excited, odd and even in-band lines of multisine runs (module docstring)."""
    out = {}
    for name, kind in (("excited", EXCITED), ("odd", ODD), ("even", EVEN)):
        power, noise = 0.0, []
        for res in residuals:
            lines = classify_lines(res.period, res.fs, res.excited_bins)
            k = np.flatnonzero((lines.kind == kind) & lines.in_band)
            power += float(np.sum(np.abs(res.spectrum[k]) ** 2))
            noise.append(res.noise_var[k])
        noise = np.concatenate(noise) if noise else np.zeros(0)
        out[name] = power_test(power, noise, min(res.n_periods for res in residuals), measured_power(residuals)).summary()
        out[name]["lines"] = int(noise.size)
    return out


def harmonic_tests(residuals: list[Residual], runs: list[Run]) -> list[dict]:
    """Residual at the harmonics of every sine (frequency, amplitude) of the sine runs (module docstring)."""
    from nlsid.feeds import sine_bin

    groups: dict[tuple, list[tuple[Residual, int]]] = {}
    for res, run in zip(residuals, runs):
        if run.kind == "sine":
            groups.setdefault((run.frequency, run.level), []).append((res, sine_bin(run, f"run {run.run_id}")))
    out = []
    for (frequency, level), members in sorted(groups.items(), key=lambda item: (item[0][0], item[0][1] or 0.0)):
        P = min(res.n_periods for res, _ in members)
        reference = measured_power([res for res, _ in members])
        row = {"frequency_hz": frequency, "level": level, "runs": len(members), "harmonic_above_noise_db": []}
        limit = min(HARMONICS, min((res.period - 1) // 2 // k0 for res, k0 in members))
        for h in range(1, limit + 1):
            test = power_test(sum(float(abs(res.spectrum[h * k0]) ** 2) for res, k0 in members),
                              np.array([res.noise_var[h * k0] for res, k0 in members]), P, reference)
            row["harmonic_above_noise_db"].append(test.above_noise_db)
        for name, orders in (("fundamental", [1]), ("odd", range(3, limit + 1, 2)), ("even", range(2, limit + 1, 2))):
            power = sum(float(abs(res.spectrum[h * k0]) ** 2) for res, k0 in members for h in orders)
            noise = np.array([res.noise_var[h * k0] for res, k0 in members for h in orders])
            row[name] = power_test(power, noise, P, reference).summary()
        out.append(row)
    return out


def above_text(test: dict) -> str:
    """A test summary's residual against the noise in words (a zero floor has no dB value)."""
    if test.get("noise_floor_zero"):
        return "zero within numerical precision" if test.get("exact_match") else "above a zero noise floor"
    return f"{test['above_noise_db']:.1f} dB above the noise"


def p_text(p: float) -> str:
    """A p-value for reading: below double precision's resolution it is a bound, not 0."""
    return "p < 1e-15" if p < 1e-15 else f"p = {p:.2g}"
