"""Issue 17's battery on its open-loop plant, two effects at once: a mass-spring-damper near 32 Hz
with damping ratio 0.03, fs 1 kHz, N = 4096, random-odd multisines over 1-150 Hz at three levels
x six realizations, four periods after a transient one, coloured sensor noise 50 dB below the
output, and sensor and actuator offsets.

The data come from tests/generators/independent_friction.py (Runge-Kutta on a fine grid, the stop instants of
the friction bisected; the cubic spring in the motion and in the stick test), not nlsid's
simulator. Earlier versions named such data wrongly: Coulomb friction 0.5 N with a cubic spring
as LuGre with Fc = 87 N, and a 5 % mass error with Coulomb friction as LuGre with Fc = 20 N (the
issue's text). The criteria are the issue's: every cause named, the main parameters within 10 %,
the final model within 3 dB of the noise floor.

Measured when this was written (2-core machine, one test at a time): Coulomb with the cubic spring
29 s (two rounds: the first fits every friction law and spring against a residual that is both),
the mass error with Coulomb 9 s. Before the response along the model's trajectory (a model with
friction responds to nothing from rest), the second round could not fit the spring at all.
"""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from generators import independent_friction  # noqa: E402
from generators import independent_plant  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.signals.lines import random_grid  # noqa: E402
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize  # noqa: E402

FS, N = 1000.0, 4096
MASS = 0.5
STIFFNESS = MASS * (2 * np.pi * 32.0) ** 2
DAMPING = 2 * 0.03 * np.sqrt(STIFFNESS * MASS)
LEVELS = (1.0, 2.0, 4.0)               # force rms (N): position 0.12 to 0.48 mm rms
SNR_DB = 50.0
SENSOR_OFFSET, ACTUATOR_OFFSET = 2e-5, 0.01   # m (a sixth of the lowest level's rms), N
NOMINAL = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": float(DAMPING),
                     "stiffness": float(STIFFNESS), "gain": 1.0}}


def two_mass(m2: float, f2: float, zeta2: float) -> dict:
    """A load m2 coupled to the driven mass by a spring and a damper (m2 alone on them: f2 Hz,
    damping ratio zeta2): the driven mass's position as a transfer function, from the two
    equations of motion (module docstring of nlsid/diagnose/hypotheses/coupled_mode.py):
    X1 / F = (m2 s^2 + c2 s + k2) / ((m1 s^2 + (c + c2) s + k + k2)(m2 s^2 + c2 s + k2) - (c2 s + k2)^2)."""
    k2 = m2 * (2 * np.pi * f2) ** 2
    c2 = 2 * zeta2 * np.sqrt(k2 * m2)
    load = np.array([m2, c2, k2])
    den = np.polysub(np.polymul([MASS, DAMPING + c2, STIFFNESS + k2], load), np.polymul([c2, k2], [c2, k2]))
    return {"type": "transfer_function", "num": [float(c) for c in load], "den": [float(c) for c in den]}


