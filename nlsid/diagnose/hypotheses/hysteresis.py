"""Hysteresis: a Bouc-Wen restoring force on the mass of a mass-spring-damper, or fed back around a
transfer function model from force to position (``hysteresis_feedback``: y = G (u - k z(y')), a
``nonlinear_feedback`` with G's coefficients refined, :mod:`~nlsid.diagnose.hypotheses.velocity_feedback`).

The force is F = k z with the Bouc-Wen state z' = v - beta |v| z - gamma v |z| (A = 1 and n = 1
held: for n = 1, A and k are one parameter, :mod:`nlsid.models.forces`), z in position units. It
is a spring of stiffness k for small strokes (z ~ p after each reversal) that yields on long ones,
the force tending to k zmax, zmax = 1 / (beta + gamma): a loop whose width the stroke sets, not
the rate. The elastic part alpha k0 p of the classical form is the model's own stiffness, refined
with the force (:func:`nlsid.diagnose.hypotheses.mechanics.linear_paths`).

Start: the refinement (the fit engine, with the model's mass, damping and stiffness) needs a
start in the basin of the truth, and the first-order signature (the residual regressed on the
model's response to -z along the model's motion) did not give one: where hysteresis is the cause
the model's own motion is far from the true one (the loop moves the resonance and damps it), and
on the tests' oscillator the regressed start took the wrong sign of gamma, from which the
refinement cannot cross zero. So the start is the grid point of least simulation error of the
estimation runs: zmax a share of the model's rms position (:data:`BOUND_SHARES`), gamma / beta
(:data:`GAMMA_SHARES`, nonzero: the refinement keeps each parameter's sign), and k a share of the
model's stiffness (:data:`SPLITS`) with the model's stiffness lowered by k / 2: a model fitted to
the data holds a spring between the small-stroke stiffness (its own plus k) and the large-stroke
one (its own), near the middle at strokes of about zmax, which the grid spans.

Around a transfer function the grid is the same, but G is a model fitted to the data, the loop's
BLA G_0 / (1 + (k_e + c_e s) G_0), which holds the force's equivalent spring and damper: each grid
point's linear part starts with them taken out, G / (1 - (k_e + c_e s) G), k_e and c_e the force's
least-squares linearization along G's motion (:func:`state_along`, :func:`equivalent_spring`,
docs/feedback_start.md). Where that would change the sign of a coefficient of G (G holds less
damping than some grid force dissipates: not that loop's BLA, but a plant's mechanics), k / 2 is
taken out of G's stiffness instead.

The exponent n of the Bouc-Wen state (z' = v - beta |v| |z|^(n-1) z - gamma v |z|^n) sets how
sharply the force yields: n = 1 a smooth knee, larger n a sharper one, tending to an elastic-plastic
spring. ``hysteresis`` and ``hysteresis_feedback`` hold n = 1 (their note says so);
``hysteresis_exponent`` frees it, from the fit of either (its mechanics or linear part, its
nuisances): n on a grid (:data:`EXPONENTS`), gamma / beta on :data:`GAMMA_SHARES` (the n = 1
fit may end at gamma = beta, a corner of the admissible loops, where a sharper knee wants a
larger n), the bound zmax = (1 / (beta + gamma))^(1/n) and k at the fitted ones or near them
(:data:`BOUND_RATIOS`, :data:`K_RATIOS`: fitted with n = 1 they are not those of a sharper knee),
the least simulation error the start, then k, beta,
gamma and n refined with the rest (n >= 1: a trial below is a rejected step). It is the same family
with one parameter more, so the verdict names it only where it is significantly better than n = 1
(:mod:`nlsid.diagnose.verdict`); it is not fitted where n = 1 already reaches the noise floor, nor
where n = 1 does not lead the hypotheses fitted before it (a suggestive gain and the lowest validation
error: its fits at a non-integer n cost minutes, spent only where the family is the likely cause).

The state is scaled by the start's bound z0: z -> c z maps (A, beta, gamma, k) to (c A, c^(1-n)
beta, c^(1-n) gamma, k / c), the same force, and c = 1 / z0 gives A = 1 / z0, beta + gamma = A
and k z0, so z tends to 1 on a long stroke, whatever n (:func:`scaled`). A is held there (with n
free, A and the scale of beta and gamma are one parameter). Why: with A = 1 the bound
(1 / (beta + gamma))^(1/n) moves with n at fixed beta (d ln zmax / dn = ln(beta + gamma) / n^2,
about 1 at zmax = 0.15 and n = 2), so the data, which fix the bound, tie beta to n along a curved
ridge (beta ~ zmax^-n): on the test's oscillator the refinement from n = 3 ran along it (beta and n
correlated +0.994 at its end) and stopped at its budget at n = 2.29, while n itself is well
determined (its standard error 0.03); scaled, the bound of z is (A / (beta + gamma))^(1/n) = 1 at
the start for every n, the ridge is straight and the same budget reaches n = 2.007 (truth 2), at
the noise floor. The values read as with A = 1 are derived (:func:`unscaled`): the initial
stiffness k0 = k A (the k of A = 1), the stroke zmax = (A / (beta + gamma))^(1/n) / A beyond
which the force yields, and the force it yields towards, k (A / (beta + gamma))^(1/n).

What tells it from its neighbours: a cubic spring stiffens (or softens) with the level but keeps
no memory (its force is a function of p, the loop has no area); a backlash at the input delays
the force by a play that is the same at every level; the Bouc-Wen force depends on the path
since the last reversal, and the loop's area grows with the stroke. The verdict names it over a
cubic spring (the same family, one parameter against three) only when it is significantly better
(:mod:`nlsid.diagnose.verdict`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from nlsid.diagnose.hypotheses import velocity_feedback
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, with_lti
from nlsid.diagnose.hypotheses.mass_forces import add_force, force_paths, needs
from nlsid.diagnose.hypotheses.mechanics import linear_paths
from nlsid.diagnose.nuisances import KEYS as NUISANCE_KEYS
from nlsid.diagnose.simulation import ModelRunner
from nlsid.simulate.jit import njit  # numba, its cache outside the package

BOUND_SHARES = (0.3, 0.6, 1.2, 2.4)  # zmax over the model's rms position, on the start grid
GAMMA_SHARES = (-0.5, 0.5)           # gamma / beta (the loop's unloading slope)
SPLITS = (0.25, 0.5)                 # k over the model's stiffness
FEEDBACK_SPLITS = (0.3, 0.6)         # k over G's static stiffness, the force's equivalent spring taken out of G
SIGN_AMBIGUITY = 1.05                # the other sign of gamma refined too where its best start's error is within this factor


def _applies(runner: ModelRunner) -> str | None:
    if runner.data["model"].get("type") != "mass_spring_damper":
        return "needs a mass_spring_damper model (its spring to the ground is what yields)"
    return None


def _shape(bound: float, share: float) -> tuple[float, float]:
    """(beta, gamma) with 1 / (beta + gamma) = bound and gamma = share beta."""
    beta = 1.0 / (bound * (1.0 + share))
    return beta, share * beta


def _estimate(ctx: Context) -> Estimate | str:
    """Start values (module docstring): the grid point of the least simulation error."""
    for signal in ("position", "velocity"):
        if needs(ctx, signal):
            return needs(ctx, signal)
    spread = float(np.sqrt(np.mean(np.concatenate([s["position"] - s["position"].mean() for s in ctx.internal]) ** 2)))
    if spread == 0:
        return "the model does not move on the estimation runs"
    stiffness = float(ctx.runner.data["model"].get("stiffness", 0.0))
    if stiffness <= 0:
        return "needs a spring in the model (stiffness > 0), part of which the hysteretic spring is"
    candidates = []
    for share in GAMMA_SHARES:
        for bound in (b * spread for b in BOUND_SHARES):
            beta, gamma = _shape(bound, share)
            for split in SPLITS:
                values = {"k": split * stiffness, "beta": beta, "gamma": gamma}
                starts = {"stiffness": (1 - 0.5 * split) * stiffness}
                cost = ctx.simulation_rss(HYSTERESIS.extend(_with_keys(ctx.runner.data, starts), values))
                candidates.append((cost, values, starts, bound, split))
    cost, values, starts, bound, split = min(candidates, key=lambda c: c[0])
    note = (f"the least simulation error of a grid of {len(BOUND_SHARES) * len(GAMMA_SHARES) * len(SPLITS)} starts: "
            f"zmax = {bound:.3g}, gamma / beta = {values['gamma'] / values['beta']:.2g}, k = {split:g} of the "
            f"model's stiffness and the model's stiffness lowered by k / 2 (no standard errors)")
    return Estimate(values, {"k": float("nan"), "beta": float("nan"), "gamma": float("nan")},
                    explained_db(float(np.sum(ctx.target() ** 2)), cost), note, starts=starts)


def _with_keys(data: dict, values: dict[str, float]) -> dict:
    return {**data, "model": {**data["model"], **values}}


def _reading(values: dict) -> str:
    bound = 1.0 / (values["beta"] + values["gamma"])
    return (f"a hysteretic spring of initial stiffness {values['k']:.4g} whose force yields towards "
            f"{values['k'] * bound:.4g} beyond a stroke of about {bound:.3g} (zmax = 1 / (beta + gamma); the "
            "exponent n held at 1, hysteresis_exponent frees it)")


HYSTERESIS = Hypothesis(
    "hysteresis", "Hysteresis (Bouc-Wen restoring force)", "stiffness", "k", "N/m",
    "odd distortion; the resonance moves with level and the damping with it; residual force depends on the "
    "path since the last reversal (a loop whose area grows with the stroke)",
    _applies, _estimate, add_force({"type": "bouc_wen"}), ("k", "beta", "gamma"),
    force_paths(("k", "beta", "gamma")), reading=_reading)



@njit(cache=True)
def _state_along(p: np.ndarray, beta: float, gamma: float) -> np.ndarray:
    z = np.zeros(p.size)
    now = 0.0
    for i in range(1, p.size):
        step = p[i] - p[i - 1]
        if step == 0.0:
            z[i] = now
            continue
        sign = 1.0 if step > 0.0 else -1.0
        left = abs(step)
        if now * sign < 0.0:  # towards zero: the unloading branch, rate beta - gamma, until z = 0
            rate = beta - gamma
            target = sign / rate if rate > 0.0 else 0.0
            reach = -now if rate == 0.0 else -math.log(target / (target - now)) / rate
            if reach >= left:
                now = now + left if rate == 0.0 else target + (now - target) * math.exp(-rate * left)
                z[i] = now
                continue
            now, left = 0.0, left - reach
        rate = beta + gamma  # away from zero: the loading branch towards the bound sign / (beta + gamma)
        now = sign / rate + (now - sign / rate) * math.exp(-rate * left)
        z[i] = now
    return z


def state_along(p: np.ndarray, beta: float, gamma: float) -> np.ndarray:
    """The Bouc-Wen state z (A = n = 1, from z = 0) along the sampled position ``p``, exact for p
    linear between samples.

    With n = 1 the law is rate independent: z' = v - beta |v| z - gamma v |z| is, per unit of
    stroke q = sigma (p - p0) in the direction sigma = sign(v), dz/dq = sigma - a z with a = beta
    + gamma where z has the sign of the motion (loading) and a = beta - gamma where it has the
    other (unloading, until z = 0). On each branch z(q) = sigma / a + (z0 - sigma / a) e^(-a q)
    (z0 + sigma q where a = 0); an unloading branch ends at q0 = -ln(t / (t - z0)) / a, t =
    sigma / a, where z crosses zero and loading begins. The config's -beta < gamma <= beta keeps a
    >= 0 on both branches.

    Parameters
    ----------
    p : ndarray
        Position samples (one run).
    beta, gamma : float
        The shape parameters (beta + gamma > 0, beta - gamma >= 0).

    Returns
    -------
    ndarray
        z at every sample (the force is k z).
    """
    return _state_along(np.ascontiguousarray(p, dtype=float), float(beta), float(gamma))


def equivalent_spring(p: np.ndarray, v: np.ndarray, force: np.ndarray) -> tuple[float, float]:
    """The stiffness k_e and damping c_e of the linear force k_e p + c_e v (with a constant) nearest
    ``force`` in least squares over the samples: the statistical (Bussgang, Caughey) linearization
    of a force with memory along the motion it is measured on (Gaussian p and v, or any other: the
    regression is over the samples themselves).

    Why: the BLA of a loop y = G (u - F) is G / (1 + G K_e) with K_e the force's equivalent
    linear part at the record's amplitude distribution (Bussgang 1952 for a static F of a Gaussian
    signal; Caughey 1963 for a hysteretic one, whose equivalent part is a spring and a damper:
    its loop's area dissipates), so a G fitted to the data holds K_e already, and the plant under
    the force is G / (1 - G K_e) (docs/feedback_start.md)."""
    columns = np.column_stack([np.ones(p.size), p, v])
    (_, stiffness, damping), *_ = np.linalg.lstsq(columns, force, rcond=None)
    return float(stiffness), float(damping)


def _estimate_feedback(ctx: Context) -> Estimate | str:
    """Start values of the feedback around a transfer function: the same grid, the model's output
    read as the position (:func:`velocity_feedback.reading`: a continuous G, or a discrete G's
    continuous equivalent, of relative degree 2 where the equivalent has relative degree 1 by its
    numerator's leading term dropped, :func:`velocity_feedback.degree_two`, as the end stops read
    it: the Bouc-Wen state reads the velocity, which around G(z) itself would be a backward
    difference with the force held over whole samples; on
    tests/diagnose/test_hysteresis_feedback_discrete.py's record that stopped 13.8 dB above the
    noise floor, read so it reaches it), its static stiffness K = G(0)^-1 in input units per output
    unit playing the model's stiffness (k a share of it).

    The linear part under each grid point's force is G with that force's equivalent spring and
    damper taken out (:func:`equivalent_spring` along the model's motion, G / (1 - (k_e + c_e s)
    G), :func:`velocity_feedback.with_spring`): the user's G, fitted to the data, is the loop's
    BLA and holds them (docs/feedback_start.md); k is FEEDBACK_SPLITS of K. Where some grid point's
    linear part would change a coefficient's sign, G is not read as the loop's BLA but as the
    plant's mechanics, and every grid point takes k / 2 times the numerator out of G's denominator
    (k SPLITS of K). On a G(z) fitted to the lower level's BLA of
    tests/diagnose/test_hysteresis_feedback_bla.py's record (its damping 45 where the plant's is
    20) that start stopped 53 times above the noise, this one at it.

    The refinement keeps gamma's sign, and the grid's best points of the two signs can err alike
    (within 2 % on five of six records, the wrong sign the lower on one of them): the best point of
    each sign is found on that sign's grid (G read as the loop's BLA or the plant's mechanics per
    sign), and the other sign's is offered as an alternative start (:attr:`Estimate.alternatives`,
    refined too and the better fit kept) where its error is within :data:`SIGN_AMBIGUITY` of the
    best one's or G is read otherwise under it (docs/feedback_start.md: the two records that ended
    2.5 times above the noise then reach it)."""
    found = velocity_feedback.reading(ctx, accelerates=True)
    if isinstance(found, str):
        return found
    reading, notes = found
    positions = velocity_feedback.positions(ctx, reading)
    if isinstance(positions, str):
        return positions
    num, den = np.asarray(reading.linear["num"], float), np.asarray(reading.linear["den"], float)
    discrete = reading.linear.get("domain") == "discrete"
    num0, den0 = (num.sum(), den.sum()) if discrete else (num[-1], den[-1])
    if num0 == 0 or den0 / num0 <= 0:
        return "needs a spring in the model (a positive static stiffness den(0) / num(0)), part of which yields"
    stiffness = float(den0 / num0)
    p, v = np.concatenate(positions), np.concatenate(reading.velocity)
    spread = float(np.std(p))
    if spread == 0:
        return "the model does not move on the estimation runs"
    lti = {"type": "transfer_function", **reading.linear, "output": "position"}
    base = with_lti(ctx.runner.data, lti)
    grid = []  # bound, beta, gamma, the two k shares, the linear part read as the loop's BLA, k_e, c_e
    for share in GAMMA_SHARES:
        for bound in (b * spread for b in BOUND_SHARES):
            beta, gamma = _shape(bound, share)
            z = np.concatenate([state_along(run, beta, gamma) for run in positions])
            unit = equivalent_spring(p, v, z)  # the spring and damper of the force per unit of k
            for split, plain in zip(FEEDBACK_SPLITS, SPLITS):
                k_e, c_e = split * stiffness * unit[0], split * stiffness * unit[1]
                under = velocity_feedback.with_spring(lti, -k_e, -c_e)
                grid.append((bound, beta, gamma, split, plain, under, k_e, c_e))
    starts = []  # the best start of each sign of gamma, each sign's grid read as a whole
    for sign in (1.0, -1.0):
        start = _best_of(ctx, [point for point in grid if np.sign(point[2]) == sign], lti, base, stiffness)
        if start is not None:
            starts.append(start)
    if not starts:
        return "every start's linear part under the force changes the sign of a coefficient of G's denominator"
    starts.sort(key=lambda start: start[0])
    (cost, values, note, held), others = starts[0], starts[1:]
    before = float(np.sum(ctx.target() ** 2))
    alternatives = tuple(Estimate(v, {n: float("nan") for n in v}, explained_db(before, c),
                                  "; ".join([f"the other sign of gamma: {n}", *notes]), lti=lti)
                         for c, v, n, h in others if c <= SIGN_AMBIGUITY * cost or h != held)
    if alternatives:
        note += (f"; the best start of the other sign of gamma (simulation error {others[0][0]:.4g} against "
                 f"{cost:.4g}, within {SIGN_AMBIGUITY:g} times, or G read otherwise under it) refined too, the lower "
                 "refined error kept")
    return Estimate(values, {n: float("nan") for n in values}, explained_db(before, cost),
                    "; ".join([note, *notes]), lti=lti, alternatives=alternatives)


def _best_of(ctx: Context, grid: list, lti: dict, base: dict, stiffness: float) -> tuple[float, dict, str, bool] | None:
    """The grid point of least simulation error among ``grid`` (points of one sign of gamma), its
    values, its note and whether G was read as the loop's BLA; None where no point has a linear
    part (every one would change a sign of G's denominator). Where some point's linear part under its force's equivalent spring and damper
    would change a sign, G is read as the plant's mechanics for all of them (k / 2 taken out)."""
    num = np.asarray(lti["num"], float)
    held = all(point[5] is not None for point in grid)  # G holds every grid force's equivalent spring and damper
    candidates = []
    for bound, beta, gamma, split, plain, under, k_e, c_e in grid:
        if not held:  # G is not this loop's BLA: the plant's mechanics with a spring in between
            split, c_e = plain, 0.0
            k_e = 0.5 * split * stiffness
            under = velocity_feedback.with_spring(lti, -k_e, 0.0)
            if under is None:
                continue
        values = {"k": split * stiffness, "beta": beta, "gamma": gamma,
                  **{f"num[{i}]": float(c) for i, c in enumerate(num)},
                  **{f"den[{i}]": float(c) for i, c in enumerate(under["den"])}}
        cost = ctx.simulation_rss(HYSTERESIS_FEEDBACK.extend(base, values))
        candidates.append((cost, values, bound, split, k_e, c_e))
    if not candidates:
        return None
    cost, values, bound, split, k_e, c_e = min(candidates, key=lambda c: c[0])
    linear = (f"the linear part G / (1 - (k_e + c_e s) G) with the force's equivalent spring k_e = {k_e:.4g} and "
              f"damper c_e = {c_e:.4g} along the model's motion taken out (G read as the loop's BLA)" if held else
              f"the linear part G / (1 - k_e G) with k_e = k / 2 = {k_e:.4g} (G read as the plant's mechanics with a "
              "spring between the small- and large-stroke ones: it holds less than some grid force's equivalent "
              "damper, so it is not that loop's BLA)")
    note = (f"the least simulation error of a grid of {len(candidates)} starts with gamma of this sign: zmax = "
            f"{bound:.3g}, gamma / beta = {values['gamma'] / values['beta']:.2g}, k = {split:g} of the model's "
            f"static stiffness {stiffness:.4g}, {linear} (no standard errors)")
    return cost, values, note, held


HYSTERESIS_FEEDBACK = Hypothesis(
    "hysteresis_feedback", "Hysteresis (Bouc-Wen force) fed back around the transfer function", "stiffness", "k",
    "input units / output units",
    "as hysteresis, for a transfer function model: residual like the response to a Bouc-Wen force of the output",
    velocity_feedback.applies, _estimate_feedback, velocity_feedback.extender({"type": "bouc_wen"}, ("k", "beta", "gamma")),
    ("k", "beta", "gamma"), velocity_feedback.paths(("k", "beta", "gamma")), reading=_reading)

EXPONENTS = (1.5, 2.0, 2.5, 3.0)  # n on the start grid of hysteresis_exponent
BOUND_RATIOS = (1.0, 1.15)    # its bound of z over the n = 1 fit's (a sharper knee yields later)
K_RATIOS = (0.8, 1.0)         # its k over the n = 1 fit's
FORCE = ("k", "beta", "gamma", "n")


def _exponent_applies(runner: ModelRunner) -> str | None:
    if _applies(runner) is None or velocity_feedback.applies(runner) is None:
        return None
    return "needs a mass_spring_damper model or an open-loop transfer_function (where hysteresis applies)"


def _on_transfer_function(data: dict) -> bool:
    return data["model"]["type"] == "transfer_function"


def _extend_exponent(data: dict, values: dict) -> dict:
    if _on_transfer_function(data):
        return velocity_feedback.extender({"type": "bouc_wen"}, (*FORCE, "A"))(data, values)
    return add_force({"type": "bouc_wen"})(data, {k: values[k] for k in (*FORCE, "A") if k in values})


def _exponent_paths(data: dict) -> dict[str, str]:
    return velocity_feedback.paths(FORCE)(data) if _on_transfer_function(data) else force_paths(FORCE)(data)


def _estimate_exponent(ctx: Context) -> Estimate | str:
    """Start values (module docstring): from the fitted hysteresis (n = 1) of the model's kind."""
    around = _on_transfer_function(ctx.runner.data)
    name = "hysteresis_feedback" if around else "hysteresis"
    extended, fitted = ctx.extended.get(name), ctx.fitted.get(name)
    if extended is None or fitted is None:
        return f"needs the fit of {name} (n = 1) to start from"
    if not ctx.leads(name):
        return (f"not fitted: {name} (n = 1) does not lead (it lowers the validation error less than another "
                "hypothesis, or not even suggestively), so no exponent of its knee is sought (its fits at a "
                "non-integer n cost minutes)")
    model = extended["model"]
    force = model["nonlinearities"][-1]
    nuisances = {k: float(model[k]) for k in NUISANCE_KEYS if k in model}
    if around:
        simpler = velocity_feedback.fitted(ctx, name)
        base, coefficients, lti, starts = (with_lti(ctx.runner.data, simpler.lti), simpler.coefficients,
                                           simpler.lti, nuisances)
    else:
        mechanics = {k: float(model[k]) for k in linear_paths(ctx.runner.data)}
        base, coefficients, lti, starts = (_with_keys(ctx.runner.data, mechanics), {}, None,
                                           {**mechanics, **nuisances})
    bound = 1.0 / (float(force["beta"]) + float(force["gamma"]))
    candidates = []
    for n, share, wider, softer in itertools.product(EXPONENTS, GAMMA_SHARES, BOUND_RATIOS, K_RATIOS):
        values = {**scaled(softer * float(force["k"]), wider * bound, share, n), **coefficients}
        extended_start = _extend_exponent(base, values)
        extended_start["model"].update(starts)
        candidates.append((ctx.simulation_rss(extended_start), values))
    cost, values = min(candidates, key=lambda c: c[0])
    note = (f"from the fit of {name} (n = 1): n = {values['n']:g}, gamma / beta = "
            f"{values['gamma'] / values['beta']:.2g}, k and the bound of z near the fit's, the least simulation "
            f"error of a grid of {len(candidates)}, the state scaled to tend to 1 (A = {values['A']:.4g}, held) "
            "(no standard errors)")
    return Estimate(values, {k: float("nan") for k in values}, explained_db(float(np.sum(ctx.target() ** 2)), cost),
                    note, lti=lti, starts=starts)


def scaled(k: float, bound: float, share: float, n: float) -> dict[str, float]:
    """The Bouc-Wen force of initial stiffness ``k`` yielding beyond the stroke ``bound`` (gamma =
    ``share`` beta, exponent ``n``) with its state scaled to tend to 1 (module docstring):
    A = 1 / bound, beta = A / (1 + share), gamma = share beta, k bound. With A = 1 it is k, beta =
    bound^-n / (1 + share), gamma = share beta: z -> z / bound maps the one to the other."""
    beta = 1.0 / (bound * (1.0 + share))
    return {"k": k * bound, "A": 1.0 / bound, "beta": beta, "gamma": share * beta, "n": n}


def unscaled(values: dict, starts: dict | None = None, model: dict | None = None) -> dict[str, float]:
    """What a Bouc-Wen force (k, A, beta, gamma, n) means whatever the scale of its state: the
    initial stiffness k0 = k A (the k of the same force with A = 1), the stroke zmax = (A / (beta +
    gamma))^(1/n) / A beyond which it yields and the force it yields towards, fmax = k (A / (beta
    + gamma))^(1/n). (``starts`` and ``model``: unused, :attr:`Hypothesis.derive`'s signature.)"""
    a = float(values.get("A", 1.0))
    bound = (a / (values["beta"] + values["gamma"])) ** (1.0 / values["n"])
    return {"k0": values["k"] * a, "zmax": bound / a, "fmax": values["k"] * bound}


def _reading_exponent(values: dict) -> str:
    seen = unscaled(values)
    return (f"a hysteretic spring of initial stiffness k0 = {seen['k0']:.4g} yielding towards {seen['fmax']:.4g} "
            f"beyond a stroke of about {seen['zmax']:.3g}, with the exponent n = {values['n']:.3g} (1 a smooth knee, "
            f"larger a sharper one; the state scaled by A = {values.get('A', 1.0):.4g}, k = k0 / A)")


HYSTERESIS_EXPONENT = Hypothesis(
    "hysteresis_exponent", "Hysteresis (Bouc-Wen force with its exponent n)", "stiffness", "n", "",
    "as hysteresis, the force yielding more sharply (or smoothly) than n = 1 allows",
    _exponent_applies, _estimate_exponent, _extend_exponent, FORCE, _exponent_paths, reading=_reading_exponent,
    derive=unscaled)

HYPOTHESES = (HYSTERESIS, HYSTERESIS_FEEDBACK, HYSTERESIS_EXPONENT)
