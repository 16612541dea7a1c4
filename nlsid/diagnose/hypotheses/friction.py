"""Friction, one family of nested laws: Coulomb (fc) in Stribeck (fs = fc) in LuGre (sigma0 to
infinity). The verdict names the richer law only when it is significantly better, and each richer
law starts from the simpler one's fit.

The break-away force of a Stribeck or LuGre law is refined as its excess over the sliding level,
``peak`` = fs - fc (the config key, :mod:`nlsid.io.model_config`), which the refinement keeps
positive as it keeps every parameter's sign: a break-away below the sliding force is not a
Stribeck peak, and refined as fs and fc the Stribeck law reached one on LuGre presliding (fs near 0
under fc, a curve that falls to zero at standstill and mimics the bristles' soft start), which the
start grid excludes. The estimates report fs = fc + peak (``derive``)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, regress
from nlsid.diagnose.hypotheses.mass_forces import add_force, force_columns, force_paths, mechanical, needs
from nlsid.diagnose.hypotheses.mechanics import linear_paths
from nlsid.diagnose.nuisances import KEYS as NUISANCE_KEYS
from nlsid.diagnose.simulation import steady_mean
from nlsid.diagnose.verdict import ALPHA

STRIBECK_DELTA = 2.0

STRIBECK_START_RATIO = 1.5  # fs / fc at the start of the fit when the signature shows no break-away peak

# fs / sigma0 over the rms position, LuGre's start grid: from bristles as soft as the motion (presliding
# of tens of micrometres under strokes of a tenth of a millimetre) to stiff ones, half a decade apart
LUGRE_DEFLECTIONS = (1.0, 0.3, 0.1, 0.03, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4)
LUGRE_PEAK, LUGRE_VS = 1.5, 0.1  # the second level set of LuGre's start: fs / fc, vs over the rms velocity

STRIBECK_GRID = 25         # Stribeck velocities tried for the start values (a factor 1.21 apart)

NEAR_COULOMB = 1.001       # fs / fc of the Stribeck start next to the fitted Coulomb law

BEYOND_GRID = 13           # Stribeck velocities tried on the Coulomb fit's residual (a factor 1.47 apart)


def _estimate_coulomb(ctx: Context) -> Estimate | str:
    if needs(ctx, "velocity"):
        return needs(ctx, "velocity")
    est = regress(ctx.target(), force_columns(ctx, [lambda s: np.sign(s["velocity"])]), ["fc"])
    return est if est.values["fc"] > 0 else "the residual correlates negatively with sign(v): not friction"

def _stribeck_columns(ctx: Context, vs: float) -> list[np.ndarray]:
    def weight(s):
        return np.exp(-np.abs(s["velocity"] / vs) ** STRIBECK_DELTA)
    return force_columns(ctx, [lambda s: np.sign(s["velocity"]) * weight(s),
                                lambda s: np.sign(s["velocity"]) * (1 - weight(s))])

def _nested_start(ctx: Context, name: str) -> dict[str, float]:
    """The linear mechanics (the masses, dampings, stiffnesses of :func:`linear_paths`) and the
    nuisances that the simpler friction law ``name`` was refined with (model key -> value); empty
    when it was not fitted."""
    extended = ctx.extended.get(name)
    if extended is None:
        return {}
    model = extended["model"]
    return {k: float(model[k]) for k in (*linear_paths(ctx.runner.data), *NUISANCE_KEYS) if k in model}

def _with_keys(data: dict, values: dict[str, float]) -> dict:
    return {**data, "model": {**data["model"], **values}}

def _signature_stribeck(ctx: Context) -> Estimate | str:
    """Stribeck start values from the signature: for each Stribeck velocity vs of a log grid
    (:data:`STRIBECK_GRID` values from 1e-2 to 1 times the model's rms velocity) the levels fs and
    fc enter linearly and are regressed; the start is the grid point of least residual among those
    with a break-away peak, fs > fc > 0. A continuous search of vs is not used: the first-order
    cost has spurious minima at small vs with fs < 0 (the force then cancels part of the Coulomb
    step), and a start at a tiny vs leaves fs without effect on the simulation, so the fit engine
    cannot move it. Without a physical grid point the start is Coulomb's fc with fs =
    STRIBECK_START_RATIO fc and vs the median model speed (where fs acts on half of the samples).
    """
    y = ctx.target()
    speed = np.abs(np.concatenate([s["velocity"] for s in ctx.internal]))
    v_rms = float(np.sqrt(np.mean(speed**2)))
    best = None
    for vs in np.geomspace(1e-2 * v_rms, v_rms, STRIBECK_GRID):
        est = regress(y, _stribeck_columns(ctx, vs), ["fs", "fc"])
        if est.values["fs"] > est.values["fc"] > 0 and (best is None or est.explained_db > best[1].explained_db):
            best = (float(vs), est)
    if best is not None:
        vs, est = best
        return Estimate({**est.values, "vs": vs}, {**est.std, "vs": float("nan")}, est.explained_db,
                        f"vs on a grid of {STRIBECK_GRID} values (no standard error)")
    coulomb = _estimate_coulomb(ctx)
    if isinstance(coulomb, str):
        return coulomb
    fc = coulomb.values["fc"]
    return Estimate({"fs": STRIBECK_START_RATIO * fc, "fc": fc, "vs": float(np.median(speed))},
                    {k: float("nan") for k in ("fs", "fc", "vs")}, float("nan"),
                    f"no break-away peak to first order: start fc from Coulomb, fs = {STRIBECK_START_RATIO:g} fc, "
                    f"vs the median model speed")

def _beyond_coulomb(ctx: Context) -> dict[str, float] | None:
    """:func:`beyond_coulomb` of the Coulomb law on the driven mass."""
    return beyond_coulomb(ctx, "coulomb")


def beyond_coulomb(ctx: Context, coulomb_name: str, internal: list[dict] | None = None) -> dict[str, float] | None:
    """Stribeck start values from what the fitted Coulomb law leaves: the residual of the Coulomb
    hypothesis ``coulomb_name``'s extended model (its last force the Coulomb law: on the driven
    mass, or fed back around a transfer function) regressed on the model's responses to the forces the Stribeck law
    adds to it, sign(v) w(v) (fs - fc) + sign(v) (1 - w(v)) (fc' - fc) with w = e^{-(|v|/vs)^2}
    and v the extended model's velocity. vs is the point of a log grid (:data:`BEYOND_GRID` values
    from 1e-2 to 1 times the rms velocity) of least residual with fs > fc' > 0, the responses
    those of the model without the Coulomb force (cheap: linear where the rest is); fs and fc'
    are then regressed at that vs on the responses along the Coulomb model's own trajectory,
    which a sticking mass follows. The nominal model's velocities, which the signature regresses
    on, have no stick phases, and a break-away peak acts where the mass sticks or nearly does: on
    the battery's Stribeck case (vs 0.002 m/s) the signature put vs at 0.031 and this at 0.0036.
    ``internal``: the Coulomb model's signals on the runs where its runner does not give them (a
    force fed back around a transfer function). None when Coulomb was not fitted or no grid point
    has a break-away peak."""
    extended, coulomb = ctx.extended.get(coulomb_name), ctx.fitted.get(coulomb_name)
    if extended is None or coulomb is None:
        return None
    runner = ctx.runner.with_changes(extended)
    left = [steady_mean(run, ctx.measured(run)) - steady_mean(run, x) for run, x in zip(ctx.runs, ctx.simulated(runner))]
    along = Context(runner, ctx.runs, left, internal or [runner.internal(run) for run in ctx.runs], signal=ctx.signal)
    if needs(along, "velocity"):
        return None
    without = copy.deepcopy(extended)
    without["model"]["nonlinearities"].pop()  # the Coulomb force the hypothesis appended
    cheap = dataclasses.replace(along, runner=ctx.runner.with_changes(without))
    speed = np.abs(np.concatenate([s["velocity"] for s in along.internal]))
    fc = coulomb.values["fc"]

    def start(local: Context, vs: float) -> tuple[float, dict[str, float]] | None:
        est = regress(local.target(), _stribeck_columns(local, vs), ["peak", "level"])
        fs, level = fc + est.values["peak"], fc + est.values["level"]
        return (est.explained_db, {"fs": fs, "fc": level, "vs": float(vs)}) if fs > level > 0 else None

    grid = [start(cheap, vs) for vs in np.geomspace(1e-2, 1.0, BEYOND_GRID) * float(np.sqrt(np.mean(speed**2)))]
    grid = [g for g in grid if g is not None]
    if not grid:
        return None
    vs = max(grid, key=lambda g: g[0])[1]["vs"]
    final = start(along, vs)
    return None if final is None else final[1]


def noise_share(ctx: Context, parameters: int) -> float:
    """The share of a residual sum of squares of the estimation runs that ``parameters`` more
    parameters lower by fitting noise alone, at most, at level ALPHA: the RSS is sigma^2
    chi^2(n) over n residual samples, and they take sigma^2 chi^2(parameters) of it."""
    from scipy.stats import chi2

    return float(chi2.isf(ALPHA, parameters)) / ctx.target().size


def _estimate_stribeck(ctx: Context) -> Estimate | str:
    """Stribeck start values: the signature's (:func:`_signature_stribeck`), or, where the Coulomb
    hypothesis was fitted, the best by simulation error of the estimation runs of that start, of
    one next to the fitted Coulomb law (its fc, fs = NEAR_COULOMB fc, the signature's vs) and of
    one regressed on what the Coulomb law leaves (:func:`_beyond_coulomb`), all with the linear
    mechanics the Coulomb fit refined; the start next to the Coulomb law unless another lowers
    the error by more than fitting noise could (:func:`noise_share`: on Coulomb data the regressed
    start was 3e-7 better, and its refinement moved fs 2 % off fc along a valley of the damping).
    A Stribeck law with fs = fc is Coulomb's, so
    where friction is Coulomb-like (the break-away peak small or absent) the refinement starts
    next to an optimum the simpler law's fit has already found, instead of from the mechanics the
    model was given: on a stage recording whose friction no law of the library fits exactly, it
    took 35 s and 176 simulations from the signature."""
    if needs(ctx, "velocity"):
        return needs(ctx, "velocity")
    signature = _signature_stribeck(ctx)
    mechanics = _nested_start(ctx, "coulomb")
    if isinstance(signature, str) or not mechanics:
        return signature
    fc = ctx.fitted["coulomb"].values["fc"]
    near = {"fs": NEAR_COULOMB * fc, "fc": fc, "vs": signature.values["vs"]}
    base = _with_keys(ctx.runner.data, mechanics)
    starts = {"signature": {k: signature.values[k] for k in ("fs", "fc", "vs")}, "near": near,
              "beyond": _beyond_coulomb(ctx)}
    costs = {name: ctx.simulation_rss(_extend_stribeck(base, start)) for name, start in starts.items() if start}
    chosen = min(costs, key=costs.get)
    if costs[chosen] > costs["near"] * (1 - noise_share(ctx, 3)):
        chosen = "near"  # no better than the Coulomb law by more than its three parameters fitting noise
    if chosen == "signature":
        return dataclasses.replace(signature, note=f"{signature.note}; mechanics from the Coulomb fit",
                                   starts=mechanics)
    note = (f"start next to the fitted Coulomb law (fs = {NEAR_COULOMB:g} fc, its mechanics)" if chosen == "near" else
            "start regressed on what the fitted Coulomb law leaves (its mechanics; vs on a grid of "
            f"{BEYOND_GRID} values)")
    return Estimate(starts[chosen], {k: float("nan") for k in starts[chosen]},
                    explained_db(float(np.sum(ctx.target() ** 2)), costs[chosen]),
                    f"{note}: the smallest simulation error of the starts tried", starts=mechanics)

def _estimate_lugre(ctx: Context) -> Estimate | str:
    """LuGre start values: the levels and the Stribeck velocity of the fitted Stribeck hypothesis
    (LuGre's steady-state friction is that Stribeck curve with delta = 2), or, where that fit
    found no peak (presliding, which the Stribeck law cannot follow, leaves it at Coulomb's),
    its fc with a break-away LUGRE_PEAK fc at LUGRE_VS of the rms velocity; and the bristle
    stiffness sigma0 from a log grid by the simulation error of the estimation runs: sigma0 such
    that the presliding deflection fs / sigma0 is 1 .. 10^-4 of the model's rms position, half a
    decade apart (:data:`LUGRE_DEFLECTIONS`: soft bristles, whose presliding is a good part of the
    motion, as well as stiff ones; the LuGre law reduces to Stribeck's when it is far smaller than
    the motion, and the refinement moves sigma0 by three decades at most), the pair of level set
    and sigma0 of least error, with the linear mechanics the Stribeck fit refined, which start
    LuGre's refinement too. The bristle damping
    sigma1 and the viscous sigma2 are 0 (viscous damping is the model's own)."""
    stribeck = ctx.fitted.get("stribeck")
    if stribeck is None:
        return "needs the Stribeck hypothesis's estimate to start from"
    if needs(ctx, "position"):
        return needs(ctx, "position")
    if needs(ctx, "velocity"):
        return needs(ctx, "velocity")
    position = np.concatenate([s["position"] for s in ctx.internal])
    fitted = {k: stribeck.values[k] for k in ("fc", "fs", "vs")}
    speed = float(np.sqrt(np.mean(np.concatenate([s["velocity"] for s in ctx.internal]) ** 2)))
    peaked = {"fc": fitted["fc"], "fs": LUGRE_PEAK * fitted["fc"], "vs": LUGRE_VS * speed}
    spread = float(np.std(position))
    mechanics = _nested_start(ctx, "stribeck")
    base = _with_keys(ctx.runner.data, mechanics)
    options = [(levels, levels["fs"] / (spread * ratio)) for levels in (fitted, peaked) for ratio in LUGRE_DEFLECTIONS]
    costs = [ctx.simulation_rss(LUGRE.extend(base, {"sigma0": sigma0, **levels})) for levels, sigma0 in options]
    levels, sigma0 = options[int(np.argmin(costs))]
    std = {k: stribeck.std[k] if levels is fitted else float("nan") for k in levels}
    origin = ("the Stribeck fit's" if levels is fitted else
              f"fc from the Stribeck fit, fs = {LUGRE_PEAK:g} fc, vs = {LUGRE_VS:g} x the rms velocity")
    return Estimate({"sigma0": sigma0, **levels}, {"sigma0": float("nan"), **std},
                    explained_db(float(np.sum(ctx.target() ** 2)), min(costs)),
                    f"levels {origin}, mechanics from the Stribeck fit; sigma0 on a grid of presliding deflections",
                    starts=mechanics or None)

def as_peak(values: dict) -> dict:
    """The levels with the break-away as its excess over sliding, ``peak`` = fs - fc, in place of fs."""
    out = dict(values)
    if "fs" in out:
        out["peak"] = out.pop("fs") - out["fc"]
    return out


def peaked(estimate: Estimate | str) -> Estimate | str:
    """A Stribeck or LuGre start (fs > fc) with ``peak`` = fs - fc beside fs: the parameter refined
    (:func:`break_away`)."""
    if isinstance(estimate, str):
        return estimate
    values = {**estimate.values, "peak": estimate.values["fs"] - estimate.values["fc"]}
    return dataclasses.replace(estimate, values=values, std={**estimate.std, "peak": float("nan")})


def break_away(fitted: dict, starts: dict, model: dict) -> dict:
    """fs = fc + peak of the fitted law."""
    return {"fs": fitted["fc"] + fitted["peak"]}


def _extend_stribeck(data: dict, values: dict) -> dict:
    return add_force({"type": "stribeck", "delta": STRIBECK_DELTA})(data, as_peak(values))


def _extend_lugre(data: dict, values: dict) -> dict:
    return add_force({"type": "lugre", "sigma1": 0.0, "sigma2": 0.0})(data, as_peak(values))


COULOMB = Hypothesis("coulomb", "Coulomb friction", "friction", "fc", "N",
               "odd distortion; BLA gain rises with level; residual force jumps at zero velocity",
               mechanical, _estimate_coulomb, add_force({"type": "coulomb"}), ("fc",), force_paths(("fc",)))
STRIBECK = Hypothesis("stribeck", "Stribeck friction", "friction", "fs", "N",
               "as Coulomb friction, with a break-away peak at low velocity",
               mechanical, lambda ctx: peaked(_estimate_stribeck(ctx)), _extend_stribeck, ("peak", "fc", "vs"),
               force_paths(("peak", "fc", "vs")), derive=break_away)
LUGRE = Hypothesis("lugre", "LuGre friction", "friction", "sigma0", "N/m",
               "as Stribeck friction, with presliding: a stiff friction force (bristles) after each velocity "
               "reversal", mechanical, lambda ctx: peaked(_estimate_lugre(ctx)), _extend_lugre,
               ("sigma0", "fc", "peak", "vs"), force_paths(("sigma0", "fc", "peak", "vs")), derive=break_away)
HYPOTHESES = (COULOMB, STRIBECK, LUGRE)
