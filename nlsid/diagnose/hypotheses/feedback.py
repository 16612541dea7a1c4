"""Polynomial feedback of the output around a linear model: the Duffing structure for any transfer
function, continuous or discrete (such as the one ``nlsid fit`` writes from a BLA).

The model G from u to y becomes y = G (u - k3 y^3): a ``nonlinear_feedback`` plant with G as its
linear part (gain 1, so k3 is in units of u per y^3) and a ``cubic_stiffness`` force reading y. Its
physical reading is a cubic spring, hardening for k3 > 0 and softening for k3 < 0, when y is a
position and u a force (the electronic Duffing oscillator of the Silverbox benchmark, Wigren and
Schoukens 2013, is this system).

Signature: to first order in k3 the residual is the model's response to the input error
-k3 y_model^3, so k3 is the least-squares regression of the residual on that response, together
with the response to -y_model (a linear stiffness, into which a model fitted to the BLA has taken
part of the cubic: :func:`_estimate`). A force that reads the position cannot act on it without
delay (an algebraic loop), so G must be strictly proper: a continuous numerator of lower degree
than the denominator, a discrete b0 (the z^0 coefficient of the numerator, the direct feedthrough
D) zero. A discrete b0 is set to zero (said in the note): the model extended is G(z) - b0, the
part of the user's model a force-to-position mechanics can be (a ZOH equivalent of a continuous
G(s) has b0 = D = 0); the fit does not restore b0, its share of the response is left to the
linear part's other coefficients.

A discrete model (as ``nlsid fit`` writes it) is extended as its continuous equivalent: the G(s)
whose zero-order-hold discretisation at the runs' fs is exactly G(z) - b0
(:mod:`nlsid.models.continuous_equivalent`), simulated with sub-steps, so that the force acts
within the sample as a spring's does. Fed back around G(z) itself, the force would be held over a
whole sample: on tests/diagnose/test_diagnose_polynomial_feedback.py's data that structure with the true
parameters is 2.9e-3 rms from the continuous Duffing truth (2.9e-5 for a continuous G), and its
fits stopped 18-22 dB above the noise (tests/diagnose/test_diagnose_continuous_equivalent.py). Where no
continuous equivalent exists (a pole at z = 0 or on the negative real z axis) the feedback is
extended around G(z), and the note says so. The fit engine then refines k3 together with the
linear part's coefficients (the nonzero ones of the numerator but a discrete b0, the denominator
but its leading 1; for the continuous equivalent those of its B(s) / A(s), A monic): under the
nonlinearity the BLA the model came from is biased, and a frozen linear part could not reach the
floor.

``polynomial_feedback`` adds the quadratic term, y = G (u - k2 y^2 - k3 y^3) with a
``polynomial_stiffness`` force: an asymmetric spring (k2 > 0 stiffer for y > 0) that is hardening
or softening (k3). Its signature is the regression of the residual on the responses to -y^2 and
-y^3 at the input, with a constant (a sensor offset, which the response to -y^2, not of zero mean,
would otherwise take); where the cubic feedback was fitted, it starts from that fit instead
(:func:`_estimate_polynomial`). The fit engine refines k2 and k3 with the linear part. It is the
same family as ``cubic_feedback``, one parameter richer: the verdict names it only when it is
significantly better (:mod:`nlsid.diagnose.verdict`).

What the data cannot tell apart: k2 y^2 + k3 y^3 = k3 (y + c)^3 - 3 k3 c^2 y - k3 c^3 with
c = k2 / (3 k3), a cubic spring centred at y = -c, a linear stiffness (the linear part's) and a
constant force. So the cubic feedback, whose fit re-fits the force offset and the output offset
with it, is the polynomial one in other coordinates (the shift of the centre is the force offset's
direction, :func:`_from_cubic`): the polynomial's fit holds ``force_offset`` at the model's value
(``holds``; free, it would make the fit singular), and its reading states the equivalent centre.
It can beat the cubic only where the cubic's fit stops short, and it does: the cubic reaches a
shifted centre only through three strongly coupled parameters (force offset, output offset,
linear stiffness), which the budget of :data:`nlsid.diagnose.diagnosis.FIT_STEPS` steps does not
reach (tests/diagnose/test_diagnose_polynomial_feedback.py: the cubic stops 23-25 dB above the noise, the
polynomial within 0.04 dB of it). Where the cubic's fit leaves nothing along the quadratic term
(a score test, :func:`_estimate_polynomial`) the polynomial is not fitted.
"""

