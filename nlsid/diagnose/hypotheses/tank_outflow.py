"""Square-root outflow: a linear model of one tank, or of two cascaded tanks, turned into the
tanks' equations (Torricelli's law), started from the linearisation the linear model is.

A tank drained through an orifice loses water at a rate proportional to the square root of its
level (Torricelli: v = sqrt(2 g h)). Two tanks in cascade, the upper one filled by a pump driven by
u, the lower one by the upper one's outflow, its level x2 measured:

    dx1/dt = -k1 sqrt(x1) + k4 u,
    dx2/dt =  k2 sqrt(x1) - k3 sqrt(x2),         y = x2 + c,

(k1 = a1 sqrt(2 g) / A1 and k2 = a1 sqrt(2 g) / A2 for an outlet of area a1 between tanks of
cross-sections A1 and A2), written as an ``equations`` model (``docs/configs.md``). One tank is the
first line alone, y = x1 + c.

*Linearisation.* At a constant input u0 the levels settle where inflow equals outflow:
sqrt(x1*) = k4 u0 / k1 and k2 sqrt(x1*) = k3 sqrt(x2*). Around them, with d/dx sqrt(x) =
1 / (2 sqrt(x)), the small deviations obey

    d(dx1)/dt = -p1 dx1 + k4 du,                 p1 = k1 / (2 sqrt(x1*)),
    d(dx2)/dt = k2 / (2 sqrt(x1*)) dx1 - p2 dx2,  p2 = k3 / (2 sqrt(x2*)),

so the linear model from u to y is

    G(s) = k4 k2 / (2 sqrt(x1*)) / ((s + p1) (s + p2)),   G(0) = 2 x2* / u0,

two real poles (a first-order lag, G(0) = k4 / p1 = 2 x1* / u0, for one tank). The static gain is
twice the secant x2* / u0 (the level grows as u0^2); so a fitted linear model and the mean input
u0 give the operating level, x2* = u0 G(0) / 2, and with it the rates:

    one tank:   x* = u0 G(0) / 2,  k1 = 2 p sqrt(x*),  k4 = p G(0);
    two tanks:  x2* = u0 G(0) / 2, k3 = 2 p2 sqrt(x2*), k1 = k2 = 2 sqrt(p1 p2 x2*),
                k4 = 2 p2 x2* / u0,  x1* = p2 x2* / p1.

The level of the upper tank is not seen: x1 -> c x1 with k1 -> k1 sqrt(c), k2 -> k2 / sqrt(c),
k4 -> c k4 gives the same output for every c > 0 (the combinations k3, k1 k2 and k1^2 / k4 are
what the output determines; the last two are 4 p1 p2 x2* and 2 p1 u0 at the start). The
extension fixes that scale by equal cross-sections, k2 = k1 (all of the upper tank's outflow
raises the lower level at the rate it lowers its own; tanks of other cross-sections read with an
upper level c = k2 / k1 times theirs), which leaves three rates, k1, k3 and k4,
each determined by the data. Which of the linear model's two poles belongs to the upper tank the
linear model cannot say (G is symmetric in p1 and p2) but the square roots can: from each
assignment's start (the output offset c the mean of the measured output less the simulated one)
the tanks are pre-fitted briefly (:func:`prefit`) and the one of lower simulation error kept.

The start uses the linear model's poles (a discrete model's as s = fs ln z) and its static gain
(G(1) of a discrete model), not its zeros (the tanks have none: a fitted zero is the fit's); u0 is
the mean plant input (the recorded u, the model's input offset and input channels) of the
estimation runs' steady state, and the level u0 G(0) / 2 must be positive and at least
LEVEL_SWINGS standard deviations of the recorded output (an excitation around a level above the
outlet, not a zero-mean one around a linear model's origin). Dead time,
input offset and channels and the input block of the linear model are kept, and an output
saturation (a sensor range found in an earlier round) with its recorded limits (limit + output
offset) where they were; another output block does not carry over to the level's scale (the
family does not apply then). The fit engine then refines k1, k3, k4 with the output offset (``refine`` of
:mod:`nlsid.diagnose.diagnosis`); the states start at the start's operating levels, which the
runs' transient periods let the model leave for its own (an ``equations`` model has no lead-in).

Signature: even distortion (sqrt is not odd about the operating point); a BLA whose gain and time
constants change with the operating level (p = k / (2 sqrt(x*)): a higher level, a slower tank).
"""

