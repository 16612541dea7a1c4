"""The estimation budget of ``diagnose`` (:func:`nlsid.diagnose.split.budgeted`): long arbitrary
records are fitted on a prefix of their estimation parts, the final model once more on all of it,
validation on all of the validation part.

The record of the end-to-end test is a Duffing-like oscillator (the model of tests/generators/diagnose_cases.py
``MSD`` with a cubic spring k3 p^3) driven by filtered noise, integrated here by classical
Runge-Kutta with 16 steps per sample on the held input (error about (h w)^4 ~ 1e-9 of the response,
far below the noise), from rest like the record.
"""

from __future__ import annotations

import math
from pathlib import Path

import numba
import numpy as np
import pytest
from scipy.signal import butter, lfilter

from generators.diagnose_cases import FS, MSD  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402
from nlsid.diagnose.split import ESTIMATION, VALIDATION, assign, budgeted  # noqa: E402
from nlsid.diagnose.verdict import EXPLAINED  # noqa: E402
from nlsid.io.ranges import RangeRun, parse_range  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

K3 = 6e3
NOISE = 1e-3


@numba.njit(cache=False)
def duffing(u: np.ndarray, k3: float, fs: float, steps: int) -> np.ndarray:
    """Position of p'' + 20 p' + 4e4 p + k3 p^3 = 1e4 u, u held over each sample, from rest."""
    h = 1.0 / (fs * steps)
    p = v = 0.0
    y = np.empty(u.size)
    for k in range(u.size):
        y[k] = p
        force = 1e4 * u[k]
        for _ in range(steps):
            a1, b1 = v, force - 20.0 * v - 4e4 * p - k3 * p ** 3
            p2, v2 = p + h / 2 * a1, v + h / 2 * b1
            a2, b2 = v2, force - 20.0 * v2 - 4e4 * p2 - k3 * p2 ** 3
            p3, v3 = p + h / 2 * a2, v + h / 2 * b2
            a3, b3 = v3, force - 20.0 * v3 - 4e4 * p3 - k3 * p3 ** 3
            p4, v4 = p + h * a3, v + h * b3
            a4, b4 = v4, force - 20.0 * v4 - 4e4 * p4 - k3 * p4 ** 3
            p, v = p + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4), v + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
    return y


def long_record(n: int, seed: int = 5) -> Run:
    rng = np.random.default_rng(seed)
    u = lfilter(*butter(4, 150 / (FS / 2)), rng.standard_normal(n))
    u *= 1.0 / np.std(u)
    return Run("long", FS, "arbitrary", u, y=duffing(u, K3, FS, 16) + NOISE * rng.standard_normal(n))


def arbitrary(run_id: str, n: int) -> Run:
    return Run(run_id, FS, "arbitrary", np.zeros(n), y=np.zeros(n))


def test_each_record_keeps_its_share_of_the_budget_from_the_start_of_its_range():
    runs = [arbitrary("a", 300_000), arbitrary("b", 250_000)]
    parts, roles = assign(runs, "rec.h5", (), parse_range("1000:201000", "--estimation-range"),
                          parse_range("201000:", "--validation-range"))
    budget = budgeted(parts, roles, samples=10_000, above=50_000)
    # estimation parts of 200000 samples each: half the budget each, ceil(10000 * 200000 / 400000)
    assert budget.available == 400_000 and budget.used == 10_000 and budget.active
    for run in parts:
        fitted = budget.of([run])[0]
        if roles[run.run_id] == VALIDATION:
            assert fitted is run  # validation parts stay whole
            continue
        assert isinstance(fitted, RangeRun) and fitted.start == 1000 and fitted.period == 5000
        assert fitted.run_id == f"{run.run_id.split('[')[0]}[1000:6000]"
        # the same samples as the range's first 5000: the record up to the part's end, unchanged
        np.testing.assert_array_equal(fitted.y, run.y[:6000])
        np.testing.assert_array_equal(fitted.periods("y")[0], run.periods("y")[0, :5000])
    assert budget.summary() == {"estimation_samples_used": 10_000, "estimation_samples": 400_000}


