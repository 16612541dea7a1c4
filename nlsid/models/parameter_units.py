"""The physical unit of a model parameter, from the recording's units and the model's structure.

A number of a model config (named by its dotted key path, :mod:`nlsid.models.key_paths`) has a
unit fixed by the equation it enters and the units of the signals it links. With the units of
the recorded input u and output y (``Run.units``), dimensional analysis gives each one:

- the force F on a mechanical model. ``m p'' + c p' + k p = gain u - F`` is in the units of
  ``gain u``. Where u is a force or a torque (N, kN, lbf, N m, ...), ``gain`` is a pure number
  and F is in u's unit; where ``gain`` is exactly 1 (the default, and what a diagnosis of a
  transfer function puts around it), F is in u's unit whatever u is (a motor command in V gives
  forces "in V": the force that 1 V of command makes). Any other gain on a u that is not a force
  leaves F unknown: its unit is whatever the user meant the gain to carry (N/V, say), and no
  parameter that holds a force gets a unit;
- the position X of a mechanical model: y's unit for ``output: position``, y's unit times s for
  ``output: velocity`` (``m/s`` gives ``m``); then ``mass`` = F s^2/X (kg for N and m),
  ``damping`` = F s/X, ``stiffness`` = F/X, a cubic spring's ``k3`` = F/X^3, Coulomb ``fc`` = F,
  a Stribeck ``vs`` = X/s, ``force_offset`` = F, ``initial.velocity`` = X/s;
- a block that maps a signal to itself (a saturation, a deadzone, a backlash; a polynomial whose
  linear coefficient is exactly 1) keeps its unit: the plant's input is then in u's unit and its
  output in y's; a polynomial's coefficient ``a_p`` is in ``unit_out / unit_in^p``. A polynomial
  with another linear coefficient, or a piecewise-linear map, leaves the signal behind it without
  a unit (its scale is the user's choice);
- ``input_offset`` in u's unit, ``output_offset`` in y's, ``delay`` in s, ``fs`` in Hz,
  ``output_timing`` and ``closed_loop.computation_delay`` in samples, a channel's gain in u's unit
  per the channel's;
- an LTI model's coefficients depend on its realization (num, den, A, B, C are scaled against each
  other at will) and get none; the keys with a definite unit are a zpk's ``gain``, in
  ``y/u s^(n_zeros - n_poles)`` for a continuous one (each plain root factor ``s - r`` is in 1/s, a
  mode factor ``(s^2 + 2 zeta w s + w^2)/w^2`` is a pure number: with only modes the gain is the
  static gain ``y/u``), ``y/u`` for a discrete one; a state space's ``D`` (y/u); a continuous
  root in 1/s, a mode's ``frequency`` in Hz;
- a controller on the error ``e = r - y`` (in y's unit) to the command u: a PID's ``kp`` in
  ``u/y``, ``ki`` in ``u/(y s)``, ``kd`` in ``u s/y``, ``tau`` in s; in a cascade the position
  loop's output is a velocity (y/s); ``feedforward.coulomb`` in u's unit, ``feedforward.velocity``
  in ``u s/y``.

Where a signal's unit is not recorded, or a key is not one of those above (an equations model's
parameters, a PNLSS model's coefficients, a block structure's filters), the unit is unknown:
:func:`unit_of` gives None, and nothing is printed rather than a guess. A pure number (a Stribeck
exponent ``delta``, a gain of N per N) is the empty string.

Examples
--------
>>> data = {"model": {"type": "mass_spring_damper", "mass": 2.0, "stiffness": 2000.0,
...                   "nonlinearities": [{"type": "cubic_stiffness", "k3": 2e8}]}}
>>> unit_of(data, "model.nonlinearities[0].k3", {"u": "N", "y": "m"})
'N/m^3'
>>> unit_of(data, "model.mass", {"u": "N", "y": "m"})
'kg'
>>> unit_of(data, "model.mass", {"u": "N", "y": "mm"})
'N s^2/mm'
>>> unit_of(data, "model.stiffness", {"u": "N"}) is None  # y's unit not recorded
True
"""

from __future__ import annotations

import re
from typing import Mapping

from nlsid.models.key_paths import key_text, parse

Unit = dict  # symbol -> integer exponent, in the order the symbols first appear; {} a pure number

#: Units of a force or a torque: an actuator command in one of these makes ``gain`` a pure number.
FORCES = ("N", "kN", "mN", "uN", "µN", "MN", "lbf", "kgf", "dyn", "ozf")
LENGTHS = ("m", "mm", "cm", "um", "µm", "km", "in", "ft")
SECOND = {"s": 1}
PURE: Unit = {}
KILOGRAM = {"N": 1, "s": 2, "m": -1}
MASSES = ("mass", "motor_mass", "load_mass")

