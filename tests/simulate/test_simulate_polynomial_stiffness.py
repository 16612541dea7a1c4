"""The ``polynomial_stiffness`` force F = k2 p^2 + k3 p^3 + ... + k10 p^10, against references
computed here, independently of nlsid's simulator:

* continuous: an asymmetric, hardening Duffing oscillator (k2, k3) against classical Runge-Kutta
  with 16 steps per sample on the held input (tests/diagnose/test_diagnose_arbitrary.py's generator):
  second-order convergence of the midpoint-held force to it, and an error far below the force's
  effect;
* discrete: around the ZOH equivalent of 1/(s^2 + s + 10), with terms k2, k3 and k5 (k4 left
  out: a zero inside the coefficients), the documented step (the force held over the sample, read
  at the midpoint of p[k] and the force-free p[k + 1], as ``cubic_stiffness``) as a difference
  equation in a plain loop;
* the mass-spring-damper template with the force equals ``nonlinear_feedback`` around its transfer
  function, and ``{k3}`` alone is ``cubic_stiffness`` bit for bit;
* a config without a nonzero term, or with a term beyond k10, is refused naming the key.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, cont2discrete, lfilter

from diagnose.test_diagnose_arbitrary import FS as DUFFING_FS  # noqa: E402
from diagnose.test_diagnose_arbitrary import duffing  # noqa: E402
from nlsid.errors import InputError  # noqa: E402
from nlsid.io import model_config as mc  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.models import from_config  # noqa: E402
from nlsid.simulate.runs import simulate_run  # noqa: E402

FS = 50.0
TERMS = {"k2": 20.0, "k3": 100.0, "k5": 300.0}  # F(p) = 20 p^2 + 100 p^3 + 300 p^5
DEN = [1.0, 1.0, 10.0]  # p'' + p' + 10 p = u - F(p)


def force(p):
    return sum(value * p ** int(key[1:]) for key, value in TERMS.items())


def excitation(n: int = 1500) -> np.ndarray:
    t = np.arange(n) / FS
    return 3.0 * np.sin(2 * np.pi * 0.4 * t) + 2.0 * np.sin(2 * np.pi * 1.1 * t + 0.3)


def simulate(model: dict, u: np.ndarray, substeps: int | None = None, fs: float = FS) -> np.ndarray:
    cfg = mc.SimulateConfig.model_validate({"model": model})
    return simulate_run(from_config.model(cfg), None, Run("r", fs, "arbitrary", u), substeps).y


def feedback(linear: dict, **terms) -> dict:
    return {"type": "nonlinear_feedback", "linear": linear,
            "nonlinearities": [{"type": "polynomial_stiffness", **(terms or TERMS)}]}


def test_continuous_polynomial_spring_converges_to_the_runge_kutta_reference():
    # p'' + 20 p' + 4e4 p + k2 p^2 + k3 p^3 = 1e4 u (tests/diagnose/test_diagnose_arbitrary.py's generator,
    # 16 Runge-Kutta steps per sample: its own error, about (w h)^4 with w h < 0.02, is below 1e-7
    # of p), as y = G (u - k2' y^2 - k3' y^3) with G = 1e4 / (s^2 + 20 s + 4e4), k' = k / 1e4.
    rng = np.random.default_rng(1)
    u = lfilter(*butter(4, 150 / (DUFFING_FS / 2)), rng.standard_normal(1500))
    u *= 1.0 / np.std(u)
    k2, k3 = 4e3, 6e3
    p_ref = duffing(u, k3, k2, steps=16)
    assert 0.5 < np.max(p_ref) and np.min(p_ref) < -0.5  # both terms act
    num, den, _ = cont2discrete(([1e4], [1.0, 20.0, 4e4]), 1 / DUFFING_FS, method="zoh")
    effect = np.max(np.abs(p_ref - lfilter(np.ravel(num), den, u)))  # what the force changes (exact ZOH, F = 0)
    model = feedback({"type": "transfer_function", "num": [1e4], "den": [1.0, 20.0, 4e4]}, k2=k2 / 1e4, k3=k3 / 1e4)
    errors = {m: np.max(np.abs(simulate(model, u, m, DUFFING_FS) - p_ref)) for m in (2, 8)}
    # Second order (the force held at its midpoint estimate, nlsid.models.forces): 4x finer
    # divides the error by about 16, >= 10 leaving room for higher-order terms. A wrong law would
    # leave its own difference to the reference, which refining does not remove.
    assert errors[2] / errors[8] >= 10
    # And the error is below 1e-3 of the force's effect: a coefficient off by 0.1 % would show.
    assert errors[8] < 1e-3 * effect


def test_discrete_polynomial_spring_follows_its_documented_step():
    # ZOH equivalent of 1 / (s^2 + s + 10): p[k+1] = -a1 p[k] - a2 p[k-1] + b1 w[k] + b2 w[k-1],
    # w = u - F, F[k] = F((p[k] + p_free[k+1]) / 2) with p_free[k+1] the value for F[k] = 0.
    num, den, _ = cont2discrete(([1.0], DEN), 1 / FS, method="zoh")
    b0, b1, b2 = np.ravel(num)
    _, a1, a2 = den
    assert abs(b0) < 1e-15
    u = excitation()
    linear = {"type": "transfer_function", "domain": "discrete", "num": [0.0, float(b1), float(b2)],
              "den": [1.0, float(a1), float(a2)]}
    out = simulate(feedback(linear), u)
    p, w_prev, p_prev = np.zeros(u.size + 1), 0.0, 0.0
    for k in range(u.size):
        free = -a1 * p[k] - a2 * p_prev + b1 * u[k] + b2 * w_prev
        f = force(0.5 * (p[k] + free))
        p_prev, p[k + 1], w_prev = p[k], free - b1 * f, u[k] - f
    reference = p[:-1]
    assert np.max(np.abs(out - reference)) <= 1e-9 * np.max(np.abs(reference))
    assert np.max(np.abs(reference)) > 0.1


def test_template_with_the_force_equals_feedback_around_its_transfer_function():
    # m p'' + c p' + k p = gain u - F(p) is p = G (gain u - F), G = 1 / (m s^2 + c s + k): the two
    # differ only in state coordinates (physical vs companion form), so they agree up to rounding.
    u = excitation()
    template = {"type": "mass_spring_damper", "mass": 2.0, "damping": 2.0, "stiffness": 20.0, "gain": 2.0,
                "nonlinearities": [{"type": "polynomial_stiffness", **TERMS}]}
    general = {**feedback({"type": "transfer_function", "num": [1.0], "den": [2.0, 2.0, 20.0]}), "gain": 2.0}
    a, b = simulate(template, u, 4), simulate(general, u, 4)
    assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(a))


def test_a_cubic_term_alone_is_cubic_stiffness():
    u = excitation(500)
    linear = {"type": "transfer_function", "num": [1.0], "den": DEN}
    cubic = {**feedback(linear), "nonlinearities": [{"type": "cubic_stiffness", "k3": 100.0}]}
    np.testing.assert_array_equal(simulate(feedback(linear, k3=100.0), u, 4), simulate(cubic, u, 4))


@pytest.mark.parametrize("terms, fragment", [({}, "at least one nonzero coefficient"),
                                             ({"k2": 0.0}, "at least one nonzero coefficient"),
                                             ({"k11": 1.0}, "k11")])
def test_bad_polynomial_springs_are_refused(terms, fragment, tmp_path):
    import yaml

    from nlsid.simulate.sweep import load_points

    model = {**feedback({"type": "transfer_function", "num": [1.0], "den": DEN}),
             "nonlinearities": [{"type": "polynomial_stiffness", **terms}]}
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump({"model": model}))
    with pytest.raises(InputError) as info:
        load_points(path)
    message = str(info.value)
    assert "model.nonlinearities[0]" in message and fragment in message and str(path) in message, message
