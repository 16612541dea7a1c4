"""The unit of every parameter of the mechanical templates, against dimensional analysis done here.

Each template's equation is written term by term in SI base dimensions (kg, m, s): with u in N and
y in m, a force is kg m s^-2, a position m, a velocity m s^-1. Every term of
m p'' + c p' + k p + F_nl = gain u has the dimension of the force; so the mass is force over
acceleration, the damping force over velocity, a cubic spring's k3 force over position cubed, and
so on. The module's unit text is read back into base dimensions by a parser of this test (N, kg,
m, s, Hz) and compared. Units the recording does not fix come back as None, never a guess.
"""

from __future__ import annotations

import math
import re

import pytest

from nlsid.diagnose.hypotheses import LIBRARY, Estimate
from nlsid.diagnose.outcome import Outcome
from nlsid.models.parameter_units import unit_of, unit_table

KG, M, S = (1, 0, 0), (0, 1, 0), (0, 0, 1)
BASE = {"kg": KG, "m": M, "s": S, "N": (1, 1, -2), "Hz": (0, 0, -1)}


def times(*factors: tuple[tuple[int, int, int], int]) -> tuple[int, int, int]:
    """prod(dimension^power) as (kg, m, s) exponents."""
    return tuple(sum(d[i] * p for d, p in factors) for i in range(3))


FORCE = BASE["N"]
POSITION = M
VELOCITY = times((M, 1), (S, -1))
ACCELERATION = times((M, 1), (S, -2))


def dimension(text: str) -> tuple[int, int, int]:
    """A unit text ("N s/m", "kg", "1/m^2", "m/(N s)") in (kg, m, s) exponents; "" is a pure number."""
    total = (0, 0, 0)
    for i, part in enumerate(text.split("/")):
        sign = 1 if i == 0 else -1
        for token in part.strip("()").split():
            if token == "1":
                continue
            symbol, _, power = re.fullmatch(r"([A-Za-z]+)(\^(-?\d+))?", token).groups()
            total = times((total, 1), (BASE[symbol], sign * int(power or 1)))
    return total


SI = {"u": "N", "y": "m"}

# every term of m p'' + c p' + k p + F = gain u is a force (docs/configs.md, mechanical templates)
MSD_EXPECTED = {
    "model.mass": times((FORCE, 1), (ACCELERATION, -1)),
    "model.damping": times((FORCE, 1), (VELOCITY, -1)),
    "model.stiffness": times((FORCE, 1), (POSITION, -1)),
    "model.gain": (0, 0, 0),  # N per N
    "model.force_offset": FORCE,
    "model.input_offset": FORCE,  # u + input_offset, u in N
    "model.output_offset": POSITION,
    "model.delay": S,
    "model.initial.position": POSITION,
    "model.initial.velocity": VELOCITY,
    "model.nonlinearities[0].k3": times((FORCE, 1), (POSITION, -3)),  # F = k3 p^3
    "model.nonlinearities[1].fc": FORCE,                               # F = fc sign(v) + fv v
    "model.nonlinearities[1].fv": times((FORCE, 1), (VELOCITY, -1)),
    "model.nonlinearities[2].fs": FORCE,                               # Stribeck: e^{-|v/vs|^delta}
    "model.nonlinearities[2].vs": VELOCITY,
    "model.nonlinearities[2].delta": (0, 0, 0),
    "model.nonlinearities[3].sigma0": times((FORCE, 1), (POSITION, -1)),  # LuGre: F = sigma0 z + sigma1 z' + ...
    "model.nonlinearities[3].sigma1": times((FORCE, 1), (VELOCITY, -1)),
    "model.nonlinearities[4].c2": times((FORCE, 1), (VELOCITY, -2)),   # F = c2 v |v|
    "model.nonlinearities[5].k": times((FORCE, 1), (POSITION, -1)),    # Bouc-Wen F = k z, z a position,
    "model.nonlinearities[5].beta": times((POSITION, -2)),             # z' = A v - beta |v| |z|^(n-1) z, n = 2
    "model.nonlinearities[6].upper": POSITION,
    "model.nonlinearities[6].stiffness": times((FORCE, 1), (POSITION, -1)),
    "model.nonlinearities[7].k4": times((FORCE, 1), (POSITION, -4)),   # F = k4 p^4
}
MSD = {"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0, "gain": 35.0,
                 "force_offset": 1.0, "nonlinearities": [
                     {"type": "cubic_stiffness", "k3": 2e8}, {"type": "coulomb", "fc": 10.0, "fv": 0.5},
                     {"type": "stribeck", "fc": 10.0, "fs": 14.0, "vs": 0.01},
                     {"type": "lugre", "sigma0": 1e5, "sigma1": 300.0, "fc": 10.0, "fs": 14.0, "vs": 0.01},
                     {"type": "quadratic_damping", "c2": 3.0},
                     {"type": "bouc_wen", "k": 100.0, "beta": 1.0, "n": 2},
                     {"type": "end_stop", "upper": 0.01, "stiffness": 1e6},
                     {"type": "polynomial_stiffness", "k4": 1.0}]}}