from __future__ import annotations

import copy
import math
from typing import Callable

import numpy as np

from nlsid.diagnose.hypotheses import filter_split as fsplit
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db
from nlsid.diagnose.hypotheses.wiener_hammerstein import plant_input
from nlsid.diagnose.simulation import LTI, ModelRunner, steady_mean

PREFIT_STEPS = 12   # residual evaluations of a pre-fit (prefit), besides its Jacobians'
LEVEL_SWINGS = 1.0  # the operating level at least this many standard deviations of the recorded output
KEPT = ("input_offset", "input_channels", "delay", "input_nonlinearity")
PARAMETER = "parameter "  # the prefix of an equations parameter's name in a diagnosis (mechanics.linear_paths)
EQUATION_PARAMETERS = ("k1", "k3", "k4", "x1max", "frac")  # the tanks' parameters, of both members


def named(values: dict) -> dict:
    """``values`` with the equations' parameters (the rates, a rim) named as the diagnosis names the
    parameters of an equations model it refines (``parameter k1``), the other values as they are."""
    return {(PARAMETER + k if k in EQUATION_PARAMETERS else k): v for k, v in values.items()}


def plain(values: dict) -> dict:
    """The inverse of :func:`named`: ``parameter k1`` -> ``k1``."""
    return {k.removeprefix(PARAMETER): v for k, v in values.items()}


def linear_poles(model: dict, fs: float) -> np.ndarray:
    """The continuous poles of an LTI model config (a discrete pole z as fs ln z; poles at the
    origin of a discrete model, its whole-sample delays, left out)."""
    _, den = fsplit.polynomials(model)
    poles = np.roots(np.trim_zeros(den, "f"))
    if model.get("domain") == "discrete":
        poles = poles[poles != 0]
        return fs * np.log(poles.astype(complex))
    return poles.astype(complex)


def static_gain(model: dict) -> float:
    """G(0) of a continuous LTI model config, G(1) of a discrete one (NaN with an integrator)."""
    num, den = fsplit.polynomials(model)
    n, d = (float(np.sum(num)), float(np.sum(den))) if model.get("domain") == "discrete" else (num[-1], den[-1])
    return n / d if d != 0 else math.nan


def _real_stable(poles: np.ndarray) -> bool:
    return bool(np.all(np.abs(poles.imag) <= 1e-9 * np.maximum(np.abs(poles), 1e-300)) and np.all(poles.real < 0))


def applies_to(order: int) -> Callable[[ModelRunner], str | None]:
    """Whether the tanks of ``order`` (1 or 2) can be read from the runner's model (module docstring)."""
    def applies(runner: ModelRunner) -> str | None:
        if runner.kind not in LTI:
            return "needs an LTI model (transfer_function, zpk or state_space) to linearise"
        if runner.closed:
            return "a model written as equations runs in open loop only"
        poles = linear_poles(runner.data["model"], 1.0)  # the rate scales every pole alike
        if poles.size != order:
            return f"needs a linear model with {order} pole{'s' if order > 1 else ''} (it has {poles.size})"
        if not _real_stable(poles):
            return "tanks in cascade have real stable poles (the linear model's are not)"
        if not math.isfinite(static_gain(runner.data["model"])):
            return "the linear model has no static gain (an integrator)"
        block = runner.data["model"].get("output_nonlinearity")
        if block is not None and block.get("type") != "saturation":
            return (f"the linear model's output block ({block.get('type')}) acts on its own output scale, which "
                    "the tank's level does not share (a sensor range, saturation, is carried over)")
        return None
    return applies


