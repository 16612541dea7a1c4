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

The richer laws start from the simpler one's fit, as on a template
(:mod:`~nlsid.diagnose.hypotheses.friction`), its linear part and nuisances included:

- ``stribeck_feedback``: a ``stribeck`` force (delta = 2, the break-away refined as ``peak`` =
  fs - fc > 0) from the fitted Coulomb feedback: the better by simulation error of a start next to
  it (fs = NEAR_COULOMB fc) and one regressed on what it leaves
  (:func:`nlsid.diagnose.hypotheses.friction.beyond_coulomb`: a break-away acts where the mass
  sticks or nearly does, on the Coulomb model's own trajectory), the regressed one only where it
  is better by more than fitting noise;
- ``lugre_feedback``: a ``lugre`` force (sigma1 = sigma2 = 0) from the fitted Stribeck feedback,
  sigma0 on the template's grid of presliding deflections fs / sigma0 (1 .. 1e-4 of the rms
  position of the Stribeck model), with the Stribeck levels or, where that fit found no peak, fc
  with a break-away LUGRE_PEAK fc at LUGRE_VS of the rms velocity; the least simulation error.

What tells them apart: Coulomb's force is a step at v = 0; Stribeck's is larger while the mass
starts (a break-away fs above the sliding fc, below the Stribeck velocity vs); LuGre's rises
within a presliding deflection after each reversal, a stiff spring (sigma0) before it slides.
Each richer law is named only when it is significantly better than the simpler one
(:mod:`nlsid.diagnose.verdict`).
"""

from __future__ import annotations

import numpy as np

from nlsid.diagnose.hypotheses import friction, velocity_feedback
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, with_lti

STRIBECK = ("peak", "fc", "vs")           # the Stribeck force's parameters refined
LUGRE = ("sigma0", "fc", "peak", "vs")   # and LuGre's


def _positive(est: Estimate) -> str | None:
    return None if est.values["fc"] > 0 else "the residual correlates negatively with sign(v): not friction"


def _estimate(ctx):
    return velocity_feedback.estimate(ctx, [np.sign], ["fc"], _positive)


def _trial(ctx: Context, simpler: velocity_feedback.Fitted, extend, values: dict) -> float:
    """The simulation error of the estimation runs of a start ``values`` of the law ``extend``,
    with the linear part and the nuisances the simpler law's fit left (written after the
    extension, which keeps a transfer function's keys only: the force offset among them)."""
    extended = extend(with_lti(ctx.runner.data, simpler.lti), {**values, **simpler.coefficients})
    extended["model"].update(simpler.nuisances)
    return ctx.simulation_rss(extended)


def _extend_stribeck(data: dict, values: dict) -> dict:
    return velocity_feedback.extender({"type": "stribeck", "delta": friction.STRIBECK_DELTA}, STRIBECK)(
        data, friction.as_peak(values))


def _extend_lugre(data: dict, values: dict) -> dict:
    return velocity_feedback.extender({"type": "lugre", "sigma1": 0.0, "sigma2": 0.0}, LUGRE)(
        data, friction.as_peak(values))


def _estimate_stribeck(ctx: Context) -> Estimate | str:
    """Start values (module docstring): the laws' levels and vs, and the Coulomb fit's linear part
    (``lti``, its coefficients among the values) and nuisances (``starts``)."""
    coulomb = velocity_feedback.fitted(ctx, "coulomb_feedback")
    if coulomb is None:
        return "needs the fit of the Coulomb friction fed back around the transfer function to start from"
    internal = velocity_feedback.internal(ctx, coulomb.extended)
    if isinstance(internal, str):
        return internal
    speed = np.abs(np.concatenate([s["velocity"] for s in internal]))
    fc = float(coulomb.force["fc"])
    starts = {"near": {"fs": friction.NEAR_COULOMB * fc, "fc": fc, "vs": float(np.median(speed))},
              "beyond": friction.beyond_coulomb(ctx, "coulomb_feedback", internal)}
    costs = {name: _trial(ctx, coulomb, _extend_stribeck, start) for name, start in starts.items() if start}
    chosen = min(costs, key=costs.get)
    if costs[chosen] > costs["near"] * (1 - friction.noise_share(ctx, 3)):
        chosen = "near"  # no better than the Coulomb law by more than three parameters fitting noise
    note = (f"start next to the fitted Coulomb feedback (fs = {friction.NEAR_COULOMB:g} fc, vs the median speed)"
            if chosen == "near" else
            f"start regressed on what the fitted Coulomb feedback leaves (vs on a grid of {friction.BEYOND_GRID})")
    values = {**starts[chosen], **coulomb.coefficients}
    return friction.peaked(Estimate(
        values, {k: float("nan") for k in values}, explained_db(float(np.sum(ctx.target() ** 2)), costs[chosen]),
        f"{note}: the smallest simulation error of the starts tried; the linear part and nuisances of its fit; "
        f"the model's output read as the {coulomb.lti['output']}", lti=coulomb.lti, starts=coulomb.nuisances))