@pytest.mark.parametrize("path", sorted(MSD_EXPECTED))
def test_mass_spring_damper_units_are_those_of_its_equation(path):
    unit = unit_of(MSD, path, SI)
    assert unit is not None and dimension(unit) == MSD_EXPECTED[path], (path, unit)


def test_the_mass_reads_kg_and_the_spring_n_per_m():
    assert unit_of(MSD, "model.mass", SI) == "kg"
    assert unit_of(MSD, "model.stiffness", SI) == "N/m"
    assert unit_of(MSD, "model.damping", SI) == "N s/m"
    assert unit_of(MSD, "model.nonlinearities[0].k3", SI) == "N/m^3"


def test_two_mass_stage_units():
    stage = {"model": {"type": "two_mass_stage", "motor_mass": 1.0, "load_mass": 0.5, "stiffness": 2e4,
                       "damping": 40.0, "motor_damping": 20.0, "output": "velocity",
                       "nonlinearities": [{"type": "cubic_stiffness", "k3": 1e9, "at": "joint"}]}}
    units = {"u": "N", "y": "m/s"}  # a velocity output: the position is y's unit times s
    expected = {"model.motor_mass": times((FORCE, 1), (ACCELERATION, -1)),
                "model.load_mass": times((FORCE, 1), (ACCELERATION, -1)),
                "model.stiffness": times((FORCE, 1), (POSITION, -1)),
                "model.damping": times((FORCE, 1), (VELOCITY, -1)),
                "model.load_damping": times((FORCE, 1), (VELOCITY, -1)),
                "model.nonlinearities[0].k3": times((FORCE, 1), (POSITION, -3)),
                "model.output_offset": VELOCITY}
    for path, dim in expected.items():
        assert dimension(unit_of(stage, path, units)) == dim, path


def test_other_units_are_carried_as_they_are_written():
    """Millimetres and volts are not converted: the unit is the recording's, not SI's."""
    assert unit_of(MSD, "model.stiffness", {"u": "N", "y": "mm"}) == "N/mm"
    assert unit_of(MSD, "model.mass", {"u": "N", "y": "mm"}) == "N s^2/mm"
    gain_one = {"model": {**MSD["model"], "gain": 1.0}}  # F = 1 * u: forces in units of the command
    assert unit_of(gain_one, "model.nonlinearities[0].k3", {"u": "V", "y": "m"}) == "V/m^3"
    assert unit_of(gain_one, "model.nonlinearities[1].fc", {"u": "V", "y": "m"}) == "V"