from __future__ import annotations

import copy
import math
from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, regress, spring
from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.models.continuous_equivalent import continuous_transfer_function

SCORE_STEP = 1e-6  # the score test's input error, relative to the rms input (forward difference)

KEPT = ("input_offset", "output_offset", "input_channels", "output_timing", "input_nonlinearity",
        "output_nonlinearity", "delay")


def _applies(runner: ModelRunner) -> str | None:
    model = runner.data["model"]
    if model["type"] != "transfer_function":
        return "needs a transfer_function model (the mechanical templates have cubic stiffness)"
    num, den = np.trim_zeros(np.asarray(model["num"], float), "f"), np.asarray(model["den"], float)
    if model.get("domain", "continuous") == "continuous" and num.size >= np.trim_zeros(den, "f").size:
        return "the continuous model is not strictly proper (a force would act without delay)"
    return None


def _responses(ctx: Context, powers: tuple[int, ...]) -> list[np.ndarray]:
    """The model's responses to the input errors -y_model^p, one column per power p."""
    outputs = ctx.runner.simulate_each(ctx.runs)
    return [ctx.response([-x**p for x in outputs], "process") for p in powers]


def _linear(ctx: Context) -> tuple[dict | None, list[str]]:
    """The LTI part the feedback goes around (an ``lti`` for :class:`Estimate`: None for the
    model's own) and the notes on it: a discrete model's b0 set to 0, and its continuous
    equivalent where there is one (module docstring)."""
    model = ctx.runner.data["model"]
    if model.get("domain") != "discrete":
        return None, []
    notes = ([f"b0 = {model['num'][0]:.3g} set to 0 (a direct feedthrough: a force reading the position would close "
              "an algebraic loop through it)"] if model["num"][0] else [])
    equivalent = continuous_transfer_function([0.0, *model["num"][1:]], model["den"], ctx.runs[0].fs)
    if isinstance(equivalent, str):
        return None, [*notes, f"extended in discrete time (the force held over each sample): the model has no "
                              f"continuous equivalent, {equivalent}"]
    return equivalent, [*notes, "extended in continuous time (the model's exact ZOH equivalent)"]


