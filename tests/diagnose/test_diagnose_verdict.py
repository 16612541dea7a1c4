"""Verdict rules of nlsid.diagnose.verdict on error powers whose ratios are set against F_{0.999}(nu, nu).

nu = 4000 equivalent degrees of freedom (about 511 lines x 4 validation runs, the hidden-effect
suite's size): the F threshold is computed here independently with scipy, and the powers are
placed 10 % inside or outside it so that no rounding decides a case.
"""

from __future__ import annotations

import pytest
from scipy.stats import f as f_dist

from nlsid.diagnose.verdict import AMBIGUOUS, EXPLAINED, NO_DISCREPANCY, UNEXPLAINED, Candidate, decide

DOF = 4000.0
F = float(f_dist.isf(0.001, DOF, DOF))  # about 1.10
INSIDE, OUTSIDE = F ** 0.9, F ** 1.1     # ratios just below and above the threshold (log scale)


def _friction(coulomb: float, stribeck: float, lugre: float) -> list[Candidate]:
    return [Candidate("coulomb", "friction", 1, coulomb), Candidate("stribeck", "friction", 3, stribeck),
            Candidate("lugre", "friction", 4, lugre)]


def test_threshold_is_the_f_quantile():
    assert decide(True, 1.0, [], DOF).threshold == pytest.approx(F, rel=1e-12)


@pytest.mark.parametrize("coulomb, stribeck, lugre, winner", [
    (INSIDE, 1.0, 1.0, "coulomb"),                   # nothing richer is significantly better
    (OUTSIDE, 1.0, 1.0, "stribeck"),                 # Stribeck's gain over Coulomb is significant, LuGre's is not
    (OUTSIDE * INSIDE, INSIDE, 1.0, "stribeck"),     # LuGre is best but only insignificantly better than Stribeck
    (OUTSIDE ** 2, OUTSIDE, 1.0, "lugre"),           # each step significant
    (INSIDE, INSIDE ** 2, INSIDE ** 2, "coulomb"),   # richer laws no better (a fit stopped early): Coulomb
])
def test_richer_friction_only_when_its_gain_over_the_simpler_is_significant(coulomb, stribeck, lugre, winner):
    original = 100.0  # every hypothesis explains (100 / power >> F)
    verdict = decide(True, original, _friction(coulomb, stribeck, lugre), DOF)
    assert verdict.status == EXPLAINED and verdict.winner == winner


def test_tied_families_are_ambiguous_and_noise_answers_no_discrepancy():
    candidates = [Candidate("coulomb", "friction", 1, 1.0), Candidate("backlash", "input", 1, INSIDE)]
    assert decide(True, 100.0, candidates, DOF).status == AMBIGUOUS
    assert decide(True, 100.0, [Candidate("coulomb", "friction", 1, 1.0),
                                Candidate("backlash", "input", 1, OUTSIDE)], DOF).winner == "coulomb"
    assert decide(False, 100.0, candidates, DOF).status == NO_DISCREPANCY
    assert decide(True, INSIDE, [Candidate("coulomb", "friction", 1, 1.0)], DOF).status == UNEXPLAINED


@pytest.mark.parametrize("split, winner", [
    (1.0 / INSIDE, "input_saturation"),   # the split is better, but not significantly: the input block it contains
    (1.0 / OUTSIDE, "wiener_hammerstein"),  # significantly better: the split
])
def test_a_model_that_contains_a_tied_one_leaves_the_tie(split, winner):
    """The Wiener-Hammerstein split contains an input block (G1 = 1): tied with input saturation it
    is not an equally good explanation of another kind but the same one with more parameters."""
    candidates = [Candidate("input_saturation", "input", 1, 1.0),
                  Candidate("wiener_hammerstein", "structure", 3, split, ("input", "output"))]
    verdict = decide(True, 100.0, candidates, DOF)
    assert verdict.status == EXPLAINED and verdict.winner == winner