_TOKEN = re.compile(r"([A-Za-zµΩ°%][A-Za-zµΩ°%_]*)(?:\^(-?\d+))?")
MECHANICAL = ("mass_spring_damper", "two_mass_stage", "nonlinear_feedback")
LTI = ("transfer_function", "zpk", "state_space")


def parse_unit(text: str | None) -> Unit | None:
    """A unit text as symbols with exponents: ``"N s/m"`` -> ``{N: 1, s: 1, m: -1}``,
    ``"m/s^2"`` -> ``{m: 1, s: -2}``, ``"m/(N s)"`` -> ``{m: 1, N: -1, s: -1}``. A text of another
    form (``"°C"``, ``"counts"``) is one symbol of its own; None or "" (not recorded) gives None."""
    if not isinstance(text, str) or not text.strip():
        return None
    text = text.strip()
    out: Unit = {}
    for i, part in enumerate(text.split("/")):
        part = part.strip()
        if part.startswith("(") and part.endswith(")"):
            part = part[1:-1]
        sign = 1 if i == 0 else -1
        tokens = [t for t in re.split(r"[\s*·]+", part) if t]
        if i == 0 and tokens == ["1"]:
            continue
        matches = [_TOKEN.fullmatch(t) for t in tokens]
        if not tokens or not all(matches):
            return {text: 1}
        for m in matches:
            _add(out, {m.group(1): sign * int(m.group(2) or 1)})
    return out


def _add(total: Unit, other: Unit, times: int = 1) -> Unit:
    for symbol, power in other.items():
        total[symbol] = total.get(symbol, 0) + times * power
        if total[symbol] == 0:
            del total[symbol]
    return total


def product(*factors: tuple[Unit | None, int]) -> Unit | None:
    """``prod(unit^power)`` of ``(unit, power)`` pairs; None when a unit with a nonzero power is unknown."""
    out: Unit = {}
    for unit, power in factors:
        if power == 0:
            continue
        if unit is None:
            return None
        _add(out, unit, power)
    return out


def unit_text(unit: Unit | None, mass: bool = False) -> str | None:
    """A unit as text: ``N s/m``, ``N/m^3``, ``m/(N s)``, ``1/s``; "" for a pure number, None for
    unknown. A ``mass`` in N s^2/m is written kg (a controller gain of the same dimension is not)."""
    if unit is None:
        return None
    if mass and unit == KILOGRAM:
        return "kg"

    def side(items: list) -> str:
        return " ".join(s if p == 1 else f"{s}^{p}" for s, p in items)

    top = side([(s, p) for s, p in unit.items() if p > 0])
    below = [(s, -p) for s, p in unit.items() if p < 0]
    if not below:
        return top
    bottom = side(below)
    return f"{top or '1'}/{f'({bottom})' if len(below) > 1 else bottom}"


def is_effort(unit: Unit | None) -> bool:
    """A force (N, lbf, ...) or a torque (a force times a length, N m): a command in it makes an
    actuator gain a pure number."""
    if unit is None:
        return False
    forces = [s for s in unit if s in FORCES]
    rest = {s: p for s, p in unit.items() if s not in FORCES}
    return (len(forces) == 1 and unit[forces[0]] == 1
            and (not rest or (len(rest) == 1 and next(iter(rest)) in LENGTHS and next(iter(rest.values())) == 1)))


def _number(value, default: float) -> float | None:
    if value is None:
        return default
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def keeps_unit(block: dict | None) -> bool:
    """Whether a plant's input or output block gives out the unit it takes (module docstring): no
    block, a saturation, deadzone or backlash, or a polynomial whose linear coefficient is exactly 1."""
    if not isinstance(block, dict):
        return True
    kind = block.get("type")
    if kind == "polynomial":
        coefficients = block.get("coefficients") or []
        return len(coefficients) > 1 and _number(coefficients[1], 0.0) == 1.0
    return kind in ("saturation", "deadzone", "backlash")


def _block_table(block, where: tuple, before: Unit | None, after: Unit | None, out: dict) -> None:
    """The units of a nonlinear block's keys, mapping ``before`` to ``after``."""
    if not isinstance(block, dict):
        return
    kind = block.get("type")
    if kind in ("saturation", "deadzone"):
        out[where + ("lower",)] = out[where + ("upper",)] = before
    elif kind == "backlash":
        out[where + ("width",)] = before
    elif kind == "piecewise_linear":
        for i in range(len(block.get("x") or [])):
            out[where + ("x", i)] = before
        for i in range(len(block.get("y") or [])):
            out[where + ("y", i)] = after
    elif kind == "polynomial":
        for p in range(len(block.get("coefficients") or [])):
            out[where + ("coefficients", p)] = product((after, 1), (before, -p))


