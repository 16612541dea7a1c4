"""The issue's closed-loop drive test for ``diagnose``: the EMPS stand-in
(tests/generators/emps_cases.py: exact between samples, stick events located, quantised encoder)
with an identification pulse train added to the drive's output (recorded in u and as channel
``pulses``), both records cut where the axis moves. The model is viscous only, its mass and
damping a few % off, and adds the pulses (``closed_loop.excitation_channels``); the records start
from the loop state fitted to their first samples (nlsid.simulate.loop_state). Judged on the
command u, Coulomb friction must be named with fc within 3 % of the truth."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from generators import emps_cases as E
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

ESTIMATION = ([0.2, 0.05, 0.15, 0.1], [0.125, 0.05, 0.1, 0.03])  # targets (m), top speeds (m/s)
VALIDATION = ([0.15, 0.05, 0.1], [0.08, 0.11, 0.04])

pytestmark = pytest.mark.xdist_group("emps")


def pulsed_in_motion(run_id: str, moves) -> Run:
    r = E.move_profile(*moves)
    t = np.arange(r.size) / E.FS
    pulses = np.where(t % 0.35 < 0.02, (-1.0) ** np.floor(t / 0.35), 0.0)  # 20 ms of +-1 V every 0.35 s
    u, y = E.closed_loop(r, excitation=pulses)
    speed = np.abs(np.gradient(r) * E.FS)
    k0 = int(np.argmax(speed > 0.99 * speed.max())) + 30  # in the first move, at its top speed
    return Run(run_id, E.FS, "arbitrary", u[k0:], y=y[k0:], r=r[k0:], units={"u": "V", "y": "m", "r": "m"},
               channels={"pulses": pulses[k0:]})


def test_diagnose_on_u_names_coulomb_on_pulsed_records_that_start_in_motion(run_cli, tmp_path):
    est = write_recording(tmp_path / "estimation.h5", [pulsed_in_motion("estimation", ESTIMATION)], {"tool": "test"})
    val = write_recording(tmp_path / "validation.h5", [pulsed_in_motion("validation", VALIDATION)], {"tool": "test"})
    model = {"model": {"type": "mass_spring_damper", "mass": 1.04 * E.MASS, "damping": 0.96 * E.VISCOUS,
                       "gain": E.GAIN},
             "closed_loop": {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                                            "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"},
                             "excitation_channels": {"pulses": 1.0}}}
    config = tmp_path / "axis.yaml"
    config.write_text(yaml.safe_dump(model, sort_keys=False))
    result = run_cli("--json", "diagnose", "--model", config, "--data", est, "--validate-on", val, "--fit-on", "u",
                     "-o", tmp_path / "d")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert [step["cause"] for step in summary["chain"]] == ["coulomb"], summary["headline"]
    assert summary["chain"][0]["values"]["fc"] == pytest.approx(E.COULOMB, rel=0.03)
    # the loop state fitted to each record's start is reported, the drive's memory among it
    states = {s["run_id"]: s for s in summary["nuisances"]["initial_state"]}
    assert len(states) == 2 and all(len(s["controller"]) == 2 for s in states.values())
