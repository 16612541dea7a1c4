"""``closed_loop.computation_delay: auto``: the drive's computation delay chosen from the data
(nlsid/fit/computation_delay.py), on records simulated here independently of nlsid's simulator.

- The EMPS stand-in (tests/generators/emps_cases.py: the axis solved exactly between samples,
  friction events located in closed form, a quantised encoder) with its command applied 1 and 0
  samples late: ``fit --model`` with ``auto`` chooses the delay it was generated with, decided by
  the data, and recovers mass, viscous, Coulomb and offset within 1 % (issue 15's tolerance; what
  limits it is the encoder quantisation the model does not have), and writes the whole number.
- A first-order plant K/(tau s + 1) under a proportional drive, solved exactly at the samples
  (tests/generators/delayed_loop.py), a periodic multisine reference, white noise on the
  measured output fed back as the drive reads it:
  with little noise the delay is decided; with noise whose share of the cost difference
  (2 sigma ||delta||, module docstring) is larger than the difference the delay makes, it is
  stated as not decided by the data.
- A loop unstable with the largest candidate delay (the discrete loop's pole beyond the unit
  circle, from its characteristic polynomial): that candidate is skipped with the reason, the
  others compared.
- ``auto`` in a plain ``simulate`` config is refused in one line.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml

from generators import delayed_loop as L
from generators import emps_cases as E
from nlsid.io.recording import write_recording
from nlsid.io.run import Run
from nlsid.stages.fit import fit_model

AXIS = {
    "model": {"type": "mass_spring_damper", "mass": 80.0, "damping": 180.0, "gain": E.GAIN, "force_offset": 0.0,
              "nonlinearities": [{"type": "coulomb", "fc": 15.0}]},
    "closed_loop": {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                                   "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"},
                    "computation_delay": "auto"},
    "free": {"model.mass": {"lower": 1.0}, "model.damping": {"lower": 0.0},
             "model.nonlinearities[0].fc": {"lower": 1.0e-3}, "model.force_offset": {}},
}


def _emps_records(delay: int, moves: int = 3) -> list[Run]:
    """Estimation and validation records of the stand-in, the first ``moves`` moves of each profile."""
    runs = []
    for run_id, profile in (("estimation", E.ESTIMATION_MOVES), ("validation", E.VALIDATION_MOVES)):
        r = E.move_profile(profile[0][:moves], profile[1][:moves])
        u, y = E.closed_loop(r, delay=delay)
        runs.append(Run(run_id, E.FS, "arbitrary", u, y=y, r=r, units={"u": "V", "y": "m", "r": "m"}))
    return runs


def _check_axis(values: dict) -> None:
    assert values["model.mass"] == pytest.approx(E.MASS, rel=0.01)
    assert values["model.damping"] == pytest.approx(E.VISCOUS, rel=0.01)
    assert values["model.nonlinearities[0].fc"] == pytest.approx(E.COULOMB, rel=0.01)
    assert values["model.force_offset"] == pytest.approx(-E.OFFSET, rel=0.01)  # force_offset = -OFFSET


def test_fit_chooses_the_drives_delay_of_one_sample(run_cli, tmp_path):
    data = write_recording(tmp_path / "emps.h5", _emps_records(1), {"tool": "test"})
    config = tmp_path / "axis.yaml"
    config.write_text(yaml.safe_dump(AXIS, sort_keys=False))
    fitted = tmp_path / "axis_fitted.yaml"
    result = run_cli("--json", "fit", "--model", config, "--data", data, "--fit-on", "u", "-o", fitted)
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    choice = summary["computation_delay"]
    assert choice["chosen"] == 1 and choice["decided"], choice["statement"]
    assert [c["delay"] for c in choice["candidates"]] == [0, 1, 2, 3]
    assert all(c["skipped"] is None for c in choice["candidates"])
    assert choice["cost_difference"] > choice["noise_explains"]
    _check_axis({name: p["value"] for name, p in summary["parameters"].items()})
    written = yaml.safe_load(fitted.read_text())
    assert written["closed_loop"]["computation_delay"] == 1
    report = json.loads((tmp_path / "axis_fitted.fit.json").read_text())
    assert report["computation_delay"]["chosen"] == 1


def test_fit_chooses_no_delay_where_the_drive_has_none():
    records = _emps_records(0)
    from nlsid.stages.recording import Recording

    fit = fit_model(AXIS, Recording(records), validation=["validation"])
    choice = fit.computation_delay
    assert choice.chosen == 0 and choice.decided, choice.statement()
    assert fit.config["closed_loop"]["computation_delay"] == 0
    _check_axis(dict(zip(fit.names, fit.values)))


def _fit_loop(run: Run, config: dict):
    from nlsid.stages.recording import Recording

    # one run fitted, a copy held out: the choice is made on the estimation run alone
    held = dataclasses.replace(run, run_id="held", realization=1)
    return fit_model(config, Recording([run, held]), validation=["held"])


@pytest.mark.parametrize("noise, decided", [(1e-3, True), (0.3, False)])
def test_the_choice_is_stated_as_decided_only_beyond_the_noise(noise, decided):
    # a slow loop (closed-loop pole (1 + K kp) / tau = 6 rad/s) at 1 kHz: one sample of delay changes y little
    run = L.first_order_loop(2, 1.0, 0.5, 2.0, noise)
    fit = _fit_loop(run, L.loop_config(0.5, 2.0, 0.8, 3))
    choice = fit.computation_delay
    assert choice.noise_known
    # the measured noise level: the period-to-period std of y, near the std of the added noise
    assert choice.noise == pytest.approx(noise, rel=0.2)
    assert choice.decided is decided, choice.statement()
    if decided:
        assert choice.chosen == 2
        assert fit.values[0] == pytest.approx(1.0, rel=1e-2)
    else:
        assert "NOT decided by the data" in choice.statement()
        assert any("not decided by the data" in w for w in fit.warnings)


def test_a_delay_that_makes_the_loop_unstable_is_skipped():
    tau, kp, start = 5e-3, 3.0, 1.1
    # the start's loop is unstable with d = 3 alone
    assert [L.loop_radius(d, start, tau, kp) < 1 for d in range(4)] == [True, True, True, False]
    run = L.first_order_loop(1, 1.0, tau, kp, 1e-4)
    fit = _fit_loop(run, L.loop_config(tau, kp, start, 3))
    choice = fit.computation_delay
    assert choice.chosen == 1 and choice.decided, choice.statement()
    skipped = {c.delay: c.reason for c in choice.candidates if not c.fitted}
    assert list(skipped) == [3] and "unstable" in skipped[3]
    assert "3: skipped" in choice.statement()


def test_auto_in_a_plain_simulation_is_refused_in_one_line(run_cli, tmp_path):
    config = tmp_path / "loop.yaml"
    config.write_text(yaml.safe_dump({key: value for key, value in L.loop_config(0.5, 2.0, 1.0, 3).items()
                                      if key != "free"}))
    excitation = write_recording(tmp_path / "r.h5", [Run("r", L.FS, "arbitrary", np.ones(100))], {"tool": "test"})
    out = tmp_path / "out.h5"
    run_cli("simulate", config, "--excitation", excitation, "-o", out).assert_one_line_error(
        "computation_delay: auto is estimated from measured data")
    assert not out.exists()


@pytest.mark.parametrize("written, largest", [("auto", 3), ({"auto": None}, 3), ({"auto": {"max": 5}}, 5),
                                              ({"auto": {"max": 0}}, 0), (2, None), (0, None)])
def test_the_written_forms_give_the_candidates(written, largest):
    from nlsid.fit.computation_delay import candidates_of

    config = L.loop_config(0.5, 2.0, 1.0, 3)
    config["closed_loop"]["computation_delay"] = written
    assert candidates_of(config, "loop.yaml") == largest


@pytest.mark.parametrize("written", [-1, 1.5, True, "automatic", {"auto": {"max": 21}}, {"auto": {"max": -1}},
                                     {"auto": {"largest": 3}}, {"auto": 3}, {"auto": {"max": 2}, "min": 0}])
def test_other_forms_are_refused_in_one_line(run_cli, tmp_path, written):
    config = L.loop_config(0.5, 2.0, 1.0, 3)
    config["closed_loop"]["computation_delay"] = written
    path = tmp_path / "loop.yaml"
    path.write_text(yaml.safe_dump(config))
    data = write_recording(tmp_path / "loop.h5", [L.first_order_loop(0, 1.0, 0.5, 2.0, 1e-3, periods=2)],
                           {"tool": "test"})
    out = tmp_path / "fitted.yaml"
    run_cli("fit", "--model", path, "--data", data, "-o", out).assert_one_line_error(
        "closed_loop.computation_delay", "auto, or {auto: {max: D}}")
    assert not out.exists()
