"""``nonlinear_feedback``: forces fed back around any continuous LTI from force to position.

The friction and cubic-stiffness forces of the mechanical templates, around a linear system given
as a transfer function, checked against independent references:

* Coulomb friction around 1/(m s^2 + c s + k) against the event-located solve_ivp solution of
  tests/simulate/test_simulate_friction.py, with the same error bounds (first order at stick/slip);
* the Duffing system of the book's Exercise 79 as 1/(s^2 + s - 10) with the feedback 100 p^3,
  against solve_ivp (second order);
* the closed-loop two-mass stage with LuGre friction, given as its force-to-motor-position transfer
  function (derived here by hand), against the two-mass template in physical coordinates.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulate.test_simulate_friction import DUFFING_FS, coulomb_reference, duffing_reference  # noqa: E402

from nlsid.errors import InputError  # noqa: E402
from nlsid.io import model_config as mc  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.models import from_config  # noqa: E402
from nlsid.simulate.runs import simulate_run  # noqa: E402
from nlsid.simulate.sweep import load_points  # noqa: E402

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def feedback_model(num, den, forces, **keys) -> dict:
    return {"type": "nonlinear_feedback", "linear": {"type": "transfer_function", "num": num, "den": den},
            "nonlinearities": forces, **keys}


def open_loop(model: dict, u: np.ndarray, fs: float, substeps: int) -> np.ndarray:
    cfg = mc.SimulateConfig.model_validate({"model": model})
    return simulate_run(from_config.model(cfg), None, Run("r", fs, "arbitrary", u), substeps).y


def test_coulomb_around_a_transfer_function_matches_event_based_reference():
    # The case of test_simulate_friction: m = 1, c = 2, k = 400, fc = 0.5 N, 1.5 sin(2 pi t) N.
    m, c, k, fc, fs = 1.0, 2.0, 400.0, 0.5, 1000.0
    u = 1.5 * np.sin(2 * np.pi * np.arange(2000) / 1000)
    x_ref, v_ref = coulomb_reference(m, c, k, fc, u, fs)
    for substeps in (4, 16):
        h = 1.0 / (fs * substeps)
        model = feedback_model([1.0], [m, c, k], [{"type": "coulomb", "fc": fc}])
        x = open_loop(model, u, fs, substeps)
        v = open_loop({**model, "output": "velocity"}, u, fs, substeps)
        # Each of the 8 stick/slip transitions misplaces the force fc by at most one sub-step
        # (nlsid.models.forces): position error <= (fc/m) h^2 and velocity error <= (fc/m) h each.
        assert np.max(np.abs(x - x_ref)) <= 8 * (fc / m) * h**2
        assert np.max(np.abs(v - v_ref)) <= 8 * (fc / m) * h
    assert np.sum(v_ref == 0.0) > 200   # the reference does stick


def test_duffing_as_feedback_around_its_transfer_function():
    # Book Ex 79 (Eq. 5-12): y'' + y' - 10 y + 100 y^3 = u, from rest. The local error of the
    # midpoint-held cubic force is about h^3 |F''| / 12 with |F''| < 1e3 (|y| < 0.5, |y'| < 1,
    # |y''| < 10), summed over 2048 * 8 sub-steps of an orbit that does not amplify errors: < 1e-6.
    u, y_ref = duffing_reference(0.67, DUFFING_FS, 2048, 0.0, 0.0)
    model = feedback_model([1.0], [1.0, 1.0, -10.0], [{"type": "cubic_stiffness", "k3": 100.0}])
    errors = {m: np.max(np.abs(open_loop(model, u, DUFFING_FS, m) - y_ref)) for m in (2, 8)}
    assert errors[8] < 1e-6
    assert errors[2] / errors[8] >= 10   # second order: 4x finer divides the error by about 16


def stage_transfer_function(m1, m2, k, c, c1, c2):
    """Force on the motor to motor position of the two-mass stage (nlsid.models.mechanical), by
    eliminating the load: P2 = (c s + k) P1 / (m2 s^2 + (c + c2) s + k), so
    P1 / F = (m2 s^2 + (c + c2) s + k) / ((m1 s^2 + (c + c1) s + k)(m2 s^2 + (c + c2) s + k) - (c s + k)^2)."""
    load = [m2, c + c2, k]
    den = np.polysub(np.polymul([m1, c + c1, k], load), np.polymul([c, k], [c, k]))
    return load, [float(a) for a in den]


def test_lugre_stage_as_transfer_function_equals_the_two_mass_template():
    # configs/model_stage_lugre.yaml at K_fc = 0.2, its output moved to the motor, against the same
    # plant written as a transfer function. The two differ only in state coordinates (physical vs
    # companion form), so they agree up to rounding and the LuGre Newton tolerance 1e-10 (|v| + vs)
    # per sub-step; measured 8e-13 relative. 1e-8 relative bounds it with margin, while a wrong force
    # column or velocity row changes the output by percent (leaving the friction out: 22 %).
    point = next(p for p in load_points(CONFIGS / "model_stage_lugre.yaml") if abs(p.params["K_fc"] - 0.2) < 2e-3)
    stage = point.config.model.model_dump()
    template = mc.SimulateConfig.model_validate({**point.config.model_dump(), "model": {**stage, "output_at": "motor"}})
    num, den = stage_transfer_function(stage["motor_mass"], stage["load_mass"], stage["stiffness"], stage["damping"],
                                       stage["motor_damping"], stage["load_damping"])
    lugre = {key: value for key, value in stage["nonlinearities"][0].items() if key != "at"}
    general = mc.SimulateConfig.model_validate({**point.config.model_dump(), "model": feedback_model(
        num, den, [lugre], gain=stage["gain"])})
    n = 4096
    run = Run("s", 2048.0, "sine", 6e-3 * np.cos(2 * np.pi * np.arange(2 * n) / n + 0.1), period=n, transient_periods=1,
              frequency=0.5)
    outputs = [simulate_run(from_config.model(cfg), from_config.closed_loop(cfg), run, 4) for cfg in (template, general)]
    scale = np.max(np.abs(outputs[0].y))
    assert np.max(np.abs(outputs[1].y - outputs[0].y)) < 1e-8 * scale
    assert np.max(np.abs(outputs[1].u - outputs[0].u)) < 1e-8 * np.max(np.abs(outputs[0].u))


@pytest.mark.parametrize("model, where, what", [
    (feedback_model([1.0, 1.0], [1.0, 2.0, 3.0], [{"type": "coulomb", "fc": 1.0}]),
     "model.nonlinearities[0]", "relative degree >= 2"),
    (feedback_model([1.0, 1.0], [1.0, 2.0, 3.0], [], output="velocity"), "model.output", "relative degree >= 2"),
    (feedback_model([1.0], [1.0, 2.0, 3.0], [{"type": "coulomb", "fc": 1.0, "at": "motor"}]),
     "model.nonlinearities[0].at", "expected one of plant"),
    (feedback_model([1.0, 0.0, 0.0], [1.0, 2.0, 3.0], []), "model.linear", "strictly proper"),
    ({**feedback_model([1.0], [1.0, 2.0, 3.0], []), "linear": {"type": "transfer_function", "num": [1.0],
                                                              "den": [1.0, 0.5], "domain": "discrete"}},
     "model.linear", "strictly proper"),  # discrete is accepted (tests/io/test_model_language.py), D = 1 is not
    ({**feedback_model([1.0], [1.0, 2.0, 3.0], []), "linear": {"type": "transfer_function", "num": [1.0],
                                                              "den": [1.0, 2.0, 3.0], "delay": 0.01}},
     "model.linear.delay", "model.delay"),
])
def test_bad_feedback_models_are_refused(model, where, what, tmp_path):
    import yaml

    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump({"model": model}))
    point = load_points(path)[0]
    with pytest.raises(InputError) as info:
        try:
            from_config.model(point.config)
        except InputError as exc:
            raise point.locate(exc) from None
    message = str(info.value)
    assert f"{where}:" in message and what in message and str(path) in message, message


def test_example_config_runs_end_to_end(run_cli, tmp_path):
    # configs/model_amplifier_saturation.yaml: nonlinear_feedback with input and output blocks in
    # closed loop, through `nlsid simulate` (reference recorded as r, the command as u).
    from nlsid.io.recording import read_runs, write_recording

    n = 1000
    r = 0.005 * np.cos(2 * np.pi * 2 * np.arange(3 * n) / n)
    excitation = tmp_path / "excitation.h5"
    write_recording(excitation, [Run("s", 1000.0, "sine", r, period=n, transient_periods=1, frequency=2.0)], {"tool": "test"})
    out = tmp_path / "rec.h5"
    result = run_cli("simulate", CONFIGS / "model_amplifier_saturation.yaml", "--excitation", excitation, "-o", out)
    assert result.exit_code == 0, result.stderr
    (run,) = read_runs(out)
    np.testing.assert_array_equal(run.r, r)
    # The command's derivative kick at the start exceeds the 2 V the amplifier passes.
    assert np.max(np.abs(run.u)) > 2.0 and np.all(np.isfinite(run.y))
