"""Nuisances: what every measurement carries and no cause explains, estimated before any hypothesis.

Real converters add a DC offset at the sensor (``output_offset``), one at the actuator
(``input_offset``, or a constant force on a mechanical template's mass, ``force_offset``) and a
sampling skew between the DAC update and the ADC sample (``output_timing``, |t| < 1 sample). Left in
the data they would be read as causes: a skew is a phase error growing linearly with frequency (a
"dead time" below a sample), an offset shifts where friction sticks and biases every fit of the
simulation error. So ``diagnose`` first fits them, together, to the estimation runs by the fit
engine (:func:`nlsid.fit.extension.fit_free_parameters`, the simulation error), writes them into the
model every hypothesis starts from, and reports them separately: they are never named as causes.

Which nuisances are fitted (those the data can tell apart, and the model can express):

- ``output_offset`` but in closed loop around a plant whose motion does not depend on where it is
  (:func:`_translation_invariant`: the loop cancels it);
- ``output_timing`` on a continuous plant (a discrete model has no values between samples; a
  structure has no timing key), within (-1, 1) samples, and in closed loop at most the plant's dead
  time (a lead needs as much dead time, :func:`nlsid.simulate.engine.timing`); within [0, 1) where
  the output has a direct term in the input (a feedthrough D, a force point's feedthrough: an
  acceleration output), which steps with the held input at each sample instant: a lag reads the
  previous sample's input, no small shift of a lead (the error jumps at 0, and a fit started
  there by central differences was carried into the lag and stuck 45 dB above the floor);
- an input-side offset only where it differs from an output offset: ``input_offset`` in closed
  loop or with an input block, else ``force_offset`` on a mechanical model with forces that can
  see it (:func:`_force_offset_seen`). On a linear open-loop model both give a constant output, so
  only the output's is fitted.

A value the model already has is the start. A timing that runs into its bound (a shift of a
sample or more) is not a skew but a dead time, a cause: it is then left out and left to the delay
hypothesis. Fitted on a model that lacks the cause, the nuisances may absorb part of it, so each
hypothesis re-fits them with its own parameters (:func:`nlsid.diagnose.diagnosis.refine`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from nlsid.diagnose.simulation import MECHANICAL, ModelRunner
from nlsid.io.run import Run
from nlsid.models.parameter_units import with_unit

KEYS = ("output_offset", "input_offset", "force_offset", "output_timing")  # the model keys of the nuisances
MAX_EVALUATIONS = 40
TIMING_LIMIT = 0.99  # |output_timing| below one sample (the key's range is open)
AT_BOUND = 0.02     # a timing this close to its bound is a longer shift (a dead time), not a skew


@dataclass(frozen=True)
class Nuisances:
    """Fitted nuisance values (model key -> value), their standard errors, the fit's notes."""

    values: dict[str, float] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    initial: dict = field(default_factory=dict)  # run id -> InitialState of an arbitrary record

    def summary(self) -> dict:
        initial = [{"run_id": run_id, **state.summary()} for run_id, state in self.initial.items()]
        return {"values": dict(self.values), "std": dict(self.std), "notes": list(self.notes),
                "initial_state": initial}

    def findings(self, unit: Callable[[str], str | None] = lambda key: None) -> list[str]:
        """The nuisances in words, each value with ``unit(key)`` where that is known."""
        out = []
        if self.values:
            parts = ", ".join(with_unit(f"{key} = {value:.4g} +- {self.std[key]:.2g}", unit(key))
                              for key, value in self.values.items())
            out.append(f"nuisances estimated first (not causes): {parts}")
        if self.initial:
            largest = max(self.initial.values(), key=lambda state: state.transient_rms)
            out.append(f"initial state fitted to the start of {len(self.initial)} arbitrary record(s) (not a cause): "
                       f"its free response up to {largest.transient_rms:.3g} rms over the first {largest.samples} samples")
        return out


def initial_states(runner: ModelRunner, runs: list[Run]) -> dict:
    """Run id -> the initial state the model ``runner`` (with its nuisances) fits to each arbitrary
    record of ``runs`` (:meth:`ModelRunner.initial_state`), where one is fitted."""
    states = {run.run_id: runner.initial_state(run) for run in runs}
    return {run_id: state for run_id, state in states.items() if state is not None}


