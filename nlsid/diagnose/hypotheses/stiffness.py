"""A cubic spring on the driven mass: F = k3 p^3 (k3 > 0 hardening, < 0 softening)."""

from __future__ import annotations

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress, spring
from nlsid.diagnose.hypotheses.mass_forces import add_force, force_columns, force_paths, mechanical, needs


def _estimate_cubic(ctx: Context) -> Estimate | str:
    if needs(ctx, "position"):
        return needs(ctx, "position")
    return regress(ctx.target(), force_columns(ctx, [lambda s: s["position"] ** 3]), ["k3"])


HYPOTHESES = (
    Hypothesis("cubic_stiffness", "Cubic stiffness", "stiffness", "k3", "N/m^3",
               "odd distortion; the resonance moves with level; residual force cubic in position",
               mechanical, _estimate_cubic, add_force({"type": "cubic_stiffness"}), ("k3",), force_paths(("k3",)),
               qualifier=lambda values: spring(values["k3"])),
)
