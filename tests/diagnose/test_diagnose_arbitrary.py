"""``diagnose`` on arbitrary records (issue 17 item 1): a Duffing-like oscillator excited by filtered
noise, one estimation record and a separate validation record (``--validate-on``), no periods.

The truth is integrated here by classical Runge-Kutta with 32 steps per sample on the held input
(a method nlsid's simulator does not use; its error, about (h w)^4 ~ 1e-10 of the response, is far
below the noise), starting from rest like the records. The noise level is unknown (one period per
record): the verdict rests on the validation error alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from generators.diagnose_cases import FS, MSD  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402
from nlsid.diagnose.verdict import EXPLAINED, UNDETERMINED  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

K3 = 6e3
STEPS = 32


def duffing(u: np.ndarray, k3: float, k2: float = 0.0, steps: int = STEPS) -> np.ndarray:
    """Position of p'' + 20 p' + 4e4 p + k2 p^2 + k3 p^3 = 1e4 u, u held over each sample, from
    rest, by ``steps`` Runge-Kutta steps per sample."""
    h = 1.0 / (FS * steps)

    def f(p, v, force):
        return v, force - 20.0 * v - 4e4 * p - k3 * p**3 - k2 * p**2

    p = v = 0.0
    y = np.empty(u.size)
    for k, uk in enumerate(u):
        y[k] = p
        force = 1e4 * uk
        for _ in range(steps):
            a1, b1 = f(p, v, force)
            a2, b2 = f(p + h / 2 * a1, v + h / 2 * b1, force)
            a3, b3 = f(p + h / 2 * a2, v + h / 2 * b2, force)
            a4, b4 = f(p + h * a3, v + h * b3, force)
            p, v = p + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4), v + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
    return y


def record(run_id: str, rng, k3: float) -> Run:
    u = lfilter(*butter(4, 150 / (FS / 2)), rng.standard_normal(8192))
    u *= 1.0 / np.std(u)
    y = duffing(u, k3) + 1e-3 * rng.standard_normal(u.size)
    return Run(run_id, FS, "arbitrary", u, y=y)


# one worker runs the module: its module fixture is built once (xdist --dist loadgroup)
pytestmark = pytest.mark.xdist_group("diagnose_arbitrary")


@pytest.fixture(scope="module")
def records():
    rng = np.random.default_rng(3)
    return {k3: (record("estimation", rng, k3), record("validation", rng, k3)) for k3 in (K3, 0.0)}


def test_cubic_stiffness_is_named_on_arbitrary_records(records):
    estimation, validation = records[K3]
    result = diagnose(MSD, "nominal.yaml", [estimation], "est.h5", validate_on=[validation])
    assert result.verdict.status == EXPLAINED and result.verdict.winner == "cubic_stiffness", result.headline()
    assert result.winner.estimate.values["k3"] == pytest.approx(K3, rel=0.05)
    assert not result.evidence.overall.noise_known  # one period per record: judged on validation


def test_a_correct_model_on_arbitrary_records_names_no_cause(records):
    estimation, validation = records[0.0]
    result = diagnose(MSD, "nominal.yaml", [estimation], "est.h5", validate_on=[validation])
    assert result.verdict.status == UNDETERMINED, result.headline()
    assert result.verdict.winner is None


def test_two_arbitrary_records_of_one_recording_split_into_estimation_and_validation(records):
    estimation, validation = records[K3]
    result = diagnose(MSD, "nominal.yaml", [estimation, validation], "rec.h5")
    assert result.verdict.winner == "cubic_stiffness", result.headline()
    assert set(result.roles.values()) == {"estimation", "validation"}


def _discrete(num, den):
    from scipy.signal import cont2discrete

    b, a, _ = cont2discrete((num, den), 1 / FS, method="zoh")
    return {"model": {"type": "transfer_function", "domain": "discrete", "num": [float(v) for v in np.ravel(b)],
                      "den": [float(v) for v in a]}}


@pytest.mark.parametrize("domain", ["continuous", "discrete"])
def test_cubic_feedback_around_a_transfer_function(records, domain):
    """The same data with the model as a transfer function (as ``nlsid fit`` writes one): y = G (u -
    k3' y^3), k3' = k3 / 1e4 in units of u (the force is 1e4 u)."""
    num, den = [1e4], [1.0, 20.0, 4e4]
    nominal = ({"model": {"type": "transfer_function", "num": num, "den": den}} if domain == "continuous"
               else _discrete(num, den))
    estimation, validation = records[K3]
    result = diagnose(nominal, "nominal.yaml", [estimation], "est.h5", validate_on=[validation])
    assert result.verdict.winner == "cubic_feedback", result.headline()
    assert result.winner.estimate.values["k3"] == pytest.approx(K3 / 1e4, rel=0.05)
    assert result.winner.extended["model"]["type"] == "nonlinear_feedback"