def _rms(runs: list[Run], signal: str) -> float:
    values = [getattr(run, signal) for run in runs if getattr(run, signal) is not None]
    return float(np.sqrt(np.mean(np.concatenate(values) ** 2))) if values else 1.0


def _timing_bounds(runner: ModelRunner, fs: float) -> tuple[float, float] | None:
    """(lower, upper) of ``output_timing``, or None where the model has no timing to fit."""
    model = runner.data["model"]
    if runner.kind not in MECHANICAL + ("transfer_function", "zpk", "state_space", "nonlinear_feedback"):
        return None
    if model.get("domain") == "discrete" or (runner.kind == "nonlinear_feedback"
                                             and model["linear"].get("domain") == "discrete"):
        return None
    upper = TIMING_LIMIT
    if runner.closed:
        loop = runner.data.get("closed_loop", {})
        dead = float(model.get("delay", 0.0)) * fs + int(loop.get("computation_delay", 0))
        upper = min(TIMING_LIMIT, dead)
    return (0.0 if _steps_with_the_input(runner) else -TIMING_LIMIT), upper


def _steps_with_the_input(runner: ModelRunner) -> bool:
    """The output has a direct term in the held input (module docstring)."""
    from nlsid.models.from_config import Plant

    plant = runner.plant
    return isinstance(plant, Plant) and (plant.ss.D != 0 or any(force.output for force in plant.forces))


POSITION_FORCES = ("cubic_stiffness", "polynomial_stiffness")  # forces that read the position


def _translation_invariant(model: dict) -> bool:
    """The plant's motion does not depend on where it is: a position output of a mechanical
    template without a spring to the ground, or of a transfer function with an integrator (a pole
    at s = 0, z = 1), and no force that reads the position. In closed loop the controller then
    moves the plant to wherever the offset sensor reads the reference, and nothing else changes:
    an output offset is not identifiable (but through the start of the record, which the initial
    state absorbs; fitted anyway it wandered to 0.4 m on an axis stand-in and stopped the fit of
    its friction at 2.5e-6 m instead of 1.9e-8 m)."""
    if model.get("output", "position") != "position":
        return False
    if any(f.get("type") in POSITION_FORCES for f in model.get("nonlinearities") or []):
        return False
    kind = model["type"]
    if kind == "mass_spring_damper":
        return float(model.get("stiffness", 0.0)) == 0.0
    lti = model.get("linear", model) if kind == "nonlinear_feedback" else model
    if lti.get("type") != "transfer_function":
        return False
    den = np.asarray(lti["den"], float)
    return bool(den.sum() == 0.0) if lti.get("domain") == "discrete" else bool(den[-1] == 0.0)


def _force_offset_seen(model: dict) -> bool:
    """A constant force differs from a sensor offset in open loop only where the mechanics has no
    spring to the ground to turn it into a constant displacement (a free mass: friction then sees
    it), or a force reads the position (a cubic or polynomial spring): velocity-only forces on a
    sprung mass see the same motion about a shifted rest position. Around a transfer function
    (``nonlinear_feedback``) the spring is a static gain of the linear part (:func:`_sprung`); an
    end stop there keeps the force offset (with the edges free it is a direction of the fit, which
    the refinement needed to reach the floor: nlsid/diagnose/hypotheses/end_stops.py)."""
    forces = model.get("nonlinearities") or []
    if not forces:
        return False
    if any(f.get("type") in POSITION_FORCES for f in forces):
        return True
    if model["type"] == "nonlinear_feedback":
        return any(f.get("type") == "end_stop" for f in forces) or not _sprung(model["linear"])
    return model["type"] != "mass_spring_damper" or float(model.get("stiffness", 0.0)) == 0.0


def _sprung(lti: dict) -> bool:
    """A transfer function config with a finite nonzero static gain, after cancelling the factors
    s (a continuous G / s with G(0) = 0, as the velocity reading of a sprung mass is) common to its
    numerator and denominator; other LTI configs are not judged (False)."""
    if lti.get("type") != "transfer_function":
        return False
    num, den = np.asarray(lti["num"], float), np.asarray(lti["den"], float)
    if lti.get("domain") == "discrete":
        return bool(den.sum() != 0.0 and num.sum() != 0.0)
    num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
    while num.size > 1 and den.size > 1 and num[-1] == 0.0 and den[-1] == 0.0:
        num, den = num[:-1], den[:-1]
    return bool(num.size and den[-1] != 0.0 and num[-1] != 0.0)


