"""A physical model with a black-box term in parallel (``type: hybrid``, ``docs/configs.md``):

    y(t) = y_p(t) + y_b(t),

y_p the output of the physical model (any model of the config language but a PNLSS or hybrid
one: the readable part, its parameters named) and y_b that of a PNLSS model
(:mod:`nlsid.models.pnlss`, discrete at the runs' rate), both driven by the same input u (each
with its own input offset and channels), their output offsets added.

The black-box term holds what the physical part leaves: fitted to the residual r = y - y_p of the
estimation runs with the physical part held (:mod:`nlsid.fit.hybrid`), it changes none of the
physical parameters, which keep their meaning. Run as measured (:func:`simulate_hybrid`), each
part starts where the record says: the physical part as any model of its kind does (periodic
steady state, or the initial state fitted to the measured y); the black box in periodic steady
state, or from the initial state fitted to what the physical part leaves of the measured y,
y - y_p, which is the signal it was fitted to.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.pnlss import Pnlss


@dataclass(frozen=True)
class Hybrid:
    """``physical`` (a :class:`nlsid.models.from_config.Plant`, ``Structure`` or
    :class:`nlsid.models.equations.Equations`) and ``black_box`` (:class:`Pnlss`) in parallel."""

    physical: object
    black_box: Pnlss


def build(config) -> Hybrid:
    """The :class:`Hybrid` of a validated :class:`nlsid.io.model_config.SimulateConfig` whose model
    is a :class:`~nlsid.io.model_config.HybridConfig` (open loop only). An error in either part
    names its key under ``model.physical`` or ``model.black_box``."""
    from nlsid.models import from_config, pnlss

    if config.closed_loop is not None:
        raise InputError("closed_loop", "a closed loop needs an LTI or mechanical plant, not a hybrid model")
    physical_config = config.model_copy(update={"model": config.model.physical})
    try:
        physical = from_config.model(physical_config)
    except InputError as exc:
        where = exc.where
        where = "model.physical" + where[len("model"):] if where.startswith("model") else where
        raise InputError(where, exc.what) from None
    return Hybrid(physical, pnlss.build(config.model.black_box, "model.black_box"))


def simulate_hybrid(model: Hybrid, run: Run, substeps: int | None, noise, steady: bool) -> Run:
    """``run`` through the hybrid model (module docstring): the physical part as
    :func:`nlsid.simulate.runs.simulate_run` runs it (``substeps`` its own, the measurement noise
    ``noise`` added to u and y, its process noise to the physical part's input), plus the black
    box's output on the same recorded u (the process noise added to its input too: both parts are
    driven by the same plant input). ``steady``: each part as measured (module docstring)."""
    from nlsid.simulate.pnlss_runs import simulate_measured
    from nlsid.simulate.runs import simulate_run

    physical = simulate_run(model.physical, None, run, substeps, noise, steady)
    quiet = physical.y - noise.y  # the physical part's noise-free output
    left = dataclasses.replace(run, y=None if run.y is None else np.asarray(run.y, dtype=float) - quiet)
    black_box = simulate_measured(model.black_box, left, steady, noise.process)
    return dataclasses.replace(physical, y=physical.y + black_box)