def operating_input(ctx: Context) -> float:
    """u0: the mean plant input over the steady state of the estimation runs."""
    model = ctx.runner.data["model"]
    return float(np.mean(np.concatenate([steady_mean(run, plant_input(model, run)) for run in ctx.runs])))


def start_values(poles: tuple[float, ...], gain: float, u0: float) -> dict[str, float]:
    """The rates and operating levels of the module docstring's map: ``poles`` the rates p (> 0;
    one, or the upper tank's then the lower's), ``gain`` G(0), ``u0`` the mean input."""
    level = u0 * gain / 2
    if len(poles) == 1:
        (p,) = poles
        return {"k1": 2 * p * math.sqrt(level), "k4": p * gain, "level": level}
    p1, p2 = poles
    return {"k1": 2 * math.sqrt(p1 * p2 * level), "k3": 2 * p2 * math.sqrt(level), "k4": 2 * p2 * level / u0,
            "level_upper": p2 * level / p1, "level": level}


def equations(values: dict) -> dict:
    """The equations model's own keys (type, states, parameters, derivatives, bounds, output) of
    the rates and levels in ``values`` (:func:`start_values`): one tank where there is no ``k3``."""
    if "k3" not in values:
        return {"type": "equations", "states": {"x": float(values["level"])},
                "parameters": {"k1": float(values["k1"]), "k4": float(values["k4"])},
                "derivatives": {"x": "-k1*sqrt(x) + k4*u"}, "bounds": {"x": [0.0, None]}, "output": "x"}
    return {"type": "equations", "states": {"x1": float(values["level_upper"]), "x2": float(values["level"])},
            "parameters": {k: float(values[k]) for k in ("k1", "k3", "k4")},
            "derivatives": {"x1": "-k1*sqrt(x1) + k4*u", "x2": "k1*sqrt(x1) - k3*sqrt(x2)"},
            "bounds": {"x1": [0.0, None], "x2": [0.0, None]}, "output": "x2"}


def sensor_range(model: dict, offset: float) -> dict | None:
    """The linear model's output saturation (a sensor range) for a model of output offset
    ``offset``: the block acts before the offset, so its limits move by the change of the offset,
    keeping the recorded range (limit + offset) where it was; None without a block."""
    block = model.get("output_nonlinearity")
    if block is None:
        return None
    shift = offset - float(model.get("output_offset", 0.0))
    return {**block, "lower": float(block["lower"]) - shift, "upper": float(block["upper"]) - shift}


def extension(build: Callable[[dict], dict]) -> Callable[[dict, dict], dict]:
    """The extension (data, values) -> config of the tanks that ``build`` writes of the values
    (:func:`equations`): the linear model replaced by them, its dead time, input offset and
    channels and input block kept, the output offset ``values['output_offset']`` and the sensor
    range at the recorded values (:func:`sensor_range`)."""
    def extend(data: dict, values: dict) -> dict:
        out = copy.deepcopy(data)
        model = out["model"]
        offset = float(values["output_offset"])
        block = sensor_range(model, offset)
        out["model"] = {**build(values), **{k: model[k] for k in KEPT if model.get(k) is not None},
                        **({"output_nonlinearity": block} if block is not None else {}), "output_offset": offset}
        return out
    return extend


extend = extension(equations)


def simulated(ctx: Context, values: dict, extended: Callable[[dict, dict], dict] = extend) -> np.ndarray:
    """The mean steady-state periods of the estimation runs simulated by the tanks of ``values``
    (written by ``extended``, :func:`extension`)."""
    runner = ctx.runner.with_changes(extended(ctx.runner.data, values))
    return np.concatenate([steady_mean(run, s) for run, s in zip(ctx.runs, runner.simulate_each(ctx.runs))])


