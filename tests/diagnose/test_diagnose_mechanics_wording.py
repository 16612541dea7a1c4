"""The headline's "the mass 5 % above the model's" compares a refined linear parameter with the
value in the model the user gave (or the last round's extension), not with where its refinement
started: a LuGre law starts from the Stribeck fit's mechanics, and measured against that start a
LuGre fit that left the user's mass unchanged read "the mass 0.383 % above the model's"."""

from __future__ import annotations

from nlsid.diagnose.outcome import MOVED, Outcome
from nlsid.diagnose.hypotheses import LIBRARY
from nlsid.diagnose.hypotheses.base import Estimate
from nlsid.fit.free_parameters import FreeParameter

MODEL = {"model": {"type": "mass_spring_damper", "mass": 0.5, "damping": 6.0, "stiffness": 2.0e4}}
LUGRE = next(h for h in LIBRARY if h.name == "lugre")


def _outcome(mass: float, start: float, std: float) -> Outcome:
    extended = {"model": {**MODEL["model"], "mass": mass}}
    paths = {"mass": "model.mass"}
    return Outcome(LUGRE, Estimate({"mass": mass, LUGRE.main: 0.0}, {"mass": std}, 0.0, ""), extended=extended,
                   free={"model.mass": FreeParameter(start, 0.05, 5.0)}, paths=paths, model=MODEL)


def test_an_unchanged_mass_is_not_named_whatever_the_start():
    # 0.50002 against the model's 0.5 is 0.2 standard errors; against the start 0.49811, 19
    assert _outcome(0.50002, 0.49811, 1e-4).mechanics_changed() == ""


def test_a_changed_mass_is_named_against_the_models_value():
    # 0.525 against 0.5: 5 % above, 250 standard errors (> MOVED); against the start 0.52, 1 %
    text = _outcome(0.525, 0.52, 1e-4).mechanics_changed()
    assert text == "the mass 5 % above the model's", text
    assert 0.025 / 1e-4 > MOVED


def test_a_later_step_of_the_chain_does_not_repeat_the_mechanics_an_earlier_one_stated():
    """Every step of a chain reports the final model's values against the user's model, so a
    second cause refined with the same mechanics would repeat the first's words: the headline
    gives them once."""
    first, second = _outcome(0.525, 0.52, 1e-4), _outcome(0.525, 0.5, 1e-4)
    stated = first.mechanics_changed()
    assert stated == second.mechanics_changed() == "the mass 5 % above the model's"
    assert second.headline_values((stated,)) == f"{LUGRE.main} = {0.0:.4g} {LUGRE.unit}"
    assert stated in first.headline_values()
