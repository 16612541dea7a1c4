"""The initial state of an arbitrary record, estimated from its measured output.

A record that does not start at rest (cut from a longer run, a machine already moving) holds at its
start the free response of the system to the state it was in. Simulated from rest, a model misses
that transient, and a fit of its parameters would bend them to explain it. So where the output is
measured, an arbitrary record is simulated "as measured" (:func:`nlsid.simulate.runs.simulate_run`
with ``steady``) from the initial state that fits its first samples best:

    y_sim = y_rest + O x0,   x0 = argmin || y[0:L] - y_rest[0:L] - O x0 ||,

with O (L x n) the free responses of the model's linear dynamics (a plant's state-space part,
forces, blocks and offsets aside; in closed loop the sampled loop with the reference at zero and the
controller at rest) from each unit plant state, and L the samples in which its slowest mode decays
to :data:`~nlsid.simulate.engine.STEADY_TOLERANCE`. This is the linear least-squares estimate of
x0 (Ljung 1999, System Identification, Sec. 10.1 on initial conditions), exact for an LTI model and
a first-order one for a nonlinear model, whose transient is that of its linearisation at rest.
Inside a fit it is variable projection: x0 is eliminated at every evaluation (Golub and Pereyra
1973). It costs the fit n degrees of freedom out of L samples.

A block structure's transient passes its static curves: its filters' states are fitted by
:mod:`nlsid.simulate.structure_state`. Not estimated (the record is simulated from rest, as
before): a model whose slowest mode does not decay within a quarter of the record
(an integrator, a mode the record cannot tell from an offset), and a run without a measured output.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from nlsid.io.run import Run
from nlsid.models import blocks
from nlsid.models.from_config import ClosedLoop, Offsets, Plant
from nlsid.simulate.engine import STEADY_TOLERANCE, _decay_rate, _loop_decay_rate, simulate_plant
from nlsid.simulate.noise import Noise

RECORD_SHARE = 0.25  # the free response must decay within this share of the record


def transient_length(plant: Plant, loop: ClosedLoop | None, run: Run) -> int | None:
    """Samples in which the slowest mode of the linear dynamics decays to STEADY_TOLERANCE, or None
    where that is longer than RECORD_SHARE of the record (or never)."""

    sigma = (_loop_decay_rate(plant, loop, run.fs, run.n_samples) if loop is not None
             else _decay_rate(plant.ss, run.fs))
    if not sigma > 0 or not math.isfinite(sigma):
        return None
    length = math.ceil(math.log(1 / STEADY_TOLERANCE) / sigma * run.fs)
    return length if length <= RECORD_SHARE * run.n_samples else None


def free_responses(plant: Plant, loop: ClosedLoop | None, run: Run, length: int) -> np.ndarray:
    """(length, n): the recorded output of the plant's linear dynamics from each unit initial state
    (module docstring), excitation zero."""
    linear = dataclasses.replace(plant, forces=[], input_block=blocks.encode(None), output_block=blocks.encode(None),
                                 offsets=Offsets(), force_bias=0.0)
    rest = Run(run.run_id, run.fs, "arbitrary", np.zeros(length))
    quiet = None if loop is None else dataclasses.replace(loop, excitation={})  # nor the drive's added channels
    n = plant.ss.order
    columns = [simulate_plant(dataclasses.replace(linear, x0=unit), quiet, rest, 1, Noise.zero(length)).y
               for unit in np.eye(n)]
    return np.column_stack(columns) if columns else np.zeros((length, 0))


@dataclass(frozen=True)
class InitialState:
    """The fitted initial plant state ``x0`` of a record (in the coordinates of the model's
    state-space form: a mass_spring_damper's position and velocity), the ``samples`` L it was
    fitted on and its free response ``transient`` = O x0 over them."""

    x0: np.ndarray
    samples: int
    transient: np.ndarray

    @property
    def transient_rms(self) -> float:
        return float(np.sqrt(np.mean(self.transient ** 2)))

    def summary(self) -> dict:
        """Plain numbers for JSON: ``samples``, ``x0``, ``transient_rms``."""
        return {"samples": int(self.samples), "x0": [float(x) for x in self.x0], "transient_rms": self.transient_rms}


def estimate(plant: Plant, loop: ClosedLoop | None, run: Run, simulated: Run) -> InitialState | None:
    """The initial state fitted to ``run``'s measured output, ``simulated`` being the model from
    rest on ``run`` (module docstring); None where none is estimated."""
    length = transient_length(plant, loop, run)
    if length is None or run.y is None or plant.ss.order == 0:
        return None
    basis = free_responses(plant, loop, run, length)
    x0, *_ = np.linalg.lstsq(basis, run.y[:length] - simulated.y[:length], rcond=None)
    return InitialState(x0, length, basis @ x0)


def with_initial_state(plant: Plant, loop: ClosedLoop | None, run: Run, simulated: Run) -> Run:
    """``simulated`` (the model from rest on ``run``) plus the free response of the initial state
    fitted to ``run``'s measured output (module docstring); unchanged where none is estimated."""
    state = estimate(plant, loop, run, simulated)
    if state is None:
        return simulated
    y = simulated.y.copy()
    y[:state.samples] += state.transient
    return dataclasses.replace(simulated, y=y)