def test_a_force_of_unknown_unit_gets_none():
    """gain 35 from a command in V: the force's unit is what the user meant the gain to carry
    (N/V, say); every key that holds a force is unknown, the positions are still known."""
    units = {"u": "V", "y": "m"}
    for path in ("model.mass", "model.stiffness", "model.gain", "model.nonlinearities[0].k3",
                 "model.nonlinearities[1].fc", "model.force_offset"):
        assert unit_of(MSD, path, units) is None, path
    assert unit_of(MSD, "model.nonlinearities[2].vs", units) == "m/s"
    assert unit_of(MSD, "model.nonlinearities[6].upper", units) == "m"
    assert unit_of(MSD, "model.input_offset", units) == "V"


def test_units_not_recorded_give_none():
    for units in ({}, {"u": "N"}, {"y": "m"}):
        assert unit_of(MSD, "model.nonlinearities[0].k3", units) is None
    assert unit_of(MSD, "model.output_offset", {"u": "N"}) is None
    assert unit_of(MSD, "model.delay", {}) == "s"  # time needs no recorded unit


def test_a_block_that_rescales_leaves_the_plant_side_unknown():
    """A polynomial input block with a linear coefficient other than 1 rescales u into a unit of the
    user's choice; with 1 (as diagnose writes it: [0, 1, a2, a3]) the plant input is in u's unit."""
    rescaled = {"model": {**MSD["model"], "input_nonlinearity": {"type": "polynomial", "coefficients": [0, 3.0, 0.1]}}}
    assert unit_of(rescaled, "model.nonlinearities[0].k3", SI) is None
    assert unit_of(rescaled, "model.input_nonlinearity.coefficients[2]", SI) is None
    unit_slope = {"model": {**MSD["model"], "gain": 1.0,
                            "input_nonlinearity": {"type": "polynomial", "coefficients": [0, 1.0, 0.1, 0.01]}}}
    assert unit_of(unit_slope, "model.nonlinearities[0].k3", {"u": "V", "y": "m"}) == "V/m^3"
    # a_p u^p is in u's unit: a_3 in 1/u^2
    assert unit_of(unit_slope, "model.input_nonlinearity.coefficients[3]", {"u": "V", "y": "m"}) == "1/V^2"
    output = {"model": {"type": "transfer_function", "num": [1.0], "den": [1.0, 1.0],
                        "output_nonlinearity": {"type": "polynomial", "coefficients": [0, 1, 0.2]}}}
    assert unit_of(output, "model.output_nonlinearity.coefficients[2]", SI) == "1/m"


def test_transfer_function_coefficients_have_no_unit_but_a_static_gain_has():
    """num and den are scaled against each other at will: no unit. A zpk's gain has one: with only
    unit-DC-gain modes it is the static gain y/u; each plain pole adds 1/s (G = gain / s is y/u)."""
    tf = {"model": {"type": "transfer_function", "num": [1e4], "den": [1.0, 20.0, 4e4]}}
    table = unit_table(tf, SI)
    assert table.get("model.num[0]") is None and table.get("model.den[1]") is None
    modes = {"model": {"type": "zpk", "zeros": [], "poles": [{"frequency": 30.0, "damping": 0.05}], "gain": 2.5e-4}}
    assert unit_of(modes, "model.gain", SI) == "m/N"
    assert unit_of(modes, "model.poles[0].frequency", SI) == "Hz"
    integrator = {"model": {"type": "zpk", "zeros": [], "poles": [0.0, [-1.0, 5.0]], "gain": 3.0}}
    # gain / (s (s^2 + 2 s + 26)): s in 1/s, so gain is y/u per s^3
    assert dimension(unit_of(integrator, "model.gain", SI)) == times((POSITION, 1), (FORCE, -1), (S, -3))
    discrete = {"model": {"type": "zpk", "domain": "discrete", "zeros": [0.5], "poles": [0.9], "gain": 0.1}}
    assert unit_of(discrete, "model.gain", SI) == "m/N"
    assert unit_of(tf, "model.gain", SI) is None


