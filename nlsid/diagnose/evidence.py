"""What the simulation gets wrong: the measured output against the model's, per line, level and time.

The model is simulated on every periodic run and the discrepancy measured: the residual of each run
(:mod:`nlsid.diagnose.residual`), its size against the noise at the excited, odd and even lines and at
the harmonics of sine runs (:mod:`nlsid.diagnose.significance`), and the measured BLA against the
model's per level and over the levels (:mod:`nlsid.diagnose.bla_comparison`).

In time, the mean residual period of the highest level is kept with the model's internal signals
(plant input, and position and velocity of a mechanical template) for the figures that show a
jump at zero velocity or a cubic trend against position.

"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.diagnose.bla_comparison import BLA_PROBABILITY, bla_significant, compare_bla, level_findings, level_name
from nlsid.diagnose.residual import Residual, measured_power, residual_of
from nlsid.diagnose.significance import Test, above_text, error_power, error_test, harmonic_tests, line_tests, p_text
from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.diagnose.split import ESTIMATION
from nlsid.io.run import Run


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
                   f"({self.overall.above_noise_db:+.1f} dB, {p_text(self.overall.p_value)})"]
        out += self._constant_findings()
        for row in self.bla:
            if row["significant"]:
                worst = (f"up to {row['gain_error_max_db']:+.1f} dB" if math.isfinite(row["gain_error_max_db"])
                         else "the measured BLA is zero at some lines (no response there)")
                out.append(f"level {level_name(row['level'])}: model FRF outside the BLA's 95% bounds at "
                           f"{row['outside_bounds']} of {row['lines']} lines; {worst} "
                           f"(worst near {row['worst_frequency_hz']:.3g} Hz) and {row['phase_error_max_deg']:+.0f} deg")
        for row in self.lines:
            for name in ("odd", "even"):
                test = row[name]
                if test["significant"]:
                    out.append(f"level {level_name(row['level'])}: {name} distortion the model does not produce, "
                               f"{above_text(test)}")
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
    output = 2 * measured_power(residuals) / len(residuals)  # mean power per run, as error_power
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
