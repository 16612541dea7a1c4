"""How accurate the simulation of a model is in its sub-steps, against the floor it is compared with.

A model with continuous-time forces depends on its sub-steps (:func:`_stepped`): the force laws are
held over each of the M sub-steps of a sample (:mod:`nlsid.models.forces`), and the error falls as
1/M at stick-slip transitions (first order) and as 1/M^2 for a smooth force (a cubic spring: measured 0.80, 0.23,
0.059, 0.015 mV at M = 10, 20, 40, 80 on a Duffing oscillator). The outputs at M, 2M and 4M on
the mean steady-state periods of the estimation runs (AC, as the residuals are compared) give
the observed order p = log2(|y_2M - y_M| / |y_4M - y_2M|), clipped to [1, 2] (Richardson's
estimate; e.g. Hairer, Norsett and Wanner 1993, Solving ODEs I, Sec. II.4), and the change from M
to 4M, which is within a factor 4/3 of the error of M at first order. The aim is a change below
ACCURACY times the floor: the noise in the averaged periods (the evidence's ``noise_rms``) where
it is measured, else the best model's validation error (``diagnose``: the final extended model's).
Where the aim is missed, the sub-steps that reach it are N = M (change / aim)^(1/p), rounded up
to tens (to whole sub-steps below 10); ``diagnose`` re-fits its final model at N when N <=
MAX_SUBSTEPS (the cost of a simulation with forces grows faster than M beyond about 40) and
otherwise says which N the data need. A static curve between two continuous filters
(``wiener_hammerstein``) is checked the same way from the engine's one sub-step: at one step the
curve's output is held over each sample into the second filter, while in the circuit it varies
within the sample. Filters with freedom to spare absorb that (a 5/6 BLA fit split over them: 0.41
mV of test error at one sub-step on the analog stand-in of tests/generators/wh_cases.py), filters of the
circuit's own orders cannot (a 2/6 fit: 1.45 mV at one sub-step, 0.18 mV re-fitted at 16,
:func:`refit_substeps`). A model written as equations (``derivatives``) is checked from its default
10 sub-steps too: RK4 with its switches located (:mod:`nlsid.models.equations`), whose error falls
as 1/M^4 where its expressions are smooth and as 1/M where a state meets a bound; the observed
order is clipped to [1, 2] like the others', which overstates the sub-steps it needs. Other models
are exact at one sub-step and are not checked.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.io.run import Run

ACCURACY = 0.1
MAX_SUBSTEPS = 80  # re-fitted at most at this (a simulation costs ~15x that at 10); beyond, the user's choice
STRUCTURE_SUBSTEPS = 16  # a block structure re-fitted at most at this (refit_substeps)
DEFAULT_SUBSTEPS = 10  # the engine's default for a plant with forces (nlsid.simulate.engine)


@dataclass(frozen=True)
class Accuracy:
    """The sub-steps used, the rms change of the output from them to four times as many, the floor
    (and what it is), the observed order of the error, and the sub-steps that would bring the
    change below a tenth of the floor; ``refit``: the final model was re-fitted at ``substeps``
    because the default missed the aim."""

    substeps: int
    change_rms: float
    floor_rms: float
    needed: int
    order: float = 1.0
    floor_from: str = "noise"
    refit: bool = False

    @property
    def sufficient(self) -> bool:
        return self.change_rms <= ACCURACY * self.floor_rms

    def note(self) -> str:
        text = (f"simulated with {self.substeps} sub-steps per sample (output change to {4 * self.substeps}: "
                f"{self.change_rms:.2g} rms, {'below' if self.sufficient else 'NOT below'} a tenth of the floor "
                f"{self.floor_rms:.2g}, {FLOOR_TEXT[self.floor_from]}; error of order {self.order:.1f} in the step)")
        if self.refit:
            text += "; re-fitted at these sub-steps, as the default missed a tenth of the floor"
        if not self.sufficient:
            text += f"; set simulation.substeps: {self.needed} in the model for a simulation accurate to the data"
        return text


FLOOR_TEXT = {"noise": "the noise in the averaged periods",
              "validation": "the final model's validation error (noise level unknown)",
              "model": "the model's validation error (noise level unknown)"}


def _structure(data: dict) -> bool:
    """A static curve between two filters (the block structure the engine steps once per sample
    unless told otherwise)."""
    return data["model"].get("type") == "wiener_hammerstein"


def _stepped(data: dict) -> bool:
    """The model's simulation depends on its sub-steps: continuous-time forces, or a static curve
    between two continuous filters (module docstring)."""
    model = data["model"]
    if _structure(data):
        return all(model[part].get("domain", "continuous") != "discrete" for part in ("first", "second"))
    if model.get("type") == "equations":  # RK4 sub-steps of its derivatives (nlsid.models.equations)
        return model.get("derivatives") is not None
    return bool(model.get("nonlinearities")) and model.get("linear", {}).get("domain") != "discrete"


def _ac_mean(runs: list[Run], outputs: list[np.ndarray]) -> np.ndarray:
    parts = []
    for run, y in zip(runs, outputs):
        period = steady_mean(run, y)
        parts.append(period - period.mean())
    return np.concatenate(parts)


def _outputs(data: dict, source: str, runs: list[Run], substeps: int, signal: str = "y") -> np.ndarray:
    trial = copy.deepcopy(data)
    trial.setdefault("simulation", {})["substeps"] = substeps
    runner = ModelRunner.from_data(trial, source)
    return _ac_mean(runs, runner.simulate_each(runs, signal))


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def _rounded(substeps: float) -> int:
    """Sub-steps rounded up: to whole ones below 10, else to tens."""
    return int(math.ceil(substeps)) if substeps <= 10 else int(math.ceil(substeps / 10) * 10)


def refit_substeps(found: Accuracy, data: dict) -> int | None:
    """The sub-steps to re-fit a model at whose step missed the aim. With forces: the ones needed,
    or None beyond MAX_SUBSTEPS (a simulation with forces at N sub-steps costs more than N times
    one; the note tells the user which N the data need). A static curve between two continuous
    filters: the ones needed, at most STRUCTURE_SUBSTEPS. Its step error is of first order with a
    large constant (the curve's output held over each sub-step into the second filter), so the
    need is in the hundreds, while each re-fit multiplies the cost of its simulations; measured on
    the analog stand-in of tests/generators/wh_cases.py at the SYSID 2009 benchmark's size (needed: 90 to
    1030): a 2/6 s fit's test error 1.45 mV at one sub-step, 0.18 mV re-fitted at 16 (35 s in
    all), 0.31 mV at 80 (96 s); a 5/6 fit 0.41 mV at one, 0.05 mV at 80 (435 s). That stand-in
    holds the curve's output over an eighth of a sample itself, so it cannot tell steps finer than
    8 apart; a circuit is continuous. The note still says which N the data need."""
    if _structure(data):
        return min(found.needed, STRUCTURE_SUBSTEPS)
    return found.needed if found.needed <= MAX_SUBSTEPS else None


def check(data: dict, source: str, runs: list[Run], floor_rms: float, floor_from: str = "noise",
          signal: str = "y") -> Accuracy | None:
    """The accuracy of the model ``data`` on ``runs`` (module docstring) in the judged ``signal``
    (the output ``y``, or in closed loop the command ``u``: the floor is that signal's); None for
    a model exact at one sub-step (:func:`_stepped`) or without a floor."""
    if not _stepped(data) or not math.isfinite(floor_rms) or floor_rms <= 0:
        return None
    m = int((data.get("simulation") or {}).get("substeps") or (1 if _structure(data) else DEFAULT_SUBSTEPS))
    y1, y2, y4 = (_outputs(data, source, runs, k * m, signal) for k in (1, 2, 4))
    first, second = _rms(y2 - y1), _rms(y4 - y2)
    order = min(max(math.log2(first / second), 1.0), 2.0) if first > 0 and second > 0 else 1.0
    change, aim = _rms(y4 - y1), ACCURACY * floor_rms
    needed = m if change <= aim else _rounded(m * (change / aim) ** (1 / order))
    return Accuracy(m, change, floor_rms, needed, order, floor_from)