def free_nuisances(runner: ModelRunner, runs: list[Run], timing: bool = True) -> dict:
    """The nuisance keys to fit (module docstring) with start and bounds (:class:`FreeParameter`);
    ``timing`` False leaves the output timing out."""
    from nlsid.fit.free_parameters import FreeParameter

    model = runner.data["model"]
    y_scale, u_scale = _rms(runs, "y") or 1.0, _rms(runs, "u") or 1.0

    def offset(key: str, scale: float) -> FreeParameter:
        start = float(model.get(key, 0.0))
        return FreeParameter(start, start - 10 * scale, start + 10 * scale)

    free = {}
    if not (runner.closed and _translation_invariant(model)):
        free["model.output_offset"] = offset("output_offset", y_scale)
    if runner.closed or model.get("input_nonlinearity") is not None:
        free["model.input_offset"] = offset("input_offset", u_scale)
    elif _force_offset_seen(model):
        free["model.force_offset"] = offset("force_offset", abs(float(model.get("gain", 1.0))) * u_scale)
    bounds = _timing_bounds(runner, runs[0].fs) if timing else None
    if bounds is not None and bounds[1] > bounds[0]:
        start = min(max(float(model.get("output_timing", 0.0)), bounds[0]), bounds[1])
        free["model.output_timing"] = FreeParameter(start, *bounds)
    return free


def estimate(data: dict, source: str, runs: list[Run], fit_on: str = "y") -> tuple[dict, Nuisances]:
    """The model config with its nuisances fitted to ``runs`` (estimation runs) on the judged
    signal ``fit_on`` (``y``, or in closed loop ``u``), and the values."""
    from nlsid.fit.extension import fit_free_parameters

    runner = ModelRunner.from_data(data, source)
    free = free_nuisances(runner, runs)
    if not free:
        return data, Nuisances()
    fit = fit_free_parameters(data, free, runs, [], source=source, max_evaluations=MAX_EVALUATIONS, fit_on=fit_on,
                              run_errors=False)
    timing = free.get("model.output_timing")
    if timing is not None and not timing.lower + AT_BOUND < fit.value("model.output_timing") < timing.upper - AT_BOUND:
        # a shift of a sample or more is a dead time, a cause: left to the delay hypothesis
        free.pop("model.output_timing")
        fit = fit_free_parameters(data, free, runs, [], source=source, max_evaluations=MAX_EVALUATIONS,
                                  fit_on=fit_on, run_errors=False)
    return fit.config, fitted(fit)


def fitted(fit) -> Nuisances:
    """The nuisances among a fit's free parameters (:class:`nlsid.fit.extension.ExtensionFit`, key
    paths ``model.<key>`` for the keys of :data:`KEYS`): values, standard errors (NaN where not
    finite) and the fit's warnings."""
    values, std = {}, {}
    for path, value, s in zip(fit.names, fit.values, fit.std):
        key = path.split(".", 1)[1] if path.startswith("model.") else ""
        if key in KEYS:
            values[key], std[key] = float(value), float(s) if math.isfinite(s) else float("nan")
    return Nuisances(values, std, list(fit.warnings))


def moved(before: Nuisances, after: Nuisances, limit: float) -> list[dict]:
    """The nuisances whose values differ between two fits by more than ``limit`` combined standard
    errors, ``|a - b| > limit sqrt(s_a^2 + s_b^2)`` (NaN standard errors left out of the sum; a
    pair without any finite one is not judged): fitted on a model that lacks a cause, a nuisance
    takes what it can of the cause (an output timing a friction's phase lag), so a value that moves
    once the cause is in the model was not a fact about the converters. Per moved key: ``key``,
    ``before``, ``after`` (values), ``std_before``, ``std_after``, ``standard_errors`` (the
    difference over the combined standard error)."""
    out = []
    for key, a in before.values.items():
        if key not in after.values:
            continue
        b = after.values[key]
        sa, sb = before.std.get(key, float("nan")), after.std.get(key, float("nan"))
        combined = math.sqrt(sum(x * x for x in (sa, sb) if math.isfinite(x)))
        if combined > 0 and abs(a - b) > limit * combined:
            out.append({"key": key, "before": a, "after": b, "std_before": sa, "std_after": sb,
                        "standard_errors": abs(a - b) / combined})
    return out
