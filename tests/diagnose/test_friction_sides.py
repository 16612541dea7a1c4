"""A friction law refined with a significant constant force on a free mass is reported both ways:
its unequal sides fc_pos = fc - f0, fc_neg = fc + f0, or one fc with the force (the two simulate the
same record: tests/simulate/test_friction_sides_offset.py)."""

from __future__ import annotations

import math

import pytest

from nlsid.diagnose.outcome import Outcome
from nlsid.diagnose.hypotheses import LIBRARY
from nlsid.diagnose.hypotheses.base import Estimate
from nlsid.diagnose.nuisances import Nuisances


def outcome(f0: float, s0: float) -> Outcome:
    coulomb = next(h for h in LIBRARY if h.name == "coulomb")
    return Outcome(coulomb, Estimate({"fc": 150.0}, {"fc": 1.0}, float("nan")),
                   found=Nuisances({"force_offset": f0}, {"force_offset": s0}))


def test_a_significant_constant_force_gives_the_sides():
    sides = outcome(10.0, 0.5).sides()
    assert sides["fc_pos"] == 140.0 and sides["fc_neg"] == 160.0 and sides["force"] == 10.0
    assert sides["std"] == pytest.approx(math.hypot(1.0, 0.5))
    assert "fc_pos = 140" in outcome(10.0, 0.5).headline_values() and "cannot" in outcome(10.0, 0.5).sides_text()


def test_a_force_within_three_standard_errors_leaves_one_fc():
    assert outcome(1.0, 0.5).sides() is None and outcome(1.0, 0.5).sides_text() == ""
    assert outcome(10.0, float("nan")).sides() is None  # no standard error: nothing to judge it by