def prefit(ctx: Context, poles: tuple[float, ...], gain: float, u0: float, y: np.ndarray,
           extra: dict[str, float] | None = None, extended: Callable[[dict, dict], dict] = extend
           ) -> tuple[dict, float, int]:
    """The map's start for the pole assignment ``poles`` (:func:`start_values`; with the further
    positive parameters ``extra`` of a richer member, written by ``extended``), its output offset
    the mean of the measured less the simulated output, then fitted to the measured steady state
    ``y`` in the coordinates v = (ln p.., ln x*, ln extra.., c) by a trust-region least-squares
    search of PREFIT_STEPS residual evaluations besides its Jacobians' (scipy's ``trf``). In
    these the model is nearly linear where the rates are not: a level traded against the output
    offset is the straight valley x* + c = constant, in the rates a curved one (k4 / k3 fixed
    with k3^2 / k4), which the fit engine, moving the rates, crossed slowly (on 14 % of clipped
    samples it stopped at its budget, 6 dB above the noise floor, from a start 20 % off). Returns
    the values, the residual sum of squares and the simulations run; an infinite sum where the
    start does not run."""
    from scipy.optimize import least_squares

    from nlsid.errors import InputError

    extra = extra or {}
    n = len(poles)

    def unpack(v: np.ndarray) -> dict:
        rates, level = tuple(float(r) for r in np.exp(v[:n])), float(np.exp(v[n]))
        more = {k: float(x) for k, x in zip(extra, np.exp(v[n + 1:-1]))}
        return {**start_values(rates, 2 * level / u0, u0), **more, "u0": u0, "output_offset": float(v[-1])}

    start = {**start_values(poles, gain, u0), **extra, "u0": u0, "output_offset": 0.0}
    try:
        offset = float(np.mean(y - simulated(ctx, start, extended)))
    except InputError:
        return start, math.inf, 1
    penalty = np.full(y.size, 10 * float(np.sqrt(np.mean(y**2))))
    count = [1]

    def residual(v: np.ndarray) -> np.ndarray:
        count[0] += 1
        try:
            e = simulated(ctx, unpack(v), extended) - y
        except InputError:  # a trial the equations cannot run
            return penalty
        return e if np.all(np.isfinite(e)) else penalty

    v0 = np.array([*np.log(poles), math.log(start["level"]), *np.log(list(extra.values())), offset])
    fit = least_squares(residual, v0, method="trf", x_scale="jac", max_nfev=PREFIT_STEPS)
    return unpack(fit.x), float(2 * fit.cost), count[0]


def operating_point(ctx: Context) -> tuple[list[float], float, float, np.ndarray] | str:
    """The linear model's pole rates (ascending), static gain G(0), the mean plant input u0 and
    the measured steady state y of the estimation runs; or why the tanks cannot be read from them
    (a dead time of a fraction of a sample, a level u0 G(0) / 2 <= 0 or below LEVEL_SWINGS
    standard deviations of y)."""
    from nlsid.errors import InputError
    from nlsid.models.lti import delay_samples

    model = ctx.runner.data["model"]
    try:
        for run in ctx.runs:
            delay_samples(float(model.get("delay", 0.0)), run.fs, "model.delay")
    except InputError:
        return (f"the model's dead time ({float(model['delay']):g} s) is not a whole number of samples, which "
                "a model written as equations needs (fit the dead time first)")
    rates = sorted(float(-p.real) for p in linear_poles(model, ctx.runs[0].fs))
    gain, u0 = static_gain(model), operating_input(ctx)
    if not u0 * gain > 0:
        return (f"the mean plant input u0 = {u0:.4g} and the linear model's static gain {gain:.4g} give an "
                "operating level u0 G(0) / 2 <= 0: no level above an outlet (a model of detrended data, "
                "input_offset = -mean(u), has no operating point)")
    y = np.concatenate([steady_mean(run, run.y) for run in ctx.runs])
    swing = float(np.std(y))
    if u0 * gain / 2 < LEVEL_SWINGS * swing:
        return (f"the operating level u0 G(0) / 2 = {u0 * gain / 2:.4g} (u0 = {u0:.4g}, the mean plant input) is "
                f"below {LEVEL_SWINGS:g} standard deviation of the recorded output ({swing:.4g}): the "
                "excitation is not around a level above an outlet")
    return rates, gain, u0, y


