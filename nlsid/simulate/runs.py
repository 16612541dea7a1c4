"""Simulating one run as it was measured: from the periodic steady state of a periodic run, or from
the initial state that fits an arbitrary record's first samples.

:mod:`nlsid.simulate.engine` simulates a plant or a block structure from rest (or a given state);
this module puts in front of it what a measured run needs: the lead-in periods
(:func:`nlsid.simulate.engine.lead_periods`) and the initial states of
:mod:`nlsid.simulate.initial_state` and :mod:`nlsid.simulate.structure_state`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nlsid.io.run import Run
from nlsid.models.equations import Equations
from nlsid.models.lti import MimoStateSpace
from nlsid.models.hybrid import Hybrid
from nlsid.models.pnlss import Pnlss
from nlsid.models.from_config import ClosedLoop, Plant, Structure
from nlsid.simulate.engine import _lead, lead_periods, simulate_equations, simulate_plant, simulate_structure, with_lead
from nlsid.simulate import equations_state
from nlsid.simulate.initial_state import estimate as estimate_plant, with_initial_state
from nlsid.simulate.loop_state import estimate as estimate_loop, simulate_from_start
from nlsid.simulate.mimo import simulate_mimo
from nlsid.simulate.pnlss_runs import simulate_measured, simulate_pnlss
from nlsid.simulate.noise import Noise
from nlsid.simulate.structure_state import estimate as estimate_structure, with_initial_states


def simulate_run(model: Plant | Structure | Equations, loop: ClosedLoop | None, run: Run, substeps: int | None,
                 noise: Noise | None = None, steady: bool = False) -> Run:
    """Simulate one run; ``noise`` defaults to none. ``steady`` (the run as it was measured): a
    periodic run is simulated in its periodic steady state, as if its excitation had run
    :func:`lead_periods` more periods before it (each signal's first period repeated ahead of it,
    then cut off again); an arbitrary record with a measured ``y`` from the initial state that
    fits its first samples (a plant's: :mod:`nlsid.simulate.initial_state`; a block structure's
    filters': :mod:`nlsid.simulate.structure_state`; a closed loop's plant, pending commands and
    drive, from y and the recorded command of a
    :class:`~nlsid.simulate.loop_state.LoopExcitation`: :mod:`nlsid.simulate.loop_state`). A model written as equations runs from its
    written initial states (:mod:`nlsid.models.equations`), but an arbitrary record with a measured
    ``y`` from the states fitted to its first samples (:mod:`nlsid.simulate.equations_state`)."""
    if isinstance(model, MimoStateSpace):  # several inputs and outputs (nlsid.simulate.mimo); noise rows per signal
        return simulate_mimo(model, run, noise, steady)
    noise = noise or Noise.zero(run.n_samples)
    if isinstance(model, Pnlss):  # its own lead-in and initial state (nlsid.simulate.pnlss_runs)
        return simulate_pnlss(model, run, substeps, noise, steady)
    if isinstance(model, Hybrid):  # each part as measured (simulate_hybrid)
        return simulate_hybrid(model, run, substeps, noise, steady)
    count = lead_periods(model, loop, run) if steady else 0
    if count:
        original, m = run, count * run.period
        run = with_lead(run, count)
        noise = (Noise.zero(run.n_samples) if noise.silent  # zeros made, not tiled, for each simulation
                 else Noise(*(_lead(x, run.period, count) for x in (noise.u, noise.y, noise.process))))
    if isinstance(model, Equations):  # no lead; an arbitrary record from the states fitted to its start
        if steady and run.period is None:
            return equations_state.with_initial_state(model, run, substeps, noise)
        return simulate_equations(model, run, substeps, noise)
    if steady and run.period is None and loop is not None:  # a record that may start in motion
        return simulate_from_start(model, loop, run, substeps, noise)
    out = (simulate_structure(model, run, substeps, noise) if isinstance(model, Structure)
           else simulate_plant(model, loop, run, substeps, noise))
    if steady and run.period is None and isinstance(model, Plant):
        return with_initial_state(model, loop, run, out)
    if steady and run.period is None:
        return with_initial_states(model, run, substeps, noise, out)
    if not count:
        return out
    return dataclasses.replace(out, u=out.u[m:], y=None if out.y is None else out.y[m:],
                               r=None if out.r is None else out.r[m:], channels=original.channels)


def fitted_initial_state(model: Plant | Structure | Equations, loop: ClosedLoop | None, run: Run,
                         substeps: int | None):
    """The initial state :func:`simulate_run` with ``steady`` fits to the start of ``run`` (an
    :class:`~nlsid.simulate.initial_state.InitialState`, in closed loop a
    :class:`~nlsid.simulate.loop_state.LoopState`), None where it fits none: a periodic run, a run
    without a measured y, a PNLSS or a hybrid model (their own initial states). A model written
    as equations: its states (:mod:`nlsid.simulate.equations_state`)."""
    if run.period is not None or run.y is None or isinstance(model, (Pnlss, Hybrid)):
        return None
    if isinstance(model, Equations):
        return equations_state.estimate(model, run, substeps)
    if loop is not None:
        return estimate_loop(model, loop, run, substeps)
    if isinstance(model, Structure):
        return estimate_structure(model, run, substeps)
    return estimate_plant(model, None, run, simulate_plant(model, None, run, substeps, Noise.zero(run.n_samples)))


def simulate_hybrid(model: Hybrid, run: Run, substeps: int | None, noise, steady: bool) -> Run:
    """``run`` through the hybrid model (:mod:`nlsid.models.hybrid`): the physical part as
    :func:`nlsid.simulate.runs.simulate_run` runs it (``substeps`` its own, the measurement noise
    ``noise`` added to u and y, its process noise to the physical part's input), plus the black
    box's output on the same recorded u (the process noise added to its input too: both parts are
    driven by the same plant input). ``steady``: each part as measured (:mod:`nlsid.models.hybrid`)."""
    physical = simulate_run(model.physical, None, run, substeps, noise, steady)
    quiet = physical.y - noise.y  # the physical part's noise-free output
    left = dataclasses.replace(run, y=None if run.y is None else np.asarray(run.y, dtype=float) - quiet)
    black_box = simulate_measured(model.black_box, left, steady, noise.process)
    return dataclasses.replace(physical, y=physical.y + black_box)