def _force_table(item: dict, where: tuple, F: Unit | None, X: Unit | None, out: dict) -> None:
    """The units of a nonlinear force's keys (docs/configs.md, "Nonlinear forces")."""
    V = product((X, 1), (SECOND, -1))
    damping = product((F, 1), (V, -1))
    per_position = product((F, 1), (X, -1))
    kind = item.get("type")
    keys: dict[str, Unit | None] = {}
    if kind in ("coulomb", "stribeck", "lugre"):
        for name in ("fc", "fs"):
            keys.update({name: F, f"{name}_pos": F, f"{name}_neg": F})
        keys["peak"] = F
        for name in ("fv", "sigma2"):
            keys.update({name: damping, f"{name}_pos": damping, f"{name}_neg": damping})
        keys.update(vs=V, delta=PURE, sigma0=per_position, sigma1=damping)
    elif kind == "cubic_stiffness":
        keys["k3"] = product((F, 1), (X, -3))
    elif kind == "polynomial_stiffness":
        keys.update({f"k{n}": product((F, 1), (X, -n)) for n in range(2, 11)})
    elif kind == "quadratic_damping":
        keys["c2"] = product((F, 1), (V, -2))
    elif kind == "cubic_damping":
        keys["c3"] = product((F, 1), (V, -3))
    elif kind == "bouc_wen":
        n = _number(item.get("n"), 1.0)
        exponent = int(n) if n is not None and n == int(n) else None
        keys.update(k=per_position, A=PURE, n=PURE)
        keys["beta"] = keys["gamma"] = product((X, -exponent)) if exponent is not None else None
    elif kind == "end_stop":
        keys.update(upper=X, lower=X, stiffness=per_position, damping=damping)
    out.update({where + (name,): unit for name, unit in keys.items()})


def _channels_table(channels, where: tuple, target: Unit | None, units: Mapping[str, str], out: dict) -> None:
    """A channel entry's gain: the target signal's unit per the channel's."""
    if not isinstance(channels, dict):
        return
    for name, entry in channels.items():
        gain = product((target, 1), (parse_unit(units.get(name)), -1))
        out[where + (name,)] = gain
        out[where + (name, "gain")] = gain


def _lti_table(lti: dict, where: tuple, before: Unit | None, after: Unit | None, out: dict) -> None:
    """An LTI model's keys with a definite unit (module docstring)."""
    discrete = lti.get("domain") == "discrete"
    out[where + ("delay",)] = SECOND
    out[where + ("fs",)] = {"Hz": 1}
    kind = lti.get("type")
    if kind == "state_space":
        out[where + ("D",)] = product((after, 1), (before, -1))
    if kind != "zpk":
        return
    roots = {"zeros": 0, "poles": 0}
    for side in roots:
        for i, root in enumerate(lti.get(side) or []):
            if isinstance(root, dict):
                out[where + (side, i, "frequency")] = {"Hz": 1}
                out[where + (side, i, "damping")] = PURE
                continue
            rate = PURE if discrete else {"s": -1}
            if isinstance(root, list):
                roots[side] += 2  # a pair re +- j im: two factors
                out[where + (side, i, 0)] = out[where + (side, i, 1)] = rate
            else:
                roots[side] += 1
                out[where + (side, i)] = rate
    time = 0 if discrete else roots["zeros"] - roots["poles"]
    out[where + ("gain",)] = product((after, 1), (before, -1), (SECOND, time))


