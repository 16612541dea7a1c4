"""Forces of the velocity (friction, nonlinear damping) fed back around a transfer function model,
as :mod:`~nlsid.diagnose.hypotheses.feedback` feeds a spring's force back: the model G from u to y
becomes a ``nonlinear_feedback`` plant, y = G (u - F(v)) with v the velocity of the moving part
(gain 1: F in units of u).

Which signal is the velocity depends on what G is, which a fitted transfer function does not say:

- G from force to *velocity* (y = v) when G has a zero at s = 0 (the velocity of a mass held by a
  spring: no static velocity under a constant force): the position is G / s, and the extension
  is the feedback around G / s with ``output: velocity``; G needs relative degree >= 1;
- G from force to *position* (y = p) otherwise: v = p' = s G u. The feedback needs G of relative
  degree >= 2 (a force accelerates: :func:`nlsid.models.mechanical.force_feedback` reads v as a
  state). A discrete G (as ``nlsid fit`` writes it) is extended as its continuous equivalent
  (:mod:`nlsid.diagnose.hypotheses.feedback`'s reasons: a force acts within the sample), its b0
  set to 0; where that has relative degree 1 (a fitted numerator's leading term), that term is
  dropped (:func:`degree_two`, relative degree 2: a force accelerates, the refinement of the
  linear part takes what the term did in the band). Around G(z) itself, the velocity the
  backward difference of the position and the force held over the sample
  (:func:`nlsid.models.mechanical.force_feedback`), Coulomb friction stopped 3.4 dB above the
  noise floor on tests/diagnose/test_friction_feedback_start.py's G(z) with a zero at 318 Hz,
  read so at it; that route is left for an equivalent of relative degree 0.

The velocity reading is not offered for a G with a static gain: read as a velocity, y fed back
through a force of it is a static feedback of the output, y = G (u - F(y)), the model of a spring
(:mod:`nlsid.diagnose.hypotheses.feedback`'s cubic feedback for F = c3 y^3): the same model under
two names, which the data cannot tell apart. The velocity of a free damped mass (a static gain
1 / c) is therefore read as a position; its user should give the model from force to position.

The linear part's coefficients are refined with the force (those that are not zero: the integrator
of G / s stays), as for the cubic feedback. Open loop only: in closed loop the velocity along the
model's trajectory needs the loop, which the probe of this module does not close.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, regress
from nlsid.diagnose.hypotheses.feedback import KEPT
from nlsid.diagnose.simulation import ModelRunner
from nlsid.models.continuous_equivalent import continuous_transfer_function

INPUT_KEYS = ("input_offset", "input_channels", "input_nonlinearity", "delay")  # kept in the velocity probe


def applies(runner: ModelRunner) -> str | None:
    model = runner.data["model"]
    if model["type"] != "transfer_function":
        return "needs a transfer_function model (the mechanical templates carry the force themselves)"
    if runner.closed:
        return "needs an open-loop model (the velocity probe does not close the loop)"
    return None


@dataclass(frozen=True)
class Reading:
    """One reading of the model's output: the linear part from force to position (G, or G / s, with
    its ``domain``), ``output`` (``position`` or ``velocity``) and the velocity of every run along
    the nominal trajectory."""

    output: str
    linear: dict
    velocity: list[np.ndarray]


ZERO_AT_DC = 1e-9  # num's constant term below this times its largest (frequency-scaled): a zero at s = 0


def _continuous(ctx: Context) -> tuple[dict | str, list[str]]:
    """The model's transfer function in continuous time (a discrete one's exact ZOH equivalent with
    b0 set to 0), or why there is none; and the notes on it."""
    model = ctx.runner.data["model"]
    if model.get("domain", "continuous") != "discrete":
        return {"num": [float(v) for v in model["num"]], "den": [float(v) for v in model["den"]]}, []
    fs = ctx.runs[0].fs
    equivalent = continuous_transfer_function([0.0, *model["num"][1:]], model["den"], fs)
    if isinstance(equivalent, str):
        return f"the discrete model has no continuous equivalent: {equivalent}", []
    notes = ["extended in continuous time (the model's exact ZOH equivalent)"]
    num, den = [float(v) for v in equivalent["num"]], [float(v) for v in equivalent["den"]]
    lead = _negligible_lead(num, den, fs)
    if lead is not None:
        num = num[1:]
        notes.append(f"its numerator's leading term {lead:.3g} dropped (a zero beyond the band, less than "
                     f"{NEGLIGIBLE_LEAD:.0%} of the numerator at the Nyquist frequency: a force accelerates)")
    return {"num": num, "den": den}, notes


NEGLIGIBLE_LEAD = 0.1  # a leading numerator term this small at Nyquist is the fit's noise (_negligible_lead)


def _negligible_lead(num: list[float], den: list[float], fs: float) -> float | None:
    """The leading numerator coefficient of a continuous equivalent of relative degree 1 where it
    is negligible, else None: its term at the Nyquist frequency w = pi fs within NEGLIGIBLE_LEAD of
    the rest of the numerator there (a zero far beyond the band). A transfer function fitted to
    a force-to-position record (``nlsid fit``, b0 = 0) has a continuous equivalent with such a term
    (on the tests' Stribeck record -0.077 s against 9635, a zero at 20 kHz): kept, it gives the
    model relative degree 1, and the force would be fed back in discrete time, held over whole
    samples (the Coulomb feedback stopped 37 dB above the floor); dropped, the feedback is
    continuous and the refinement of the linear part takes what the term did in the band."""
    trimmed = np.trim_zeros(np.asarray(num, float), "f")
    if trimmed.size < 2 or np.trim_zeros(np.asarray(den, float), "f").size - trimmed.size != 1:
        return None
    s = 1j * np.pi * fs
    lead = abs(trimmed[0] * s ** (trimmed.size - 1))
    return float(trimmed[0]) if lead <= NEGLIGIBLE_LEAD * abs(np.polyval(trimmed[1:], s)) else None


def _relative_degree(linear: dict) -> int:
    return (np.trim_zeros(np.asarray(linear["den"], float), "f").size
            - np.trim_zeros(np.asarray(linear["num"], float), "f").size)


def _zero_at_dc(linear: dict, fs: float) -> bool:
    """Whether the continuous num has a zero at s = 0: its constant term negligible against the
    others, each scaled by the power of a frequency (the sampling rate) it multiplies."""
    num = np.trim_zeros(np.asarray(linear["num"], float), "f")
    scaled = np.abs(num) * (2 * np.pi * fs) ** np.arange(num.size - 1, -1, -1)
    return num.size > 1 and scaled[-1] <= ZERO_AT_DC * scaled.max()


def _probe(ctx: Context, linear: dict) -> list[np.ndarray]:
    """The output of the transfer function ``linear`` (with the model's input-side keys, no output
    offset or block) on every run."""
    model = ctx.runner.data["model"]
    data = {"model": {"type": "transfer_function", **linear,
                      **{k: copy.deepcopy(model[k]) for k in INPUT_KEYS if k in model}}}
    return ctx.runner.with_changes(data).simulate_each(ctx.runs)


def reading(ctx: Context, accelerates: bool = False) -> tuple[Reading, list[str]] | str:
    """The reading of the model's output (module docstring), with the notes on the linear part.

    ``accelerates``: where a discrete G's continuous equivalent has relative degree 1 and no zero
    at s = 0, read it as a position with the numerator's leading term dropped (:func:`degree_two`)
    instead of around G(z) with the velocity a backward difference."""
    model = ctx.runner.data["model"]
    discrete = model.get("domain") == "discrete"
    notes = ([f"b0 = {model['num'][0]:.3g} set to 0 (a direct feedthrough would close an algebraic loop)"]
             if discrete and model["num"][0] else [])
    linear, more = _continuous(ctx)
    if isinstance(linear, str):
        return linear
    fs = ctx.runs[0].fs
    if _zero_at_dc(linear, fs):
        if _relative_degree(linear) < 1:
            return "the model is not strictly proper (a force of the velocity would act without delay)"
        integrated = {"num": linear["num"], "den": [*linear["den"], 0.0], "domain": "continuous"}
        return Reading("velocity", integrated, _probe(ctx, {**linear, "domain": "continuous"})), [*notes, *more]
    if _relative_degree(linear) >= 2:
        return (Reading("position", {**linear, "domain": "continuous"},
                        _probe(ctx, {"num": [*linear["num"], 0.0], "den": linear["den"], "domain": "continuous"})),
                [*notes, *more])
    if discrete and accelerates and _relative_degree(linear) == 1:
        lead, reduced = degree_two(linear)
        return (Reading("position", {**reduced, "domain": "continuous"},
                        _probe(ctx, {"num": [*reduced["num"], 0.0], "den": reduced["den"], "domain": "continuous"})),
                [*notes, *more, f"its numerator's leading term {lead:.3g} dropped (relative degree 2: a force "
                                "accelerates the position; the refinement of the linear part takes what the term "
                                "did in the band)"])
    if discrete:
        own = {"num": [0.0, *model["num"][1:]], "den": list(model["den"]), "domain": "discrete"}
        positions = _probe(ctx, own)
        velocity = [np.diff(p, prepend=p[0]) * fs for p in positions]
        return Reading("position", own, velocity), [*notes, "extended in discrete time, the velocity the backward "
                                                            "difference of the position (its continuous equivalent "
                                                            "has relative degree 1: a force would act without delay)"]
    return ("a force of the velocity needs the model from force to position of relative degree >= 2, or one "
            "from force to velocity (a zero at s = 0)")


def degree_two(linear: dict) -> tuple[float, dict]:
    """The leading numerator coefficient a of a continuous G = (a s^m + N'(s)) / D(s) of relative
    degree 1, and G' = N'(s) / D(s), of relative degree 2 (``num`` and ``den`` lists).

    A force-to-position mechanics has relative degree 2, but the ZOH equivalent of a discrete G
    fitted to a record with a force the model lacks can carry a zero in or near the band (on the
    tests' end-stop record a 2/2 fit's equivalent is (6.2 s + 7128) / D, a zero at 182 Hz).
    Around G(z) itself the force is held over whole samples and the velocity is a backward
    difference: the end-stop feedback stopped 34 dB above the noise floor. For a second-order D,
    b / D with b the constant term is G's least-squares projection on {c / D} over any set of
    frequencies, as a j w / D(j w) is in quadrature with 1 / D(j w) at every w; the refinement of
    the linear part's coefficients then takes the rest (there: 0.8 dB above the floor, as from
    a continuous fit)."""
    num = np.trim_zeros(np.asarray(linear["num"], float), "f")
    return float(num[0]), {"num": [float(v) for v in num[1:]], "den": [float(v) for v in linear["den"]]}


def estimate(ctx: Context, laws: list[Callable[[np.ndarray], np.ndarray]], names: list[str],
             valid: Callable[[Estimate], str | None]) -> Estimate | str:
    """Start values of the forces sum_i theta_i law_i(v): the residual regressed on the model's
    responses to the input errors -law_i(v) and -v (a linear damper d), v along the nominal
    trajectory of the model's reading (:func:`reading`, a discrete G of relative degree 1 read as
    the position with its leading term dropped, :func:`degree_two`); not fitted where the estimate
    is not ``valid`` (the reason: e.g. a negative friction level). The linear part starts at
    G / (1 + d s G) (:func:`with_spring`; G itself where d would change a sign, or G is discrete).
    The estimate's ``lti`` is that linear part with the reading's ``output`` (consumed by
    :func:`extender`).

    Why the damper: a G fitted to the data is the loop's BLA G_0 / (1 + c_e s G_0), c_e the
    force's equivalent damper at the record's velocities (Bussgang: sqrt(2 / pi) fc / sigma_v for
    Coulomb friction of a Gaussian velocity; a force of v alone has no equivalent spring on a
    symmetric motion), so the residual is the force less its linear part, which correlates with
    sign(v) less than the force does, or negatively (docs/feedback_start.md): regressed on
    sign(v) alone, a Coulomb record's G(z) fitted to its BLA gave a negative friction level and was
    not fitted; with d, d = -c_e takes the equivalent damper out of G."""
    found = reading(ctx, accelerates=True)
    if isinstance(found, str):
        return found
    chosen, notes = found
    columns = [ctx.response([-law(v) for v in chosen.velocity], "process") for law in laws]
    damped = chosen.linear.get("domain") != "discrete"
    if damped:
        columns.append(ctx.response([-v for v in chosen.velocity], "process"))
    est = regress(ctx.target(), columns, [*names, "d"] if damped else names)
    reason = valid(est)
    if reason is not None:
        return reason
    linear = chosen.linear
    if damped:
        moved = with_spring(linear, 0.0, est.values["d"])
        if moved is not None:
            linear = moved
            notes = [f"the linear part started at G / (1 + d s G), d = {est.values['d']:.4g} (a linear damper "
                     "regressed with the force: a G fitted to the data holds the force's equivalent damper)", *notes]
    values = {k: v for k, v in est.values.items() if k != "d"}
    std = {k: v for k, v in est.std.items() if k != "d"}
    coefficients = {name: float(linear[name[:3]][int(name[4:-1])]) for name in paths(())({"model": linear})}
    note = f"the model's output read as the {chosen.output}"
    return Estimate({**values, **coefficients}, {**std, **{k: math.nan for k in coefficients}},
                    est.explained_db, "; ".join([note, *notes]),
                    lti={"type": "transfer_function", **linear, "output": chosen.output})


def positions(ctx: Context, chosen: Reading) -> list[np.ndarray] | str:
    """The position of every run along the nominal trajectory of a ``position`` reading (the output
    of its linear part, without the model's output offset or block), or why there is none (a
    velocity reading: its position, the integral, has no origin the model fixes)."""
    if chosen.output != "position":
        return "needs the model's output read as a position (it has a zero at s = 0: a velocity)"
    return _probe(ctx, chosen.linear)


def stiffened(linear: dict, c: float) -> np.ndarray:
    """The denominator of G / (1 + c G) for a transfer function config ``linear``, den + c num
    aligned by its domain (powers of s from the right, of z^-1 from the left): y = G (u - c y - F)
    is y = G / (1 + c G) (u - F), a linear spring c moved into the linear part."""
    num, den = np.asarray(linear["num"], float), np.asarray(linear["den"], float)
    if linear.get("domain") == "discrete":
        return den + c * np.pad(num, (0, max(den.size - num.size, 0)))[:den.size]
    return den + c * np.pad(num, (max(den.size - num.size, 0), 0))[-den.size:]


def with_spring(lti: dict, c: float, d: float) -> dict | None:
    """``lti`` with the denominator of G / (1 + (c + d s) G): y = G (u - c y - d y' - F) is
    y = G / (1 + (c + d s) G) (u - F), a linear spring c and damper d moved into the linear part
    (:func:`stiffened`; a discrete G takes c alone: its s is no polynomial in z^-1). None where that
    changes the sign of a denominator coefficient (a change of structure, not a start)."""
    den = np.asarray(lti["den"], float)
    moved = stiffened(lti, c)
    if lti.get("domain") != "discrete":
        moved = moved + stiffened({**lti, "num": [*lti["num"], 0.0]}, d) - den
    return {**lti, "den": [float(v) for v in moved]} if np.all(np.sign(moved) == np.sign(den)) else None


def internal(ctx: Context, extended: dict) -> list[dict[str, np.ndarray]] | str:
    """The position and velocity of the moving part of the ``nonlinear_feedback`` model
    ``extended`` on every estimation run (open loop: copies of it that output them, from rest,
    without output block), or why there are none."""
    from nlsid.errors import InputError

    out = [{} for _ in ctx.runs]
    for signal in ("position", "velocity"):
        data = copy.deepcopy(extended)
        data["model"]["output"] = signal
        data["model"].pop("output_nonlinearity", None)
        try:
            runner = ctx.runner.with_changes(data)
        except InputError as exc:
            return f"the model has no {signal} read-out: {exc.what}"
        for signals, run in zip(out, ctx.runs):
            signals[signal] = runner.simulate(dataclasses.replace(run, y=None)).y
    return out


@dataclass(frozen=True)
class Fitted:
    """A fitted feedback hypothesis as a richer one starts from it: its linear part (an ``lti`` for
    :class:`~nlsid.diagnose.hypotheses.base.Estimate`, with the reading's ``output``), those
    coefficients by parameter name (``num[i]``, ``den[i]``: :func:`paths`), its force and the
    nuisances it was refined with (model key -> value), and its extended config."""

    lti: dict
    coefficients: dict[str, float]
    force: dict
    nuisances: dict[str, float]
    extended: dict


def fitted(ctx: Context, name: str) -> Fitted | None:
    """The fit of the feedback hypothesis ``name`` (its extended config, one force), None where it
    was not fitted."""
    from nlsid.diagnose.nuisances import KEYS as NUISANCE_KEYS

    extended = ctx.extended.get(name)
    if extended is None:
        return None
    model = extended["model"]
    linear = model["linear"]
    lti = {"type": "transfer_function", "num": [float(c) for c in linear["num"]],
           "den": [float(c) for c in linear["den"]], "domain": linear.get("domain", "continuous"),
           "output": model.get("output", "position")}
    coefficients = {n: float(lti[n[:3]][int(n[4:-1])]) for n in paths(())({"model": lti})}
    nuisances = {k: float(model[k]) for k in NUISANCE_KEYS if k in model}
    return Fitted(lti, coefficients, dict(model["nonlinearities"][-1]), nuisances, extended)


def extender(force: dict, names: tuple[str, ...], keys: dict[str, str] | None = None
             ) -> Callable[[dict, dict], dict]:
    """The extension: the model (its LTI part as the estimate's ``lti`` left it, with the reading's
    ``output``) as the linear part of a ``nonlinear_feedback`` with the force ``force``, its
    parameters ``names`` (those of them in the values) written at their ``keys`` (parameter ->
    the force's key; default the name itself)."""
    keys = keys or {}

    def extend(data: dict, values: dict) -> dict:
        out = copy.deepcopy(data)
        model = out["model"]
        linear = {"type": "transfer_function", "domain": model.get("domain", "continuous"),
                  **{key: [float(values.get(f"{key}[{i}]", v)) for i, v in enumerate(model[key])]
                     for key in ("num", "den")}}
        out["model"] = {"type": "nonlinear_feedback", "linear": linear, "gain": 1.0,
                        "output": model.get("output", "position"),
                        "nonlinearities": [{**force, **{keys.get(n, n): float(values[n]) for n in names
                                                         if n in values}}],
                        **{k: model[k] for k in KEPT if k in model}}
        return out
    return extend


def paths(names: tuple[str, ...], keys: dict[str, str] | None = None) -> Callable[[dict], dict[str, str]]:
    """The force's ``names`` (at their ``keys``, as :func:`extender`) and the linear part's nonzero
    coefficients (but den[0])."""
    keys = keys or {}

    def of(data: dict) -> dict[str, str]:
        model = data["model"]
        out = {n: f"model.nonlinearities[0].{keys.get(n, n)}" for n in names}
        out.update({f"num[{i}]": f"model.linear.num[{i}]" for i, c in enumerate(model["num"]) if c != 0})
        out.update({f"den[{i}]": f"model.linear.den[{i}]" for i, c in enumerate(model["den"]) if i and c != 0})
        return out
    return of