def test_records_within_the_threshold_and_periodic_runs_are_fitted_whole():
    short = [arbitrary("a", 100_000)]
    parts, roles = assign(short, "rec.h5", (), parse_range(":70000", "--estimation-range"),
                          parse_range("70000:", "--validation-range"))
    budget = budgeted(parts, roles, samples=10_000, above=70_000)
    assert not budget.active and budget.of(parts) == parts and budget.used == budget.available == 70_000
    periodic = [Run(f"p{i}", FS, "multisine", np.zeros(4 * 1024), y=np.zeros(4 * 1024), period=1024, realization=i)
                for i in range(2)]
    parts, roles = assign(periodic, "rec.h5")
    assert set(roles.values()) == {ESTIMATION, VALIDATION}
    budget = budgeted(parts, roles, samples=10, above=0)
    assert budget.available == 0 and not budget.active and budget.of(parts) == parts


# one worker runs the module: its module fixture is built once (xdist --dist loadgroup)
pytestmark = pytest.mark.xdist_group("diagnose_budget")


@pytest.fixture(scope="module")
def both():
    """The same diagnosis of a 40000-sample record within a 4096-sample budget and without one."""
    run = long_record(40_000)
    ranges = {"estimation_range": parse_range(":28000", "--estimation-range"),
              "validation_range": parse_range("28000:", "--validation-range")}
    budget = diagnose(MSD, "nominal.yaml", [run], "long.h5", estimation_budget=4096, budget_above=20_000, **ranges)
    full = diagnose(MSD, "nominal.yaml", [run], "long.h5", estimation_budget=None, **ranges)
    return budget, full


def test_the_budget_names_the_same_cause_with_the_same_validation_error(both):
    budget, full = both
    for result in both:
        assert result.verdict.status == EXPLAINED and result.verdict.winner == "cubic_stiffness", result.headline()
        # k3 from all 28000 samples; 5 % is the tolerance of the 8192-sample test of
        # tests/diagnose/test_diagnose_arbitrary.py, wider than the standard error here
        assert result.winner.estimate.values["k3"] == pytest.approx(K3, rel=0.05)
    # The budget's fits predict with an excess error power sigma^2 p / B (p ~ 5 parameters,
    # B = 4096: 0.1 %, 0.005 dB) before the final refinement on all samples; 0.05 dB is ten times that.
    db = 20 * math.log10(budget.final_score().error_rms / full.final_score().error_rms)
    assert abs(db) < 0.05
    assert budget.summary()["estimation_samples_used"] == 4096
    assert budget.summary()["estimation_samples"] == 28_000
    assert any(f.startswith("estimation budget: the hypotheses were fitted on 4096 of the 28000") for f in budget.findings())
    assert full.summary()["estimation_samples_used"] == 28_000


def test_the_final_refinement_restores_the_precision_of_all_samples(both):
    """The final cause's standard error is that of a fit on all 28000 samples (the same as without
    the budget, within the 20 % a sandwich estimate from other residuals varies by), while the
    other hypotheses, fitted on 4096, have errors about sqrt(28000 / 4096) = 2.6 times larger."""
    budget, full = both
    std_budget, std_full = budget.winner.estimate.std["k3"], full.winner.estimate.std["k3"]
    assert std_budget == pytest.approx(std_full, rel=0.2)
    assert "refined once more on all 28000 estimation samples" in budget.winner.estimate.note
    others = {o.hypothesis.name: o for o in budget.outcomes if o.estimate is not None}
    others_full = {o.hypothesis.name: o for o in full.outcomes if o.estimate is not None}
    ratios = [others[name].estimate.std[p] / others_full[name].estimate.std[p]
              for name in others if name != "cubic_stiffness" and name in others_full
              for p in others[name].hypothesis.parameters
              if math.isfinite(others[name].estimate.std[p]) and others_full[name].estimate.std[p] > 0]
    assert ratios and 1.5 < float(np.median(ratios)) < 4.5