def _estimate(ctx: Context) -> Estimate | str:
    """Start values: k3 regressed together with a linear stiffness c (the residual on the
    responses to -y^3 and -y at the input), and the linear part started at G / (1 + c G)
    (:func:`_stiffened`), which y = G (u - c y - k3 y^3) is.

    A model fitted to the BLA already holds the cubic's mean stiffening (3 k3 E{y^2} for a
    Gaussian y): the response to -y^3 is mostly linear in y, a part the residual of that model
    lacks, and regressed alone it took k3 with the wrong sign on 4 of 8 noise seeds of
    tests/diagnose/test_diagnose_continuous_equivalent.py (a 2/2 fitted to the BLA; the fit keeps the sign,
    and the diagnosis named nothing). With c beside it k3 is the regression on the part of the
    response to -y^3 that is not the response to -y (Frisch-Waugh), and c the linear stiffness the
    model lacks (negative where the BLA took part of the cubic's). Where G / (1 + c G) would change
    the sign of a denominator coefficient, or make a zero one nonzero (a change of structure, not
    a start), the linear part starts at the model's."""
    est = regress(ctx.target(), _responses(ctx, (3, 1)), ["k3", "c"])
    lti, notes = _linear(ctx)
    model = ctx.runner.data["model"]
    linear = lti or {"num": [0.0, *model["num"][1:]] if model.get("domain") == "discrete" else model["num"],
                     "den": model["den"], "domain": model.get("domain", "continuous")}
    k3, c = est.values["k3"], est.values["c"]
    den = np.asarray(linear["den"], float)
    stiffened = _stiffened(linear, c)
    if np.all(np.sign(stiffened) == np.sign(den)):
        notes.append(f"the linear part started at G / (1 + c G), c = {c:.4g} (a linear stiffness regressed with k3)")
    else:
        stiffened = den
    names = [n for n in _paths(("k3",))({"model": linear}) if n != "k3"]
    values = {"k3": k3, **_coefficients({"num": np.asarray(linear["num"], float), "den": stiffened}, names)}
    notes = [f"odd feedback of y^3 with the sign of a {spring(k3)} spring", *notes]
    return Estimate(values, {"k3": est.std["k3"], **{n: math.nan for n in names}}, est.explained_db,
                    "; ".join(notes), lti=lti)


def _centred(x: np.ndarray) -> np.ndarray:
    return x - x.mean()


def _score(ctx: Context, cubic: dict) -> tuple[float, float, float]:
    """(t, coefficient, residual sum of squares) of the score regression of
    :func:`_estimate_polynomial`: the fitted cubic's estimation residual, without its mean, on the
    cubic model's sensitivity to the input error -y^2 (a forward difference), without its mean."""
    runner = ctx.runner.with_changes(cubic)
    residual, column = [], []
    for run in ctx.runs:
        nominal = runner.simulate(run)
        d = -nominal.y**2
        step = SCORE_STEP * float(np.sqrt(np.mean(run.u**2)) / max(np.sqrt(np.mean(d**2)), 1e-300))
        moved = getattr(runner.simulate(run, process=step * d), ctx.signal)
        x = getattr(nominal, ctx.signal)  # the judged signal: y, or in closed loop u
        residual.append(steady_mean(run, ctx.measured(run) - x))
        column.append(steady_mean(run, moved - x) / step)
    r = np.concatenate(residual)
    est = regress(_centred(r), [_centred(np.concatenate(column))], ["k2"])
    return est.values["k2"] / est.std["k2"], est.values["k2"], float(np.sum(r**2))


def _static_inverse(linear: dict) -> float:
    """1 / G(0) of a transfer function config (inf where G(0) = 0)."""
    num, den = np.asarray(linear["num"], float), np.asarray(linear["den"], float)
    if linear.get("domain") == "discrete":
        num0, den0 = num.sum(), den.sum()
    else:
        num0, den0 = num[-1], den[-1]
    return den0 / num0 if num0 != 0 else math.inf


def _stiffened(linear: dict, c: float) -> np.ndarray:
    """The denominator of G / (1 + c G) of a transfer function config, den + c num aligned by its
    domain: y = G (u - c y - F) is y = G / (1 + c G) (u - F). (The terms of a discrete numerator
    longer than the denominator are left out: it is then a start value, not the same model.)"""
    num, den = np.asarray(linear["num"], float), np.asarray(linear["den"], float)
    if linear.get("domain") == "discrete":
        return den + c * np.pad(num, (0, max(den.size - num.size, 0)))[:den.size]
    return den + c * np.pad(num, (den.size - num.size, 0))


def _coefficients(polynomials: dict, names: list[str]) -> dict[str, float]:
    """The linear coefficients ``names`` (``num[i]``, ``den[i]``) of ``polynomials`` (key -> array)."""
    out = {}
    for name in names:
        key, index = name[:-1].split("[")
        out[name] = float(polynomials[key][int(index)])
    return out