def _estimate_lugre(ctx: Context) -> Estimate | str:
    """Start values (module docstring), from the fitted Stribeck feedback."""
    stribeck = velocity_feedback.fitted(ctx, "stribeck_feedback")
    if stribeck is None:
        return "needs the fit of the Stribeck friction fed back around the transfer function to start from"
    internal = velocity_feedback.internal(ctx, stribeck.extended)
    if isinstance(internal, str):
        return internal
    spread = float(np.std(np.concatenate([s["position"] for s in internal])))
    speed = float(np.sqrt(np.mean(np.concatenate([s["velocity"] for s in internal]) ** 2)))
    if spread == 0:
        return "the Stribeck model does not move on the estimation runs"
    force = stribeck.force
    fs = force["fs"] if "fs" in force else force["fc"] + force["peak"]
    found = {"fc": float(force["fc"]), "fs": float(fs), "vs": float(force["vs"])}
    peaked = {"fc": found["fc"], "fs": friction.LUGRE_PEAK * found["fc"], "vs": friction.LUGRE_VS * speed}
    options = [(levels, levels["fs"] / (spread * ratio))
               for levels in (found, peaked) for ratio in friction.LUGRE_DEFLECTIONS]
    costs = [_trial(ctx, stribeck, _extend_lugre, {"sigma0": sigma0, **levels}) for levels, sigma0 in options]
    levels, sigma0 = options[int(np.argmin(costs))]
    origin = ("the Stribeck feedback's" if levels is found else
              f"fc from the Stribeck feedback, fs = {friction.LUGRE_PEAK:g} fc, vs = {friction.LUGRE_VS:g} x the rms "
              "velocity")
    values = {"sigma0": sigma0, **levels, **stribeck.coefficients}
    return friction.peaked(Estimate(
        values, {k: float("nan") for k in values}, explained_db(float(np.sum(ctx.target() ** 2)), min(costs)),
        f"levels {origin}; sigma0 on a grid of {len(friction.LUGRE_DEFLECTIONS)} presliding deflections (the least "
        "simulation error); the linear part and nuisances of the Stribeck fit", lti=stribeck.lti,
        starts=stribeck.nuisances))


HYPOTHESES = (
    Hypothesis("coulomb_feedback", "Coulomb friction fed back around the transfer function", "friction", "fc",
               "input units",
               "odd distortion; BLA gain rises with level; residual like the response to -sign(v) at the input",
               velocity_feedback.applies, _estimate, velocity_feedback.extender({"type": "coulomb"}, ("fc",)),
               ("fc",), velocity_feedback.paths(("fc",))),
    Hypothesis("stribeck_feedback", "Stribeck friction fed back around the transfer function", "friction", "fs",
               "input units",
               "as coulomb_feedback, with a break-away peak at low velocity (fs above the sliding fc)",
               velocity_feedback.applies, _estimate_stribeck, _extend_stribeck, STRIBECK,
               velocity_feedback.paths(STRIBECK), derive=friction.break_away),
    Hypothesis("lugre_feedback", "LuGre friction fed back around the transfer function", "friction", "sigma0",
               "input units / output units",
               "as stribeck_feedback, with presliding: a stiff friction force (bristles) after each velocity reversal",
               velocity_feedback.applies, _estimate_lugre, _extend_lugre, LUGRE,
               velocity_feedback.paths(LUGRE), derive=friction.break_away),
)