def recording(seed: int, forces: list[dict], mass: float = MASS, linear: dict | None = None,
              snr_db: float = SNR_DB, **changes) -> list[Run]:
    """The runs measured on the truth: the nominal plant with ``forces``, ``mass`` and the other
    keys of ``changes`` (an input block), or the transfer function ``linear``; noise ``snr_db``
    below the output."""
    rng = np.random.default_rng(seed)
    bins, _ = random_grid(np.arange(5, int(150 * N / FS) + 1, 2), 3, rng)
    commands = [np.tile(synthesize(N, bins, flat_amplitudes(bins.size, level), random_phases(bins.size, rng)), 5)
                for level in LEVELS for _ in range(6)]
    truth = copy.deepcopy(NOMINAL)["model"] | {"mass": mass} | changes
    U = np.stack(commands) + ACTUATOR_OFFSET
    Y = (independent_friction.stribeck_response(truth | {"nonlinearities": forces}, U, FS) if forces
         else independent_plant.outputs({"model": linear or truth}, U, FS))
    noise = 10 ** (-snr_db / 20) * float(np.sqrt(np.mean(Y**2)))
    runs = []
    for i, (u, y) in enumerate(zip(commands, Y)):
        coloured = lfilter([0.6], [1.0, -0.8], rng.standard_normal(y.size)) * noise  # unit variance x noise
        runs.append(Run(f"r{i}", FS, "multisine", u, y=y + coloured + SENSOR_OFFSET, period=N, transient_periods=1,
                        realization=i % 6, level=LEVELS[i // 6], excited_bins=bins))
    return runs


def _final_values(result) -> dict:
    """The final model's mass and forces by type; a break-away written as ``peak`` (fs = fc + peak,
    docs/configs.md) also as its ``fs``."""
    model = result.final.extended["model"]
    forces = {f["type"]: ({**f, "fs": f["fc"] + f["peak"]} if "peak" in f else f)
              for f in model.get("nonlinearities", [])}
    return {"mass": model["mass"], **forces}


@pytest.mark.slow
def test_coulomb_friction_and_a_cubic_spring_are_both_named():
    coulomb, cubic = {"type": "coulomb", "fc": 0.2}, {"type": "cubic_stiffness", "k3": 1e9}
    result = diagnose(NOMINAL, "model.yaml", recording(4, [coulomb, cubic]), "recording.h5")
    assert sorted(o.hypothesis.name for o in result.chain) == ["coulomb", "cubic_stiffness"], result.headline()
    values = _final_values(result)
    assert values["coulomb"]["fc"] == pytest.approx(0.2, rel=0.10)
    assert values["cubic_stiffness"]["k3"] == pytest.approx(1e9, rel=0.10)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


@pytest.mark.slow
def test_a_mass_error_and_coulomb_friction_are_both_corrected():
    result = diagnose(NOMINAL, "model.yaml", recording(5, [{"type": "coulomb", "fc": 0.2}], mass=1.05 * MASS),
                      "recording.h5")
    named = {o.hypothesis.name for o in result.chain}
    assert "coulomb" in named and named <= {"coulomb", "wrong_mechanics"}, result.headline()
    values = _final_values(result)
    assert values["coulomb"]["fc"] == pytest.approx(0.2, rel=0.10)
    assert values["mass"] == pytest.approx(1.05 * MASS, rel=0.01)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


@pytest.mark.slow
@pytest.mark.parametrize("snr_db", [SNR_DB, 30.0])
def test_a_correct_model_with_offsets_and_coloured_noise_is_nothing_beyond_noise(snr_db):
    """The offsets are nuisances: their static effect on y (a sensor offset, and the actuator's
    through the static gain 1 / k) is fitted, not named as a cause; at the issue's SNR and lower."""
    result = diagnose(NOMINAL, "model.yaml", recording(6, [], snr_db=snr_db), "recording.h5")
    assert result.verdict.status == "no_discrepancy", result.headline()
    found = result.nuisances.values
    static = found.get("output_offset", 0.0) + (found.get("force_offset", 0.0) + found.get("input_offset", 0.0)) / STIFFNESS
    assert static == pytest.approx(SENSOR_OFFSET + ACTUATOR_OFFSET / STIFFNESS, rel=0.05), found


@pytest.mark.slow
def test_a_coupled_load_mass_is_a_coupled_mode_though_it_moves_the_model_own_mode():
    """A 0.15 kg load on the 0.5 kg driven mass, 60 Hz on its coupling: the low mode moves from
    32 Hz to 27.3 Hz (the user's model knows the driven mass alone), the resonance is at 70.4 Hz
    (the roots of the fourth-order denominator, by numpy). The ratio of the BLA to the model then
    holds both, and its second-order fit put the anti-resonance above the resonance: the issue's
    "named wrong mechanics". The coupled mode must be named with its resonance within 10 %."""
    truth = two_mass(0.15, 60.0, 0.02)
    resonance = max(abs(np.roots(truth["den"]))) / (2 * np.pi)
    result = diagnose(NOMINAL, "model.yaml", recording(7, [], linear=truth), "recording.h5")
    assert result.verdict.winner == "coupled_mode", result.headline()
    assert result.winner.estimate.values["fr"] == pytest.approx(resonance, rel=0.10)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


@pytest.mark.slow
def test_a_saturation_and_a_stiffness_error_give_the_limits_of_the_recorded_input():
    """An actuator limit of +-8 N behind the actuator offset (0.01 N before the limit: the limits
    seen from the recorded command are -8.01 and +7.99) and a spring 3 % softer than the model's,
    at 35 dB. An offset before a saturation is the saturation moved plus a constant force, which
    the output offset takes through the static gain (nlsid/diagnose/hypotheses/input_blocks.py):
    with the input offset free the fit wandered along that direction to -9.50 / +6.49 on this
    record (input offset -1.49, correlation -1.000 with the output offset). Held, the limits must
    be those of the recorded command within 1 %, the stiffness within 1 %."""
    result = diagnose(NOMINAL, "model.yaml",
                      recording(9, [], snr_db=35.0, stiffness=0.97 * STIFFNESS,
                                input_nonlinearity={"type": "saturation", "lower": -8.0, "upper": 8.0}),
                      "recording.h5")
    assert result.verdict.winner == "input_saturation", result.headline()
    block = result.final.extended["model"]["input_nonlinearity"]
    assert block["lower"] == pytest.approx(-8.0 - ACTUATOR_OFFSET, rel=0.01)
    assert block["upper"] == pytest.approx(8.0 - ACTUATOR_OFFSET, rel=0.01)
    assert result.final.extended["model"]["stiffness"] == pytest.approx(0.97 * STIFFNESS, rel=0.01)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


@pytest.mark.slow
def test_a_weak_coulomb_friction_10_db_above_the_noise_is_named():
    """The issue's lower end: an effect about 10 dB above the noise (Coulomb 0.03 N against forces of
    1 to 4 N rms, 30 dB SNR, coloured). Named, fc within 10 %, the final model at the floor."""
    result = diagnose(NOMINAL, "model.yaml", recording(10, [{"type": "coulomb", "fc": 0.03}], snr_db=30.0),
                      "recording.h5")
    assert 6.0 < result.evidence.overall.above_noise_db < 14.0, result.headline()  # the case is the one described
    assert [o.hypothesis.name for o in result.chain] == ["coulomb"], result.headline()
    assert _final_values(result)["coulomb"]["fc"] == pytest.approx(0.03, rel=0.10)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_dead_time_with_a_mass_error_is_one_cause_with_the_mass_corrected():
    """A 2.7-sample dead time and a mass 5 % above the model's. Refined alone, the dead time could
    not take the mass error, and wrong mechanics (here) or a coupled mode (on another seed) was
    named, 40-43 dB above the floor; refined with the mechanics, as the
    forces and blocks are (Hypothesis.refits_linear), the dead time is the cause, within 10 %, the
    mass within 1 %, and the final model at the floor."""
    result = diagnose(NOMINAL, "model.yaml", recording(11, [], mass=1.05 * MASS, delay=2.7e-3), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["delay"], result.headline()
    assert result.chain[0].estimate.values["delay"] == pytest.approx(2.7e-3, rel=0.1)
    assert result.final.extended["model"]["mass"] == pytest.approx(1.05 * MASS, rel=0.01)
    assert "the mass 5 % above" in result.headline()
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


@pytest.mark.slow
def test_a_dead_time_and_a_backlash_tie_and_the_next_round_resolves_it():
    """A 1.3-sample dead time and a backlash of 0.4 N at the input. Alone, a dead time and a
    missing resonance (which mimics its phase lag in the band, with three parameters) explain the
    same share of the error: the first round ties them, and the chain stopped at "equally good
    explanations". Each taken as the cause, the next round names the backlash and both end at the
    floor; the simpler branch is taken (nlsid/diagnose/diagnosis.py, _resolve_tie): the dead time,
    then the backlash, each within 10 %, the final model within 3 dB of the floor."""
    result = diagnose(NOMINAL, "model.yaml",
                      recording(12, [], delay=1.3e-3, input_nonlinearity={"type": "backlash", "width": 0.4}),
                      "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["delay", "backlash"], result.headline()
    assert result.chain[0].estimate.values["delay"] == pytest.approx(1.3e-3, rel=0.1)
    assert result.chain[1].estimate.values["width"] == pytest.approx(0.4, rel=0.1)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


@pytest.mark.slow
def test_stribeck_friction_starts_from_what_the_coulomb_law_leaves():
    """Stribeck friction (fc 0.2 N, fs 0.4 N, vs 2 mm/s) is named, its levels and velocity within
    10 %, at the floor. Its refinement starts from the regression on what the fitted Coulomb law
    leaves (nlsid.diagnose.hypotheses.friction._beyond_coulomb), whose velocities stick as the
    mass does: vs within a factor 2 of the truth (measured 3.6 mm/s, the grid's points a factor
    1.47 apart); the nominal model's signature put it at 31 mm/s, and the refinement from next to
    the Coulomb law took 123 simulations instead of 55."""
    stribeck = {"type": "stribeck", "fc": 0.2, "fs": 0.4, "vs": 0.002}
    result = diagnose(NOMINAL, "model.yaml", recording(1, [stribeck]), "recording.h5")
    assert [o.hypothesis.name for o in result.chain] == ["stribeck"], result.headline()
    start = next(o for o in result.outcomes if o.hypothesis.name == "stribeck")
    assert "what the fitted Coulomb law leaves" in start.estimate.note, start.estimate.note
    values = _final_values(result)["stribeck"]
    for key in ("fc", "fs", "vs"):
        assert values[key] == pytest.approx(stribeck[key], rel=0.10), (key, values)
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()