def _model_table(model: dict, units: Mapping[str, str], out: dict) -> None:
    U, Y = parse_unit(units.get("u")), parse_unit(units.get("y"))
    where = ("model",)
    kind = model.get("type")
    plant_in = U if keeps_unit(model.get("input_nonlinearity")) else None
    plant_out = Y if keeps_unit(model.get("output_nonlinearity")) else None
    _block_table(model.get("input_nonlinearity"), where + ("input_nonlinearity",), U, plant_in, out)
    _block_table(model.get("output_nonlinearity"), where + ("output_nonlinearity",), plant_out, Y, out)
    out[where + ("input_offset",)] = U
    out[where + ("output_offset",)] = Y
    out[where + ("delay",)] = SECOND
    out[where + ("fs",)] = {"Hz": 1}
    out[where + ("output_timing",)] = {"samples": 1}
    _channels_table(model.get("input_channels"), where + ("input_channels",), U, units, out)
    if kind in LTI:
        _lti_table(model, where, plant_in, plant_out, out)
    if kind not in MECHANICAL:
        return
    gain = _number(model.get("gain"), 1.0)
    F = plant_in if gain == 1.0 or (plant_in is not None and plant_in == U and is_effort(U)) else None
    X = plant_out if model.get("output", "position") == "position" else product((plant_out, 1), (SECOND, 1))
    mass, damping, stiffness = (product((F, 1), (SECOND, p), (X, -1)) for p in (2, 1, 0))
    out[where + ("gain",)] = product((F, 1), (plant_in, -1))
    out[where + ("force_offset",)] = F
    out[where + ("initial", "position")] = X
    out[where + ("initial", "velocity")] = product((X, 1), (SECOND, -1))
    for key in MASSES:
        out[where + (key,)] = mass
    for key in ("damping", "motor_damping", "load_damping"):
        out[where + (key,)] = damping
    out[where + ("stiffness",)] = stiffness
    for i, item in enumerate(model.get("nonlinearities") or []):
        if not isinstance(item, dict):
            continue
        # a force at a named point of a nonlinear_feedback (``points``: a modal coordinate, say)
        # reads a coordinate and enters along a column whose scales are the model's, not y's or u's
        elsewhere = kind == "nonlinear_feedback" and item.get("at", "plant") != "plant"
        _force_table(item, where + ("nonlinearities", i), None if elsewhere else F, None if elsewhere else X, out)
    if kind == "nonlinear_feedback" and isinstance(model.get("linear"), dict):
        out[where + ("linear", "fs")] = {"Hz": 1}


def _pid_table(controller: dict, where: tuple, error: Unit | None, command: Unit | None, out: dict) -> None:
    """A controller's keys: a PID from ``error`` to ``command``, a cascade's two loops."""
    kind = controller.get("type")
    if kind == "pid":
        gain = product((command, 1), (error, -1))
        out[where + ("kp",)] = gain
        out[where + ("ki",)] = product((gain, 1), (SECOND, -1))
        out[where + ("kd",)] = product((gain, 1), (SECOND, 1))
        out[where + ("tau",)] = SECOND
    elif kind == "cascade":
        velocity = product((error, 1), (SECOND, -1))
        if isinstance(controller.get("position"), dict):
            _pid_table(controller["position"], where + ("position",), error, velocity, out)
        if isinstance(controller.get("velocity"), dict):
            _pid_table(controller["velocity"], where + ("velocity",), velocity, command, out)


def _loop_table(loop: dict, units: Mapping[str, str], out: dict) -> None:
    U, Y = parse_unit(units.get("u")), parse_unit(units.get("y"))
    where = ("closed_loop",)
    if isinstance(loop.get("controller"), dict):
        _pid_table(loop["controller"], where + ("controller",), Y, U, out)
    if isinstance(loop.get("measurement"), dict):
        _pid_table(loop["measurement"], where + ("measurement",), Y, U, out)
    out[where + ("computation_delay",)] = {"samples": 1}
    out[where + ("feedforward", "coulomb")] = U
    out[where + ("feedforward", "velocity")] = product((U, 1), (Y, -1), (SECOND, 1))
    _channels_table(loop.get("excitation_channels"), where + ("excitation_channels",), U, units, out)


def unit_table(data: dict, units: Mapping[str, str]) -> dict[str, str | None]:
    """The unit of every key of the config ``data`` that has one (dotted key path -> unit text,
    :func:`unit_text`; None where a signal's unit it needs is not recorded), given the recording's
    ``units`` (signal or channel name -> unit, as ``Run.units``). A force's keys are listed whether
    or not the config writes them (``fs`` of a Stribeck law given as ``peak``)."""
    out: dict = {}
    model = data.get("model") if isinstance(data, dict) else None
    if isinstance(model, dict):
        _model_table(model, units or {}, out)
    loop = data.get("closed_loop") if isinstance(data, dict) else None
    if isinstance(loop, dict):
        _loop_table(loop, units or {}, out)
    return {key_text(keys): unit_text(unit, keys[-1] in MASSES) for keys, unit in out.items()}


def unit_of(data: dict, path: str, units: Mapping[str, str]) -> str | None:
    """The unit of the number at ``path`` in the config ``data`` (``model.nonlinearities[0].k3``),
    given the recording's ``units``: a unit text, "" for a pure number, None when it is unknown
    (a unit not recorded, or a key whose unit the model's structure does not fix)."""
    keys = parse(path)
    if keys is None:
        return None
    return unit_table(data, units).get(key_text(keys))


def with_unit(text: str, unit: str | None) -> str:
    """A formatted value followed by its unit where it has one: ``2.001e+08 N/m^3``; ``0.3`` alone."""
    return f"{text} {unit}" if unit else text
