"""The output (sensor) saturation family: its signature (the recorded output flat at a ceiling or a
floor) on signals built here, and the diagnosis of records from tests/generators/effect_cases.py
(exact ZOH responses, a sensor offset, coloured noise at -50 dB):

- a sensor that tops out at 0.6 (clipping the noisy, offset signal, as a converter does) is named
  output saturation, its ceiling within 4 standard errors of the truth (0.6 less the sensor
  offset, in the model's units before the offset), the extended model within 3 dB of the noise
  floor;
- a range on both sides (-0.5 .. 0.7) with the plant's transfer function as the model: both
  limits within 4 standard errors;
- its neighbour, an actuator that saturates at +-1.2 (the plant smooths the clipped input: no
  flat output), is named input saturation, and sensor saturation does not apply;
- the same plant without an effect (offsets, coloured noise) is nothing beyond noise.

Measured when written: sensor saturation 42.1 dB gain, 0.4 dB below the floor, ceiling 0.598 +-
1.1e-4; both sides 43.7 dB, 0.2 dB below the floor, 0.69799 +- 1.2e-4 and -0.50201 +- 1.0e-4;
actuator saturation 42.0 dB, 0.6 dB above the floor (the polynomial next best, 12.6 dB).
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import effect_cases as cases
from nlsid.diagnose.diagnosis import diagnose
from nlsid.diagnose.hypotheses.output_saturation import FLAT_SHARE, flat_sides

CEILING = 0.6
FLOOR, RANGE_TOP = -0.5, 0.7  # a sensor range clipping 9.5 % and 4.7 % of the samples


def outcome(result, name):
    return next(o for o in result.outcomes if o.hypothesis.name == name)


def test_flat_sides_of_clipped_and_of_quantised_signals():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(20000)
    step = 2.0**-12  # a 16-bit converter over +-8
    quantised = np.round(x / step) * step
    assert flat_sides(quantised) == {}  # its extremes are in the tails: taken once or twice
    assert flat_sides(x) == {}
    top = float(np.quantile(quantised, 0.99))  # 1 % of the samples at the ceiling
    clipped = np.minimum(quantised, top)
    assert flat_sides(clipped) == {"upper": top}
    both = np.clip(x, -1.5, 2.0)  # 6.7 % below -1.5, 2.3 % above 2 (normal tails)
    assert flat_sides(both) == {"upper": 2.0, "lower": -1.5}
    rare = np.minimum(x, np.sort(x)[-int(0.5 * FLAT_SHARE * x.size)])  # fewer than FLAT_SHARE on it
    assert flat_sides(rare) == {}


def test_a_sensor_that_tops_out_is_named_output_saturation():
    runs = cases.recording(4, cases.linear, sensor=lambda y: np.minimum(y, CEILING))
    assert np.mean(np.concatenate([r.y for r in runs]) == CEILING) > 0.01
    result = diagnose(cases.MSD, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "output_saturation", result.headline()
    est = result.winner.estimate
    assert cases.within(est.values["limit"], CEILING - cases.OFFSET, est.std["limit"]), (est.values, est.std)
    assert result.winner.qualifier() == "ceiling"
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_sensor_range_on_both_sides_around_a_transfer_function():
    runs = cases.recording(11, cases.linear, sensor=lambda y: np.clip(y, FLOOR, RANGE_TOP))
    result = diagnose(cases.TF, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "output_saturation", result.headline()
    est = result.winner.estimate
    assert cases.within(est.values["limit"], RANGE_TOP - cases.OFFSET, est.std["limit"]), (est.values, est.std)
    assert cases.within(est.values["floor"], FLOOR - cases.OFFSET, est.std["floor"]), (est.values, est.std)
    assert result.winner.qualifier() == "ceiling and floor"
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_an_actuator_saturation_is_not_a_sensor_saturation():
    runs = cases.recording(5, lambda U: cases.linear(U, lambda u: np.clip(u, -1.2, 1.2)))
    result = diagnose(cases.MSD, "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "input_saturation", result.headline()
    assert outcome(result, "output_saturation").reason.startswith("does not apply: the recorded output has no flat")
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_linear_plant_is_nothing_beyond_noise():
    result = diagnose(cases.MSD, "model.yaml", cases.recording(8, cases.linear), "recording.h5")
    assert result.verdict.status == "no_discrepancy", result.headline()
    assert not result.chain