def _from_cubic(cubic: dict, names: list[str]) -> tuple[dict[str, float], float]:
    """The fitted cubic feedback (k3, force offset f0, linear part G) in the polynomial's
    coordinates with the force offset at zero, and the centre shift s (module docstring, with the
    constant term): z = y' + s turns G^-1 z = u + f0 - k3 z^3 into G'^-1 y' = u - 3 k3 s y'^2 -
    k3 y'^3 with G'^-1 = G^-1 + 3 k3 s^2, where s solves k3 s^3 + s / G(0) = f0 (the real root
    nearest zero); the output offset takes s, and the fit re-fits it. ``names``: the linear
    coefficients to start from (``num[i]``, ``den[i]``)."""
    model = cubic["model"]
    k3, linear = model["nonlinearities"][0]["k3"], model["linear"]
    f0 = model.get("force_offset", 0.0) / model.get("gain", 1.0)
    inverse = _static_inverse(linear)
    s = 0.0
    if f0 != 0 and math.isfinite(inverse):
        roots = np.roots([k3, 0.0, inverse, -f0])
        real = roots[np.abs(roots.imag) <= 1e-9 * np.abs(roots)].real
        s = float(real[np.argmin(np.abs(real))])
    shifted = {"num": np.asarray(linear["num"], float), "den": _stiffened(linear, 3 * k3 * s**2)}
    return {"k2": 3 * k3 * s, "k3": k3, **_coefficients(shifted, names)}, s


def _estimate_polynomial(ctx: Context) -> Estimate | str:
    """Start values: from the fitted cubic feedback where there is one, else the signature.

    With its force offset free the cubic feedback is the polynomial one in other coordinates
    (:func:`_from_cubic`), so the polynomial can be better only where the cubic's fit stopped short
    of its optimum. A score test measures how far: the estimation residual r of the fitted cubic
    model (its extended config, nuisances included) regressed on that model's sensitivity x to
    the input error -y^2 (:func:`_score`); one step along x lowers the residual's sum of squares
    by t^2 s^2 (t the regression's t-statistic, s^2 its residual variance). With |t| below the
    two-sided ALPHA quantile of N(0, 1) that drop is not even detectable, while naming the
    polynomial needs its validation error power below the cubic's by the factor F* of
    :mod:`nlsid.diagnose.verdict` (1.07 at 8192 degrees of freedom: 7 %): it is not fitted. A
    cubic fit that stopped short leaves a structured residual, which raises |t|; the polynomial
    then starts from the cubic in its coordinates, plus that step along x for k2, so it starts
    where the cubic stopped (up to the output offset), with the right sign of k2. (A first-order
    signature on the nominal model does not give it: with a cubic that moves the resonance the
    response to -y^2 through the nominal has the wrong phase, and k2 came out of the wrong sign.)

    Without a cubic fit: k2 and k3 regressed together with a constant (an output offset, not
    reported), i.e. the target and the columns without their means (Frisch-Waugh).
    """
    from scipy.stats import norm

    from nlsid.diagnose.verdict import ALPHA

    target = ctx.target()
    cubic = ctx.extended.get("cubic_feedback")
    lti, notes = _linear(ctx)
    if cubic is None:
        est = regress(_centred(target), [_centred(c) for c in _responses(ctx, (2, 3))], list(POLYNOMIAL))
        return Estimate(est.values, est.std, est.explained_db,
                        "; ".join(["signature regressed with a constant (an output offset); force_offset held",
                                   *notes]), lti=lti)
    t, step, rss = _score(ctx, cubic)
    z = float(norm.isf(ALPHA / 2))
    if abs(t) < z:
        return (f"not fitted: the quadratic term is not detectable in the residual of the fitted cubic feedback "
                f"(score test: t = {t:.2f}, |t| < {z:.2f}), so it cannot be significantly better")
    names = [n for n in _paths(POLYNOMIAL)({"model": cubic["model"]["linear"]}) if n not in POLYNOMIAL]
    values, shift = _from_cubic(cubic, names)
    values["k2"] += step
    start = (f"start: the fitted cubic feedback in these coordinates (centre shift {shift:.4g}, force_offset "
             f"held at the model's) and one step along k2 (score test t = {t:.1f})")
    return Estimate(values, {n: math.nan for n in values}, explained_db(float(np.sum(target**2)), rss),
                    "; ".join([start, *notes]), lti=lti)


