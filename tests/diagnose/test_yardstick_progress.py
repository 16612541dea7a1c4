"""The yardstick's share of a diagnosis' progress moves while its PNLSS fit runs.

``fit_pnlss(progress=)`` is told (count, budget) at each accepted iterate: the budget is the sum
of the stages' iteration maxima, less what each finished stage did not take; the diagnosis turns
that into whole units of its YARDSTICK_WORK (floor(work x count / budget)), and its last step adds
the rest, so the units told add up to the plan exactly.

Data made here, without nlsid's simulator: a Wiener-Hammerstein cascade by scipy.signal.lfilter
for the fit; for the diagnosis the exact ZOH solution of 1e4 / (s^2 + 20 s + 4e4) (Van Loan's
block exponential, tests/generators/exact_zoh.py) with a quadratic output term (about -31 dB of
the output, the sensor noise -53 dB), which the linear user's model misses and the black box fits.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import signal

from generators.diagnose_cases import FS, NOISE, TF, excitation  # noqa: E402
from generators.exact_zoh import zoh  # noqa: E402
from nlsid.fit.pnlss import fit_pnlss
from nlsid.io.run import Run
from nlsid.models.lti import from_transfer_function
from nlsid.models.pnlss import from_linear

LINEAR, NONLINEAR = 3, 4  # iteration maxima of the linear stage and of each nonlinear stage


def test_the_fit_tells_each_accepted_iterate_against_a_budget_that_only_falls():
    b1, a1 = signal.cheby1(2, 1.0, 0.3)
    b2, a2 = signal.butter(1, 0.15)
    rng = np.random.default_rng(8)
    runs = []
    for k in range(2):
        u = rng.standard_normal(500)
        w = signal.lfilter(b1, a1, u)
        y = signal.lfilter(b2, a2, w + 0.3 * w ** 2 + 0.2 * w ** 3) + 0.01 * rng.standard_normal(u.size)
        runs.append(Run(f"r{k}", 1.0, "arbitrary", u, y))
    linear = from_transfer_function(list(np.polymul(b1, b2)), list(np.polymul(a1, a2)), True, 0.0, "linear")
    start, _ = from_linear(linear, 1.0, (2, 3), (2, 3))
    told = []
    fit = fit_pnlss(start, runs[:1], runs[1:], max_iterations=NONLINEAR, linear_iterations=LINEAR, patience=50,
                    progress=lambda count, budget: told.append((count, budget)))
    # the budget from the fit's own record of its stages: every stage's maximum at the start, then
    # each stage that ended gives back the iterations it did not take
    maxima = {"linear": LINEAR, "nonlinear_states": NONLINEAR, "nonlinear": NONLINEAR}
    accepted = [it.stage for it in fit.iterations[1:]]
    assert start.with_input and not start.lfr and set(accepted) >= {"linear", "nonlinear"}, accepted
    budgets, budget = [], sum(maxima.values())
    for stage in maxima:
        taken = accepted.count(stage)
        budgets += [budget] * taken
        budget -= maxima[stage] - taken
    n = len(accepted)
    assert told == [(k + 1, budgets[k]) for k in range(n)] + [(n, n)]


def _plant(u: np.ndarray) -> np.ndarray:
    """The exact ZOH response of 1e4 / (s^2 + 20 s + 4e4) with y = x + 0.06 x^2."""
    phi, gamma = zoh(np.array([[0.0, 1.0], [-4e4, -20.0]]), np.array([0.0, 1.0]), 1 / FS)
    x, out = np.zeros(2), np.empty(u.size)
    for k, uk in enumerate(u):
        out[k] = 1e4 * x[0]
        x = phi @ x + gamma * uk
    return out + 0.06 * out ** 2


def test_the_yardstick_units_add_up_to_the_plan(monkeypatch):
    """A diagnosis without hypotheses (the library emptied: only the yardstick's work is of
    interest) and a three-iteration yardstick: the units told during its fit and at its end add up
    to YARDSTICK_WORK, the work done to the work planned, all whole numbers."""
    import nlsid.diagnose.diagnosis as diagnosis
    import nlsid.diagnose.yardstick as yardstick

    monkeypatch.setattr(diagnosis, "LIBRARY", ())
    for name in ("MIN_ITERATIONS", "MAX_ITERATIONS", "LINEAR_ITERATIONS"):
        monkeypatch.setattr(yardstick, name, 3)
    rng = np.random.default_rng(6)
    runs = []
    for run in excitation(rng, levels=(1.0,), realizations=2, periods=1, transient=1):
        runs.append(dataclasses.replace(run, y=_plant(run.u) + NOISE * rng.standard_normal(run.n_samples)))
    calls = []
    result = diagnosis.diagnose(TF, "model.yaml", runs, "rec.h5", yardstick=True,
                                step=lambda name, work, planned: calls.append((name, work, planned)))
    assert result.yardstick.fitted, result.yardstick.reason
    assert all(isinstance(v, int) for call in calls for v in call[1:])
    during = [work for name, work, _ in calls if name == yardstick.PROGRESS_STEP]
    name, last_work, last_planned = calls[-1]
    assert name == "yardstick" and last_planned == 0
    assert len(during) >= 2 and all(work > 0 for work in during)  # the bar moves during the fit
    assert sum(during) + last_work == diagnosis.YARDSTICK_WORK
    planned = sum(p for *_, p in calls)
    assert sum(w for _, w, _ in calls) == planned == diagnosis.planned_work(TF, "model.yaml", True)
