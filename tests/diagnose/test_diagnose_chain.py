"""Several effects at once (issue 17 item 6): an input saturation and an even output nonlinearity
on a linear plant. The first cause is accepted, the extended model diagnosed again, and the
second found; the summary's ``chain`` lists both, the extended model holds both.

The measurement is made here without nlsid's simulator: the held, saturated input through the
exact ZOH solution of 1e4 / (s^2 + 20 s + 4e4) (the transfer function of tests/generators/diagnose_cases.py,
Van Loan's block exponential), the output squared in, and white sensor noise.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from generators.diagnose_cases import FS, NOISE, TF, excitation  # noqa: E402
from generators.exact_zoh import zoh  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402

LIMIT, A2 = 1.6, 0.06


def plant(u: np.ndarray) -> np.ndarray:
    a = np.array([[0.0, 1.0], [-4e4, -20.0]])
    phi, gamma = zoh(a, np.array([0.0, 1.0]), 1 / FS)
    x, y = np.zeros(2), np.empty(u.size)
    for k, uk in enumerate(u):
        y[k] = 1e4 * x[0]
        x = phi @ x + gamma * uk
    return y


# one worker runs the module: its module fixture is built once (xdist --dist loadgroup)
pytestmark = pytest.mark.xdist_group("chain")


@pytest.fixture(scope="module")
def diagnosis():
    rng = np.random.default_rng(9)
    runs = []
    for run in excitation(rng):
        x = plant(np.clip(run.u, -LIMIT, LIMIT))
        y = x + A2 * x**2 + NOISE * rng.standard_normal(run.n_samples)
        runs.append(dataclasses.replace(run, y=y))
    return diagnose(TF, "nominal.yaml", runs, "recording.h5")


def test_both_causes_are_named_in_the_chain(diagnosis):
    causes = [o.hypothesis.name for o in diagnosis.chain]
    assert sorted(causes) == ["input_saturation", "quadratic_output"], diagnosis.headline()
    headline = diagnosis.headline()
    assert headline.startswith("Causes: ") and "Input saturation" in headline and "output" in headline


def test_the_final_model_holds_both_and_reaches_the_floor(diagnosis):
    final = diagnosis.final.extended["model"]
    assert final["input_nonlinearity"]["upper"] == pytest.approx(LIMIT, rel=0.05)
    assert final["output_nonlinearity"]["coefficients"][2] == pytest.approx(A2, rel=0.1)
    assert abs(diagnosis.final_score().above_floor_db) < 1.0
    chain = diagnosis.summary()["chain"]
    assert [step["cause"] for step in chain] == [o.hypothesis.name for o in diagnosis.chain]
    assert all(step["gain_db"] > 0 for step in chain)
