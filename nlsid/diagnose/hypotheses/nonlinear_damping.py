"""Nonlinear damping: a drag that grows faster than the viscous one, quadratic F = c2 v |v| (a
fluid's at high Reynolds number, an orifice) or cubic F = c3 v^3, on the driven mass of a
mechanical template (``nonlinearities: quadratic_damping`` / ``cubic_damping``) or fed back around
a transfer function model (:mod:`~nlsid.diagnose.hypotheses.velocity_feedback`).

Signature: odd distortion; the resonance's damping grows with level (the equivalent viscous
damping of c2 v|v| at amplitude V is 8 c2 V / 3 pi, of c3 v^3 it is 3 c3 V^2 / 4); the residual
is the model's response to the force -F(v) with v the model's velocity, so c2 (c3) is the
least-squares regression of the residual on the response to -v|v| (-v^3). A negative coefficient
(an undamping) is not a drag: the hypothesis is then not fitted.

Its neighbour is Coulomb friction, F = fc sign(v), the same odd function of v of degree 0 where
these are of degree 2 and 3: friction acts most at low speed (its equivalent damping falls with
level, 4 fc / pi V), damping at high speed (it grows). All are velocity-dependent dissipative forces and one
family, ``friction``: the verdict names the one of least validation error (equal parameter
counts), and a richer friction law only when it is significantly better.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses import velocity_feedback
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.mass_forces import add_force, force_columns, force_paths, needs
from nlsid.diagnose.simulation import ModelRunner


def mechanical_or_transfer_function(runner: ModelRunner) -> str | None:
    """Applies to a mechanical template or an open-loop transfer function (the force fed back)."""
    if runner.mechanical:
        return None
    reason = velocity_feedback.applies(runner)
    return None if reason is None else f"needs a mechanical template or {reason.removeprefix('needs ')}"


def _positive(name: str) -> Callable[[Estimate], str | None]:
    def valid(est: Estimate) -> str | None:
        return None if est.values[name] > 0 else f"the residual correlates negatively with the {name} force: not a drag"
    return valid


def law_estimate(law: Callable[[np.ndarray], np.ndarray], name: str) -> Callable[[Context], Estimate | str]:
    """The start of a force ``law(v)`` of coefficient ``name`` > 0 (module docstring), on the
    driven mass or fed back around a transfer function."""
    valid = _positive(name)

    def estimate(ctx: Context) -> Estimate | str:
        if not ctx.runner.mechanical:
            return velocity_feedback.estimate(ctx, [law], [name], valid)
        if needs(ctx, "velocity"):
            return needs(ctx, "velocity")
        est = regress(ctx.target(), force_columns(ctx, [lambda s: law(s["velocity"])]), [name])
        return valid(est) or est
    return estimate


def law_extension(force: dict, names: tuple[str, ...]) -> Callable[[dict, dict], dict]:
    """The force appended to a mechanical template's, or fed back around a transfer function."""
    on_mass, around = add_force(force), velocity_feedback.extender(force, names)

    def extend(data: dict, values: dict) -> dict:
        return around(data, values) if data["model"]["type"] == "transfer_function" else on_mass(data, values)
    return extend


def law_paths(names: tuple[str, ...]) -> Callable[[dict], dict[str, str]]:
    on_mass, around = force_paths(names), velocity_feedback.paths(names)

    def paths(data: dict) -> dict[str, str]:
        return around(data) if data["model"]["type"] == "transfer_function" else on_mass(data)
    return paths


HYPOTHESES = (
    Hypothesis("quadratic_damping", "Quadratic damping", "friction", "c2", "force units / velocity^2",
               "odd distortion; damping grows with level; residual like the response to the force -v|v|",
               mechanical_or_transfer_function, law_estimate(lambda v: v * np.abs(v), "c2"),
               law_extension({"type": "quadratic_damping"}, ("c2",)), ("c2",), law_paths(("c2",))),
    Hypothesis("cubic_damping", "Cubic damping", "friction", "c3", "force units / velocity^3",
               "odd distortion; damping grows with level; residual like the response to the force -v^3",
               mechanical_or_transfer_function, law_estimate(lambda v: v**3, "c3"),
               law_extension({"type": "cubic_damping"}, ("c3",)), ("c3",), law_paths(("c3",))),
)
