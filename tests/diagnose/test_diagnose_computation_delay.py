"""``diagnose`` of a model with ``closed_loop.computation_delay: auto`` (nlsid/diagnose/computation_delay.py):
the delay chosen before the diagnosis, on the estimation runs with the model's nuisances fitted, and
stated in the terminal and in ``summary.json``.

- The first-order loop of tests/generators/delayed_loop.py (exact ZOH solution, the drive's command
  applied 2 samples late, 0.1 % noise on the measured output, two realizations of a periodic
  multisine): the model is the truth but for ``auto``; the delay 2 is chosen, decided by the data,
  and with it the model is the truth, so no cause may be named (a wrong delay would leave a dead
  time to name).
- The EMPS stand-in (tests/generators/emps_cases.py: exact between samples, quantised encoder) with
  its command applied 1 sample late, an arbitrary estimation record and a validation recording:
  the axis written as the benchmark publishes it, with ``auto``, gets the delay 1, decided.
"""

from __future__ import annotations

import io
import json
from types import SimpleNamespace

import pytest
import yaml
from rich.console import Console

from generators import delayed_loop as L
from generators import emps_cases as E
from nlsid.diagnose.computation_delay import resolve
from nlsid.io.recording import write_recording
from nlsid.io.run import Run


def test_diagnose_states_the_chosen_delay_and_names_no_cause(run_cli, tmp_path, monkeypatch):
    import nlsid.cli.diagnose as diagnose_cli

    buffer = io.StringIO()  # the terminal's lines (rich writes to its console, not to click's stdout)
    console = Console(file=buffer, width=80, color_system=None)
    monkeypatch.setattr(diagnose_cli, "settings", lambda: SimpleNamespace(console=console, verbose=0))
    runs = [L.first_order_loop(2, 1.0, 0.5, 2.0, 1e-3, seed=1, run_id="a", realization=0),
            L.first_order_loop(2, 1.0, 0.5, 2.0, 1e-3, seed=2, run_id="b", realization=1)]
    data = write_recording(tmp_path / "loop.h5", runs, {"tool": "test"})
    config = {key: value for key, value in L.loop_config(0.5, 2.0, 1.0, 3).items() if key != "free"}
    model = tmp_path / "loop.yaml"
    model.write_text(yaml.safe_dump(config))
    result = run_cli("diagnose", "--model", model, "--data", data, "--no-yardstick", "-o", tmp_path / "d")
    assert result.exit_code == 0, result.stderr
    assert "computation delay 2 samples (auto, 0..3)" in " ".join(buffer.getvalue().split())
    summary = json.loads((tmp_path / "d" / "summary.json").read_text())
    choice = summary["computation_delay"]
    assert choice["chosen"] == 2 and choice["decided"] and choice["by"] == "nuisances", choice["statement"]
    assert [c["delay"] for c in choice["candidates"]] == [0, 1, 2, 3]
    assert summary["chain"] == [], summary["headline"]


@pytest.mark.xdist_group("emps")
def test_the_emps_axis_gets_its_delay_from_its_nuisance_fit():
    runs = []
    for run_id, profile in (("estimation", E.ESTIMATION_MOVES), ("validation", E.VALIDATION_MOVES)):
        r = E.move_profile(profile[0][:2], profile[1][:2])
        u, y = E.closed_loop(r, delay=1)
        runs.append(Run(run_id, E.FS, "arbitrary", u, y=y, r=r))
    axis = {"model": {"type": "mass_spring_damper", "mass": E.MASS, "damping": E.VISCOUS, "gain": E.GAIN,
                      "force_offset": -E.OFFSET, "nonlinearities": [{"type": "coulomb", "fc": E.COULOMB}]},
            "closed_loop": {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                                           "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"},
                            "computation_delay": "auto"}}
    config, choice = resolve(axis, "axis.yaml", runs[:1], "emps.h5", runs[1:])
    assert choice.chosen == 1 and choice.decided, choice.statement()
    assert config["closed_loop"]["computation_delay"] == 1
    assert not choice.noise_known  # arbitrary records: the winner's rms error bounds the noise