def _stiffer(k2: float) -> str:
    """Where a spring with the quadratic term k2 p^2 against the motion is stiffer."""
    return f"stiffer for y {'>' if k2 > 0 else '<'} 0"


def _reading(values: dict) -> str:
    """The fitted polynomial spring in words, with the centre of the cubic it equals (module docstring)."""
    k2, k3 = values["k2"], values["k3"]
    return (f"an asymmetric spring, {_stiffer(k2)} (k2), {spring(k3)} (k3); "
            f"equivalently a {spring(k3)} cubic spring centred at y = {-k2 / (3 * k3):.4g} "
            "(-k2 / 3 k3, with a constant force and a linear stiffness)")


def _extender(force: str, names: tuple[str, ...]) -> Callable[[dict, dict], dict]:
    """The extension: the model as the linear part of a ``nonlinear_feedback`` with one ``force``."""
    def extend(data: dict, values: dict) -> dict:
        out = copy.deepcopy(data)
        model = out["model"]
        linear = {k: model[k] for k in ("type", "num", "den", "domain") if k in model}
        if linear.get("domain") == "discrete":
            linear["num"] = [0.0, *linear["num"][1:]]
        for key in ("num", "den"):  # start values of the linear coefficients, where the estimate has them
            linear[key] = [float(values.get(f"{key}[{i}]", v)) for i, v in enumerate(linear[key])]
        out["model"] = {"type": "nonlinear_feedback", "linear": linear, "gain": 1.0,
                        "nonlinearities": [{"type": force, **{n: float(values[n]) for n in names}}],
                        **{k: model[k] for k in KEPT if k in model}}
        return out
    return extend


def _paths(names: tuple[str, ...]) -> Callable[[dict], dict[str, str]]:
    def paths(data: dict) -> dict[str, str]:
        """The force's ``names``, and the linear part's coefficients (numerator but a discrete b0,
        denominator but a0)."""
        model = data["model"]
        first = 1 if model.get("domain") == "discrete" else 0
        out = {n: f"model.nonlinearities[0].{n}" for n in names}
        out.update({f"num[{i}]": f"model.linear.num[{i}]" for i in range(first, len(model["num"]))
                    if model["num"][i] != 0})
        out.update({f"den[{i}]": f"model.linear.den[{i}]" for i in range(1, len(model["den"])) if model["den"][i] != 0})
        return out
    return paths


POLYNOMIAL = ("k2", "k3")

HYPOTHESES = (
    Hypothesis("cubic_feedback", "Cubic feedback of the output (cubic stiffness)", "stiffness", "k3",
               "input units / output units^3",
               "odd distortion; the resonance moves with level; residual like the response to -y^3 at the input",
               _applies, _estimate, _extender("cubic_stiffness", ("k3",)), ("k3",), _paths(("k3",)),
               qualifier=lambda values: spring(values["k3"])),
    Hypothesis("polynomial_feedback", "Quadratic and cubic feedback of the output (asymmetric stiffness)", "stiffness",
               "k2", "input units / output units^2",
               "odd and even distortion; residual like the responses to -y^2 and -y^3 at the input",
               _applies, _estimate_polynomial, _extender("polynomial_stiffness", POLYNOMIAL), POLYNOMIAL,
               _paths(POLYNOMIAL), reading=_reading, holds=("force_offset",),
               qualifier=lambda values: f"{_stiffer(values['k2'])}, {spring(values['k3'])}"),
)
