"""What the simulation gets wrong: the measured output against the model's, per line, level and time.

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

At the excited lines of each multisine level the measured BLA (robust method, book Section 6.1.1;
the reference method in closed loop) is compared with the model's BLA computed in the same way
from the simulated runs: per line the gain error ``20 log10 |G/G_model|`` (dB), the phase error,
and the test ``|G - G_model|^2 / var(G) > F_{0.95}(2, 2M - 2)`` of the measured BLA's total
variance (book (6-88), Exercise 92: the model's BLA lies outside the 95% confidence circle).
At the odd and even detection lines (book Section 6.1.2, seed 000 Fig. 3) the residual is the
distortion the model does not produce. Across levels (seed 000 Figs. 4-5) the change of the
measured and of the model's BLA with the excitation level.

On single-sine runs (the HOSIDF excitation, seed 000 Eqs. 8-12) the residual at the harmonics
h k0 of the tone's line k0 is what the model misses of each HOSIDF (the first, h = 1, its
describing function): per sine (frequency and amplitude, all its runs) the same F test at the
fundamental, at the odd harmonics 3, 5, ... and at the even harmonics 2, 4, ... up to
:data:`HARMONICS` (or the last line below Nyquist), and the size of each harmonic above the noise.
Odd harmonics point to an odd nonlinearity (friction, a cubic spring, saturation), even ones to
an even one (a quadratic output).

In time, the mean residual period of the highest level is kept with the model's internal signals
(plant input, and position and velocity of a mechanical template) for the figures that show a
jump at zero velocity or a cubic trend against position.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.analysis.lines import EVEN, EXCITED, ODD, classify_lines, spectra
from nlsid.analysis.modes import SIGNIFICANCE
from nlsid.analysis.output_spectrum import db
from nlsid.analysis.precision import PRECISION, negligible
from nlsid.diagnose.simulation import ModelRunner, steady_mean, steady_periods
from nlsid.diagnose.split import ESTIMATION
from nlsid.io.run import Run

ALPHA = 0.001
BLA_PROBABILITY = 0.95
HARMONICS = 9  # sine harmonics tested (the fundamental included)


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


def ac_lines(period: int) -> np.ndarray:
    """Lines 1 .. (N-1)//2: every line of the period but DC and Nyquist."""
    return np.arange(1, (period - 1) // 2 + 1)


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
    return power_test(power, noise, min(res.n_periods for res in residuals), _reference(residuals))


def _reference(residuals) -> float:
    """The measured output's power over these runs (the scale of numerical precision)."""
    return sum(res.output_power for res in residuals)


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
        out[name] = power_test(power, noise, min(res.n_periods for res in residuals), _reference(residuals)).summary()
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
        reference = _reference([res for res, _ in members])
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


def compare_bla(measured, model) -> dict:
    """Measured BLA against the model's at one level's excited lines (module docstring)."""
    from nlsid.analysis.confidence import f_quantile_2

    G, Gm = measured.robust.G, model.robust.G
    M = measured.robust.n_realizations
    variance = measured.robust.var_total
    observations = M
    if not np.all(np.isfinite(variance)):
        variance, observations = measured.robust.var_noise, M * measured.robust.n_periods
    threshold = f_quantile_2(BLA_PROBABILITY, 2 * observations - 2)
    # noise-free data: a zero variance is the numerical precision of G (a circle of that radius)
    variance = np.maximum(variance, PRECISION**2 * np.abs(G) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(G - Gm) ** 2 / variance
    outside = z > threshold
    with np.errstate(divide="ignore"):  # a measured G of exactly 0 (a constant output): -inf dB, said in words
        gain_db = 20 * np.log10(np.abs(G) / np.abs(Gm))
    phase_deg = np.degrees(np.angle(G / Gm))
    freq = measured.lines.frequency(measured.lines.excited)
    worst = int(np.argmax(np.where(outside, np.abs(gain_db), -1))) if outside.any() else None
    return {
        "level": measured.level, "u_rms": measured.u_rms, "lines": int(G.size),
        "outside_bounds": int(outside.sum()), "outside_fraction": float(outside.mean()),
        "expected_fraction": 1 - BLA_PROBABILITY,
        "gain_error_max_db": float(gain_db[np.argmax(np.abs(gain_db))]),
        "phase_error_max_deg": float(phase_deg[np.argmax(np.abs(phase_deg))]),
        "worst_frequency_hz": float(freq[worst]) if worst is not None else float("nan"),
        "frequency_hz": freq, "G": G, "G_model": Gm, "radius": measured.robust.bounds.radius,
        "gain_error_db": gain_db, "phase_error_deg": phase_deg, "outside": outside,
    }


def bla_significant(row: dict) -> bool:
    """More lines outside the 95% circles than chance: a binomial test at :data:`ALPHA`."""
    from scipy.stats import binom

    return bool(binom.sf(row["outside_bounds"] - 1, row["lines"], row["expected_fraction"]) < ALPHA)


@dataclass
class Evidence:
    """Everything ``diagnose`` measured about the discrepancy (see :meth:`summary`)."""

    residuals: list[Residual]
    overall: Test
    lines: list[dict]
    bla: list[dict]
    levels: list[dict]
    time: dict
    noise_rms: float
    error_rms: float
    spectra: dict = field(default_factory=dict)
    bla_levels: tuple = ()
    harmonics: list[dict] = field(default_factory=list)
    output_rms: float = float("nan")  # of the measured mean periods (AC lines), as error_rms
    constant_runs: list[str] = field(default_factory=list)  # runs whose measured y never changes
    across: dict = field(default_factory=dict)  # the measured across_levels without its rows

    @property
    def constant_output(self) -> bool:
        """The measured output is constant in every run: nothing responded to the input, so no
        extension of the model can explain anything (its error is its whole response)."""
        return bool(self.residuals) and len(self.constant_runs) == len(self.residuals)

    @property
    def noise_zero(self) -> bool:
        """The noise floor is zero within numerical precision (noise-free data)."""
        return self.overall.noise_zero

    @property
    def exact(self) -> bool:
        """Noise-free data that the model reproduces within numerical precision."""
        return self.overall.exact

    @property
    def odd_seen(self) -> bool:
        return any(row["odd"]["significant"] for row in self.lines + self.harmonics)

    @property
    def even_seen(self) -> bool:
        return any(row["even"]["significant"] for row in self.lines + self.harmonics)

    @property
    def distortion_testable(self) -> bool:
        """Odd and even detection lines (or harmonics of sine runs) with a measured noise level
        both exist, so that :attr:`odd_seen` and :attr:`even_seen` false mean no distortion seen
        (a multisine without odd detection lines cannot show an odd nonlinearity)."""
        return all(any(row[kind]["noise_known"] and row[kind].get("lines", 1) > 0 for row in self.lines + self.harmonics)
                   for kind in ("odd", "even"))

    @property
    def linear_seen(self) -> bool:
        return any(row["significant"] for row in self.bla)

    def summary(self) -> dict:
        return {
            "error_rms": self.error_rms, "noise_rms": self.noise_rms, "output_rms": self.output_rms,
            "noise_floor_zero": self.noise_zero, "exact_match": self.exact,
            "error_above_noise": self.overall.summary(),
            "lines": self.lines,
            "bla": [{k: v for k, v in row.items() if not isinstance(v, np.ndarray)} for row in self.bla],
            "levels": self.levels, "across_levels": self.across,
            "harmonics": self.harmonics,
            "odd_distortion_unexplained": self.odd_seen, "even_distortion_unexplained": self.even_seen,
            "linear_mismatch": self.linear_seen, "constant_output_runs": self.constant_runs,
        }

    def findings(self) -> list[str]:
        """What the simulation gets wrong, in words, each with its size."""
        if self.exact:
            out = [f"simulation error {self.error_rms:.3g} rms against an output of {self.output_rms:.3g} rms: zero "
                   "within numerical precision; the noise floor is zero (noise-free data)"]
        elif self.noise_zero:
            out = [f"simulation error {self.error_rms:.3g} rms against a zero noise floor (noise-free data: every "
                   "residual above numerical precision is significant)"]
        elif not self.overall.noise_known:
            out = [f"simulation error {self.error_rms:.3g} rms against an output of {self.output_rms:.3g} rms; the "
                   "noise level is unknown (no two periods per run): the error is judged on validation runs alone"]
        else:
            out = [f"simulation error {self.error_rms:.3g} rms against the noise in it of {self.noise_rms:.3g} "
                   f"({self.overall.above_noise_db:+.1f} dB, {_p_text(self.overall.p_value)})"]
        out += self._constant_findings()
        for row in self.bla:
            if row["significant"]:
                worst = (f"up to {row['gain_error_max_db']:+.1f} dB" if math.isfinite(row["gain_error_max_db"])
                         else "the measured BLA is zero at some lines (no response there)")
                out.append(f"level {_name(row['level'])}: model FRF outside the BLA's 95% bounds at "
                           f"{row['outside_bounds']} of {row['lines']} lines; {worst} "
                           f"(worst near {row['worst_frequency_hz']:.3g} Hz) and {row['phase_error_max_deg']:+.0f} deg")
        for row in self.lines:
            for name in ("odd", "even"):
                test = row[name]
                if test["significant"]:
                    out.append(f"level {_name(row['level'])}: {name} distortion the model does not produce, "
                               f"{_above_text(test)}")
        out += self._harmonic_findings()
        out += level_findings(self.levels, self.across)
        return out


    def _constant_findings(self) -> list[str]:
        """The runs whose measured output is constant, said (they are kept, not dropped)."""
        if not self.constant_runs:
            return []
        if self.constant_output:
            return [f"the measured output y is constant in every run ({len(self.constant_runs)}): the system did not "
                    "respond to the input, or y is not the sensor's signal; there is nothing a model extension could "
                    f"explain, and the model's error is its whole response ({self.error_rms:.3g} rms)"]
        shown = ", ".join(self.constant_runs[:5]) + (", ..." if len(self.constant_runs) > 5 else "")
        return [f"the measured output y is constant in {len(self.constant_runs)} of {len(self.residuals)} runs "
                f"({shown}): no response there (a mass held by friction below its break-away force, or a sensor "
                "below its resolution?)"]

    def _harmonic_findings(self) -> list[str]:
        """One line per harmonic class over all sine cells (the per-cell numbers are in the summary)."""
        out = []
        cells = len(self.harmonics)
        frequencies = sorted({row["frequency_hz"] for row in self.harmonics})
        for name in ("odd", "even"):
            seen = [row[name]["above_noise_db"] for row in self.harmonics if row[name]["significant"]]
            if seen:
                finite = [x for x in seen if math.isfinite(x)]
                size = (f"{min(finite):.0f} to {max(finite):.0f} dB above the noise" if len(finite) == len(seen)
                        else "above a zero noise floor" if not finite
                        else f"up to {max(finite):.0f} dB above the noise, in the others above a zero noise floor")
                out.append(f"sines ({cells} cells, {frequencies[0]:g} to {frequencies[-1]:g} Hz): {name} harmonics "
                           f"the model does not produce in {len(seen)} of {cells} cells, {size}")
        return out


def level_findings(rows: list[dict], across: dict) -> list[str]:
    """The change of the measured BLA over the levels and the model's, in words, or why there is none.

    ``rows`` are :func:`nlsid.analysis.levels.across_levels` rows with ``model_bla_change_max_db``,
    ``across`` the rest of the measured ``across_levels`` (``not_compared``, ``lines_compared``).
    The change is that of the highest level compared with the reference (the lowest), on the lines
    excited at every level: a level that was not compared never reads as a change of 0 dB.
    """
    if len(rows) < 2:
        return []
    compared = [row for row in rows if row.get("bla_change_max_db") is not None]
    if not compared:
        reasons = sorted({row["bla_not_compared"] for row in rows[1:] if row.get("bla_not_compared")})
        return [f"BLA not compared over the levels: {'; '.join(reasons) or 'no common lines'}"]
    out = _mode_findings(across.get("modes", []))
    last = compared[-1]
    model = last.get("model_bla_change_max_db")
    model_text = "" if model is None or not math.isfinite(model) else f"; the model's by {model:+.1f} dB"
    aside = [row for row in rows[1:] if row.get("bla_change_max_db") is None]
    return [f"BLA changes by up to {last['bla_change_max_db']:+.1f} dB (mean {last['bla_change_mean_db']:+.2f} dB "
            f"over {last['bla_compared_lines']} lines excited at every level) from level {_name(rows[0]['level'])} "
            f"to level {_name(last['level'])}{model_text}"
            + (f"; {len(aside)} level(s) not compared ({aside[0]['bla_not_compared']})" if aside else "")] + out


def _mode_findings(modes: list[dict]) -> list[str]:
    """Each resonance whose frequency or damping changes significantly from the lowest to the highest
    level, with the relative changes and their standard errors (:mod:`nlsid.analysis.modes`); the
    others in one line."""
    out, quiet, alone = [], [], []
    for mode in modes:
        if mode["significant"]:
            out.append(f"mode near {mode['frequency_hz']:.3g} Hz: frequency {_percent(mode, 'frequency')}, damping "
                       f"{_percent(mode, 'damping')} from level {_name(mode['from_level'])} to level "
                       f"{_name(mode['to_level'])}: significant ({SIGNIFICANCE:g} standard errors)")
        elif mode["to_level"] == mode["from_level"]:
            alone.append(f"{mode['frequency_hz']:.3g}")
        else:
            quiet.append(f"{mode['frequency_hz']:.3g}")
    if quiet:
        out.append(f"mode{'s' if len(quiet) > 1 else ''} near {', '.join(quiet)} Hz: no significant change of "
                   "frequency or damping over the levels")
    if alone:
        out.append(f"mode{'s' if len(alone) > 1 else ''} near {', '.join(alone)} Hz: fitted at the lowest level only")
    return out


def _percent(mode: dict, name: str) -> str:
    """A relative change and its standard error in percent, e.g. ``-1.3 % +- 0.07 %``."""
    return f"{100 * mode[f'{name}_change']:+.2g} % +- {100 * mode[f'{name}_change_se']:.2g} %"


def _above_text(test: dict) -> str:
    """A test summary's residual against the noise in words (a zero floor has no dB value)."""
    if test.get("noise_floor_zero"):
        return "zero within numerical precision" if test.get("exact_match") else "above a zero noise floor"
    return f"{test['above_noise_db']:.1f} dB above the noise"


def _p_text(p: float) -> str:
    """A p-value for reading: below double precision's resolution it is a bound, not 0."""
    return "p < 1e-15" if p < 1e-15 else f"p = {p:.2g}"


def _name(level) -> str:
    return "-" if level is None else f"{level:g}"


def gather(runner: ModelRunner, runs: list[Run], roles: dict[str, str],
           source: str = "", signal: str = "y") -> tuple[Evidence, dict[str, Run]]:
    """Simulate the model on every periodic run and measure the discrepancy (module docstring).

    ``signal``: the judged signal, the output ``y`` or in closed loop the command ``u``: the
    residuals, the noise floor, the line and harmonic tests and the time signals are of it (the
    BLA comparison stays that of the output). Returns the evidence and the model's simulated runs
    keyed by run id. ``source`` (the recording) prefixes the runs in error messages:
    ``source:/runs/<id>``.
    """
    from nlsid.analysis.levels import across_levels, analyse_runs, common_lines

    used = [run for run in runs if run.run_id in roles]
    simulated = {run.run_id: runner.simulate(run) for run in used}
    residuals = [residual_of(run, getattr(simulated[run.run_id], signal), roles[run.run_id], signal) for run in used]
    multisine = [run for run in used if run.kind == "multisine"]
    lines, bla, levels, spectra_, across = [], [], [], {}, {}
    measured_levels = model_levels = ()
    if multisine:
        model_runs = [_as_measured(simulated[run.run_id], run) for run in multisine]
        where = (lambda run: f"{source}:/runs/{run.run_id}") if source else (lambda run: run.run_id)
        measured_levels, _ = analyse_runs(((run, where(run)) for run in multisine), "auto", BLA_PROBABILITY)
        model_levels, _ = analyse_runs(((run, run.run_id) for run in model_runs), "auto", BLA_PROBABILITY)
        for measured, model in zip(measured_levels, model_levels):
            members = [res for res in residuals if res.kind == "multisine" and res.level == measured.level]
            row = line_tests(members)
            row["level"] = measured.level
            row["u_rms"] = measured.u_rms
            lines.append(row)
            comparison = compare_bla(measured, model)
            comparison["significant"] = bla_significant(comparison)
            bla.append(comparison)
            spectra_[measured.level] = (measured.spectrum, model.spectrum, measured.lines)
        common = common_lines(list(measured_levels))  # the model is compared on the measured lines
        measured_across = across_levels(list(measured_levels), common)
        across = {key: value for key, value in measured_across.items() if key != "levels"}
        model_across = across_levels(list(model_levels), common, modes=False)
        for row, model_row in zip(measured_across["levels"], model_across["levels"]):
            row["model_bla_change_max_db"] = model_row["bla_change_max_db"]
            row["model_bla_db"] = model_row["bla_db"]
            levels.append(row)
    error, noise = error_power(residuals)
    output = 2 * _reference(residuals) / len(residuals)  # mean power per run, as error_power
    return Evidence(
        residuals=residuals, overall=error_test(residuals), lines=lines, bla=bla, levels=levels,
        time=_time_signals(runner, used, residuals), noise_rms=math.sqrt(noise), error_rms=math.sqrt(error),
        spectra=spectra_, bla_levels=(measured_levels, model_levels), harmonics=harmonic_tests(residuals, used),
        output_rms=math.sqrt(output),
        constant_runs=[run.run_id for run in used if run.y.size and np.ptp(run.y) == 0], across=across,
    ), simulated


def _as_measured(simulated: Run, measured: Run) -> Run:
    """A simulated run with the measured run's metadata (its own u, y and, in closed loop, r)."""
    return dataclasses.replace(measured, u=simulated.u, y=simulated.y, r=simulated.r)


def _time_signals(runner: ModelRunner, runs: list[Run], residuals: list[Residual]) -> dict:
    """Mean residual period of the strongest estimation run with the model's internal signals."""
    candidates = [(run, res) for run, res in zip(runs, residuals) if res.role == ESTIMATION]
    run, res = max(candidates, key=lambda pair: float(np.std(pair[0].periods("u"))))
    internal = runner.internal(run)
    out = {"run_id": run.run_id, "fs": run.fs, "residual": res.residual, "measured": res.measured,
           "model": res.model}
    for name, signal in internal.items():
        out[name] = steady_mean(run, signal)
    return out
