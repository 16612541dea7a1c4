"""A physical model with a black-box term in parallel (``type: hybrid``, ``docs/configs.md``):

    y(t) = y_p(t) + y_b(t),

y_p the output of the physical model (any model of the config language but a PNLSS or hybrid
one: the readable part, its parameters named) and y_b that of a PNLSS model
(:mod:`nlsid.models.pnlss`, discrete at the runs' rate), both driven by the same input u (each
with its own input offset and channels), their output offsets added.

The black-box term holds what the physical part leaves: fitted to the residual r = y - y_p of the
estimation runs with the physical part held (:mod:`nlsid.fit.hybrid`), it changes none of the
physical parameters, which keep their meaning. Built from a config by
:func:`nlsid.models.from_config.hybrid`; run as measured
(:func:`nlsid.simulate.runs.simulate_hybrid`), each
part starts where the record says: the physical part as any model of its kind does (periodic
steady state, or the initial state fitted to the measured y); the black box in periodic steady
state, or from the initial state fitted to what the physical part leaves of the measured y,
y - y_p, which is the signal it was fitted to.
"""

from __future__ import annotations

from dataclasses import dataclass

from nlsid.models.pnlss import Pnlss


@dataclass(frozen=True)
class Hybrid:
    """``physical`` (a :class:`nlsid.models.from_config.Plant`, ``Structure`` or
    :class:`nlsid.models.equations.Equations`) and ``black_box`` (:class:`Pnlss`) in parallel."""

    physical: object
    black_box: Pnlss