def test_feedback_around_a_transfer_function_is_in_units_of_u():
    """diagnose puts a transfer function's nonlinearity in feedback with gain 1: F in u's unit."""
    around = {"model": {"type": "nonlinear_feedback", "linear": {"type": "transfer_function", "num": [1.0],
                                                                   "den": [1.0, 20.0, 4e4]},
                        "nonlinearities": [{"type": "cubic_stiffness", "k3": 0.6}]}}
    assert unit_of(around, "model.nonlinearities[0].k3", {"u": "V", "y": "m"}) == "V/m^3"
    assert unit_of(around, "model.linear.num[0]", {"u": "V", "y": "m"}) is None


def test_a_force_at_a_modal_point_has_no_unit():
    """A force at a named point of nonlinear_feedback (a modal coordinate q of a state space) reads q,
    whose scale is the realisation's, not y's: its k3 has no unit (y's would be wrong)."""
    modal = {"model": {"type": "nonlinear_feedback", "gain": 1.0,
                       "linear": {"type": "state_space", "A": [[0, 1], [-100, -1]], "B": [0, 1], "C": [1, 0]},
                       "points": {"mode": {"force": [0, 1], "position": [1, 0]}},
                       "nonlinearities": [{"type": "cubic_stiffness", "k3": 5.0, "at": "mode"},
                                          {"type": "cubic_stiffness", "k3": 2.0}]}}
    assert unit_of(modal, "model.nonlinearities[0].k3", SI) is None
    assert unit_of(modal, "model.nonlinearities[1].k3", SI) == "N/m^3"  # at the plant: y's position


def test_models_whose_units_the_structure_does_not_fix_get_none():
    equations = {"model": {"type": "equations", "states": {"h": 0.0}, "parameters": {"k1": 0.1},
                           "derivatives": {"h": "-k1 * sqrt(h) + u"}, "output": "h"}}
    assert unit_of(equations, "model.parameters.k1", SI) is None
    assert unit_of(MSD, "model.no_such_key", SI) is None
    assert unit_of(MSD, "not a path", SI) is None


def test_controller_units():
    loop = {"model": MSD["model"], "closed_loop": {
        "controller": {"type": "pid", "kp": 2.0, "ki": 40.0, "kd": 0.02, "tau": 0.001},
        "feedforward": {"coulomb": 1.0, "velocity": 2.0}}}
    # u = kp e + ki int e + kd e', e in y's unit
    assert dimension(unit_of(loop, "closed_loop.controller.kp", SI)) == times((FORCE, 1), (POSITION, -1))
    assert dimension(unit_of(loop, "closed_loop.controller.ki", SI)) == times((FORCE, 1), (POSITION, -1), (S, -1))
    assert dimension(unit_of(loop, "closed_loop.controller.kd", SI)) == times((FORCE, 1), (VELOCITY, -1))
    assert unit_of(loop, "closed_loop.feedforward.coulomb", SI) == "N"
    assert dimension(unit_of(loop, "closed_loop.feedforward.velocity", SI)) == times((FORCE, 1), (VELOCITY, -1))


def _cubic_outcome() -> Outcome:
    cubic = next(h for h in LIBRARY if h.name == "cubic_stiffness")
    extended = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4,
                          "gain": 1e4, "nonlinearities": [{"type": "cubic_stiffness", "k3": 6000.0}]}}
    return Outcome(cubic, Estimate({"k3": 6000.0}, {"k3": 1.5}, math.nan), extended=extended,
                   paths={"k3": "model.nonlinearities[0].k3"}, model=extended)


def test_the_headline_gives_the_derived_unit_or_none():
    outcome = _cubic_outcome()
    assert outcome.headline_values((), {"u": "N", "y": "m"}) == "k3 = 6000 N/m^3"
    assert outcome.headline_values((), {"u": "N", "y": "mm"}) == "k3 = 6000 N/mm^3"
    # y's unit not recorded: no unit, not the hypothesis' SI default
    assert outcome.headline_values((), {"u": "N"}) == "k3 = 6000"
    assert outcome.summary({"u": "N"})["units"] == {"k3": None}
