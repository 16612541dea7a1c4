"""``fit --model --fit-on u`` on a closed-loop record that starts in motion (the EMPS stand-in of
tests/generators/emps_cases.py cut where the axis moves; tests/simulate/test_loop_state.py): the
loop's initial state is fitted to the record's start (nlsid.simulate.loop_state), so the axis
is recovered as from a record that starts at rest, within the 1 % of the drive test
(tests/diagnose/test_emps_standin.py: the model error left is the encoder's quantisation), and
the fitted state is reported per run."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from generators import emps_cases as E
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

AXIS = {
    "model": {"type": "mass_spring_damper", "mass": 70.0, "damping": 150.0, "gain": E.GAIN, "force_offset": 0.0,
              "nonlinearities": [{"type": "coulomb", "fc": 10.0}]},
    "closed_loop": {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                                   "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"}},
    "free": {"model.mass": {"lower": 1.0}, "model.damping": {"lower": 0.0},
             "model.nonlinearities[0].fc": {"lower": 1.0e-3}, "model.force_offset": {}},
}


def assert_the_axis(summary: dict) -> None:
    """Mass, viscous, Coulomb and offset (force_offset = -OFFSET) within 1 % of the truth."""
    values = {name: p["value"] for name, p in summary["parameters"].items()}
    assert values["model.mass"] == pytest.approx(E.MASS, rel=0.01)
    assert values["model.damping"] == pytest.approx(E.VISCOUS, rel=0.01)
    assert values["model.nonlinearities[0].fc"] == pytest.approx(E.COULOMB, rel=0.01)
    assert values["model.force_offset"] == pytest.approx(-E.OFFSET, rel=0.01)


def test_fit_on_u_of_a_record_that_starts_in_motion(run_cli, tmp_path):
    r = E.move_profile(*E.ESTIMATION_MOVES)
    u, y = E.closed_loop(r)
    speed = np.abs(np.gradient(r) * E.FS)
    k0 = int(np.argmax(speed > 0.99 * speed.max())) + 30  # in the first move, at its top speed
    run = Run("moving", E.FS, "arbitrary", u[k0:], y=y[k0:], r=r[k0:], units={"u": "V", "y": "m", "r": "m"})
    data = write_recording(tmp_path / "moving.h5", [run], {"tool": "test"})
    config = tmp_path / "axis.yaml"
    config.write_text(yaml.safe_dump(AXIS, sort_keys=False))
    result = run_cli("--json", "fit", "--model", config, "--data", data, "--fit-on", "u",
                     "--estimation-range", f"0:{run.n_samples * 2 // 3}",
                     "--validation-range", f"{run.n_samples * 2 // 3}:{run.n_samples}", "-o", tmp_path / "fitted.yaml")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert_the_axis(summary)
    # the state reported for the record: the drive's memory is the two encoder readings before it
    state = next(r["initial_state"] for r in summary["runs"] if r["role"] == "estimation")
    assert state["controller"] == pytest.approx([y[k0 - 1], y[k0 - 2]], abs=5 * E.ENCODER)
    assert state["command_transient_rms"] > 1.0  # volts: what a start from rest would have missed


def pulse_train(n: int, fs: float, height: float = 1.0, width: float = 0.02, every: float = 0.35) -> np.ndarray:
    """Pulses of alternating sign, ``width`` seconds long, one every ``every`` seconds."""
    t = np.arange(n) / fs
    phase = np.floor(t / every)
    return np.where(t - phase * every < width, height * (-1.0) ** phase, 0.0)


def test_fit_on_u_with_pulses_added_to_the_command_of_a_record_in_motion(run_cli, tmp_path):
    """The issue's drive test: an identification pulse train added to the drive's output and
    recorded in u (and as channel ``pulses``), the record cut in motion: mass, viscous, Coulomb
    and offset within 1 %."""
    r = E.move_profile(*E.VALIDATION_MOVES)
    pulses = pulse_train(r.size, E.FS)
    u, y = E.closed_loop(r, excitation=pulses)
    speed = np.abs(np.gradient(r) * E.FS)
    k0 = int(np.argmax(speed > 0.99 * speed.max())) + 30
    run = Run("pulsed", E.FS, "arbitrary", u[k0:], y=y[k0:], r=r[k0:], units={"u": "V", "y": "m", "r": "m"},
              channels={"pulses": pulses[k0:]})
    data = write_recording(tmp_path / "pulsed.h5", [run], {"tool": "test"})
    axis = {**AXIS, "closed_loop": {**AXIS["closed_loop"], "excitation_channels": {"pulses": 1.0}}}
    config = tmp_path / "axis.yaml"
    config.write_text(yaml.safe_dump(axis, sort_keys=False))
    split = run.n_samples * 2 // 3
    result = run_cli("--json", "fit", "--model", config, "--data", data, "--fit-on", "u",
                     "--estimation-range", f"0:{split}", "--validation-range", f"{split}:{run.n_samples}",
                     "-o", tmp_path / "fitted.yaml")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert_the_axis(summary)
    # the validation part's command error is the encoder's: its quantisation through the drive,
    # q / sqrt(12) sqrt((kp kv + kv fs / 2)^2 + (kv fs / 2)^2) = 2.9 mV rms (tests/simulate/test_excitation_channels.py)
    sigma_u = E.ENCODER / np.sqrt(12) * np.hypot(E.KP * E.KV + E.KV * E.FS / 2, E.KV * E.FS / 2)
    assert summary["u_validation_rms"] < 1.5 * sigma_u
