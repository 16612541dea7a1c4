"""Issue 17's battery on its closed-loop plant: a PD loop around a free mass, about 20 Hz bandwidth,
one sample of computation delay, fs 1 kHz, N = 4096, random-odd multisines over 1-150 Hz at three
levels x six realizations, four periods after a transient one, coloured sensor noise fed back
through the loop (41-54 dB below the output over the levels).

The data come from tests/generators/independent_free_mass.py (closed-form motion between the friction's
events, not nlsid's simulator). The tool gets the nominal model (mass 2 kg, damping 5 N s/m, no
spring, no friction) and the recording; the issue's criteria are asserted: the right cause(s), the
main parameters within 10 %, the extended model within 3 dB of the noise floor, no false alarm on
a correct model (here with a constant force offset, a nuisance, not a cause). Measured when this
was written (2-core machine, one test at a time): 2 to 15 s per test, the data generation included.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from generators import independent_free_mass  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.signals.lines import random_grid  # noqa: E402
from nlsid.signals.multisine import flat_amplitudes, random_phases, synthesize  # noqa: E402

FS, N = 1000.0, 4096
MASS, DAMPING = 2.0, 5.0
W = 2 * np.pi * 20.0
KP, KD = MASS * W**2, 2 * 0.7 * W * MASS   # crossover near 20 Hz, damping ratio 0.7
NOISE = 1e-5                                # sensor noise rms (m), first-order coloured
LEVELS = (0.003, 0.006, 0.012)              # reference rms (m): outputs 1.2 to 4.9 mm rms

MODEL = {"model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": 0.0,
                   "output": "position"},
         "closed_loop": {"controller": {"type": "transfer_function", "domain": "discrete",
                                        "num": [0.0, KP + KD * FS, -KD * FS], "den": [1.0]}}}


def recording(seed: int, **truth) -> list[Run]:
    """The battery's runs measured on the independent loop with the plant ``truth`` (mass, fc,
    force_offset, limit; the model's values where not given)."""
    rng = np.random.default_rng(seed)
    candidates = np.arange(5, int(150 * N / FS) + 1, 2)        # odd lines from 1.2 Hz to 150 Hz
    bins, _ = random_grid(candidates, 3, rng)
    runs = []
    for i, level in enumerate(LEVELS):
        for m in range(6):
            r = np.tile(synthesize(N, bins, flat_amplitudes(bins.size, level), random_phases(bins.size, rng)), 5)
            noise = lfilter([0.6], [1.0, -0.8], rng.standard_normal(r.size)) * NOISE  # unit variance x NOISE
            u, y = independent_free_mass.closed_loop(r, noise, FS, truth.get("mass", MASS), DAMPING, KP, KD,
                                                     truth.get("fc", 0.0), truth.get("force_offset", 0.0),
                                                     truth.get("limit", np.inf))
            runs.append(Run(f"l{i}_m{m}", FS, "multisine", u, y=y, r=r, period=N, transient_periods=1,
                            realization=m, level=level, excited_bins=bins))
    return runs


def test_the_generator_is_the_model_where_both_are_linear():
    """Without friction the closed form is the exact ZOH step, as nlsid's model: they agree to rounding."""
    from nlsid.diagnose.simulation import ModelRunner

    run = recording(1)[0]
    quiet = independent_free_mass.closed_loop(run.r, np.zeros(run.n_samples), FS, MASS, DAMPING, KP, KD)
    simulated = ModelRunner.from_data(MODEL, "model.yaml").simulate(dataclasses.replace(run, y=quiet[1]))
    assert np.max(np.abs(simulated.y - quiet[1])) < 1e-10 * np.max(np.abs(quiet[1]))


def _causes(result) -> list[str]:
    return sorted(o.hypothesis.name for o in result.chain)


@pytest.mark.slow
def test_a_correct_model_with_a_force_offset_is_nothing_beyond_noise():
    result = diagnose(MODEL, "model.yaml", recording(2, force_offset=3.0), "recording.h5")
    assert result.verdict.status == "no_discrepancy", result.headline()
    assert result.nuisances.values["input_offset"] == pytest.approx(3.0, rel=0.01)


@pytest.mark.slow
@pytest.mark.parametrize("truth, causes, checks", [
    ({"mass": 1.05 * MASS}, ["wrong_mechanics"], {"mass": 1.05 * MASS}),
    ({"fc": 2.0}, ["coulomb"], {"fc": 2.0}),
    ({"mass": 1.05 * MASS, "fc": 2.0}, None, {"fc": 2.0, "mass": 1.05 * MASS}),
    ({"mass": 0.95 * MASS, "fc": 1.0, "force_offset": 3.0}, None, {"fc": 1.0, "mass": 0.95 * MASS}),
    ({"limit": 2500.0}, ["input_saturation"], {"upper": 2500.0}),
], ids=["mass", "coulomb", "mass_and_coulomb", "mass_coulomb_offset", "saturation"])
def test_the_hidden_effects_are_named_recovered_and_reach_the_floor(truth, causes, checks):
    """``causes`` None (a wrong mass and Coulomb friction): Coulomb named, alone with the mass it
    corrected (a Coulomb law refined with the mechanics is the whole truth, and the headline names
    the mass) or after the wrong mechanics in the chain; the final model's mass is checked."""
    result = diagnose(MODEL, "model.yaml", recording(3, **truth), "recording.h5")
    named = _causes(result)
    if causes is None:
        assert "coulomb" in named and set(named) <= {"coulomb", "wrong_mechanics"}, result.headline()
    else:
        assert named == causes, result.headline()
    final = result.final.extended["model"]
    values = {"mass": final["mass"], **{k: v for f in final.get("nonlinearities", []) for k, v in f.items()},
              **(final.get("input_nonlinearity") or {})}
    for key, expected in checks.items():
        assert values[key] == pytest.approx(expected, rel=0.10), (key, result.headline())
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()
