"""The overflowing upper tank (nlsid/diagnose/hypotheses/tank_overflow.py) on the two cascaded
tanks of tests/generators/tank_cases.py with the upper tank's rim at X1MAX = 17 (its level
would exceed that about 15 % of the time) and FRAC = 0.3 of the spill entering the lower tank
(RK4 with the rim crossing located, its step checked by halving), from the user's linear model
(the linearisation without overflow, its poles and gain 20 % off).

On the family's scale of equal cross-sections (k2 = k1: the upper level times k2 / k1) the rim
reads X1MAX k2 / k1 and the spill share FRAC k1 / k2 (the volume share: the truth adds FRAC f1 to
the lower level's rate, f1 the upper level's, in tanks whose areas differ by k1 / k2).
"""

from __future__ import annotations

import numpy as np
import pytest

from generators.tank_cases import FRAC, K1, K2, K3, K4, X1MAX, identifiable, linear_start, recording
from nlsid.diagnose.diagnosis import diagnose


def test_the_overflow_is_named_with_its_rim():
    """Diagnose names the overflowing tanks over the plain ones (which stay 28 dB above the noise
    floor): the rim and the spill share within 10 % of the truth on the family's scale, the
    identifiable rates within 10 %, the extended model within 3 dB of the floor.

    Measured when written: rim 6.350 (truth 6.375), share 0.802 (0.8), k3 -0.3 %, 0.5 dB above
    the floor."""
    runs = recording(np.random.default_rng(42), rim=X1MAX)
    result = diagnose(linear_start(runs), "model.yaml", runs, "tanks.h5", yardstick=False)
    assert result.verdict.winner == "cascaded_tanks_overflow", result.headline()
    values = result.winner.estimate.values
    assert values["parameter x1max"] == pytest.approx(X1MAX * K2 / K1, rel=0.1)
    assert values["parameter frac"] == pytest.approx(FRAC * K1 / K2, rel=0.1)
    k1, k3, k4 = (values[f"parameter {k}"] for k in ("k1", "k3", "k4"))
    fitted = identifiable(k1, k1, k3, k4)
    assert fitted == pytest.approx(identifiable(K1, K2, K3, K4), rel=0.1), fitted
    assert result.final_score().above_floor_db < 3.0, result.headline()
    plain = next(o for o in result.outcomes if o.hypothesis.name == "cascaded_tanks")
    assert plain.score.above_floor_db > 10.0  # the overflow is what the plain tanks miss
