"""Coulomb friction fed back around a transfer function model: y = G (u - fc sign(v)), v the
velocity of the moving part, as a ``nonlinear_feedback`` plant with a ``coulomb`` force
(:mod:`~nlsid.diagnose.hypotheses.velocity_feedback`: the model's output read as the position or
the velocity, whichever the signature explains better). A transfer function fitted to measured
data (``nlsid fit``) then gets the friction the mechanical templates have
(:mod:`~nlsid.diagnose.hypotheses.friction`), stick-slip included: the kernel's friction step
holds the mass while the net force is within the band.

Signature as Coulomb's on a template: odd distortion, the BLA's gain rising with level, the
residual the model's response to -sign(v), regressed for fc (> 0; a negative level is not
friction). One family with the other friction laws and the nonlinear damping (the verdict's
nesting rule).
"""

from __future__ import annotations

import numpy as np

from nlsid.diagnose.hypotheses import velocity_feedback
from nlsid.diagnose.hypotheses.base import Estimate, Hypothesis


def _positive(est: Estimate) -> str | None:
    return None if est.values["fc"] > 0 else "the residual correlates negatively with sign(v): not friction"


def _estimate(ctx):
    return velocity_feedback.estimate(ctx, [np.sign], ["fc"], _positive)


HYPOTHESES = (
    Hypothesis("coulomb_feedback", "Coulomb friction fed back around the transfer function", "friction", "fc",
               "input units",
               "odd distortion; BLA gain rises with level; residual like the response to -sign(v) at the input",
               velocity_feedback.applies, _estimate, velocity_feedback.extender({"type": "coulomb"}, ("fc",)),
               ("fc",), velocity_feedback.paths(("fc",))),
)