def pole_note(values: dict) -> str:
    """The two tanks' poles of ``values`` at its mean input, in words."""
    u0 = values["u0"]
    return (f"the upper tank's pole {values['k1'] ** 2 / (2 * values['k4'] * u0):.3g} 1/s, the lower's "
            f"{values['k3'] ** 2 / (2 * values['k4'] * u0):.3g} (the better of the two assignments)")


def _estimate(order: int):
    def estimate(ctx: Context) -> Estimate | str:
        """The start of the module docstring's map, pre-fitted from each pole assignment
        (:func:`prefit`); the one of lower simulation error."""
        point = operating_point(ctx)
        if isinstance(point, str):
            return point
        rates, gain, u0, y = point
        assignments = [tuple(rates)] if order == 1 else [tuple(reversed(rates)), tuple(rates)]
        fits = [prefit(ctx, poles, gain, u0, y) for poles in assignments]
        values, rss, _ = min(fits, key=lambda f: f[1])
        if not math.isfinite(rss):
            return "the start does not run (a level leaves its bounds or a value is not finite)"
        before = float(np.sum(ctx.target() ** 2))
        note = (f"linearisation of sqrt outflow at the mean input u0 = {u0:.4g}: operating level u0 G(0) / 2 = "
                f"{u0 * gain / 2:.4g}, pre-fitted ({sum(f[2] for f in fits)} simulations) to {values['level']:.4g}"
                + ("" if order == 1 else f"; {pole_note(values)}"))
        paths = {PARAMETER + k: f"model.parameters.{k}" for k in ("k1", "k3", "k4") if k in values}
        return Estimate(named(values), {k: float("nan") for k in named(values)}, explained_db(before, rss), note,
                        paths=paths)
    return estimate


def derive(fitted: dict, starts: dict, model: dict) -> dict[str, float]:
    """The operating levels of the fitted rates at the start's mean input u0: x* = (k4 u0 / k1)^2
    of one tank; x1* = (k4 u0 / k1)^2 and x2* = (k4 u0 / k3)^2 of two (k2 = k1)."""
    fitted = plain(fitted)
    u0 = fitted["u0"]
    if "k3" not in fitted:
        return {"level": (fitted["k4"] * u0 / fitted["k1"]) ** 2}
    return {"level_upper": (fitted["k4"] * u0 / fitted["k1"]) ** 2, "level": (fitted["k4"] * u0 / fitted["k3"]) ** 2}


def extend_named(data: dict, values: dict) -> dict:
    """:func:`extend` of the values as the diagnosis names them (:func:`named`)."""
    return extend(data, plain(values))


def _reading(values: dict) -> str:
    values = plain(values)
    if "k3" not in values:
        return (f"one tank: outflow k1 = {values['k1']:.4g}, inflow k4 = {values['k4']:.4g} per unit input; level "
                f"{values['level']:.4g} at the mean input")
    return (f"two tanks (equal cross-sections, k2 = k1): outflows k1 = {values['k1']:.4g}, k3 = {values['k3']:.4g}, "
            f"inflow k4 = {values['k4']:.4g} per unit input; levels {values['level_upper']:.4g} (upper) and "
            f"{values['level']:.4g} (measured) at the mean input")


SIGNATURE = ("even distortion; the BLA's gain and time constants change with the operating level (a higher "
             "level, a slower tank)")
UNIT = "output units (the measured tank's level above its outlet at the mean input)"

HYPOTHESES = (
    Hypothesis("tank_outflow", "Square-root outflow (one tank)", "structure", "level", UNIT, SIGNATURE,
               applies_to(1), _estimate(1), extend_named, ("parameter k1", "parameter k4"), reading=_reading,
               derive=derive),
    Hypothesis("cascaded_tanks", "Square-root outflow (two cascaded tanks)", "structure", "level", UNIT, SIGNATURE,
               applies_to(2), _estimate(2), extend_named, ("parameter k1", "parameter k3", "parameter k4"),
               reading=_reading, derive=derive),
)
