"""``nlsid diagnose`` of a free mass in closed loop (issue #14): a mass with viscous damping and no
spring (transfer functions with a pole at s = 0, z = 1) under a discrete PD controller with a
one-sample computation delay, the reference recorded as r.

Facts asserted: the right linear model of the loop explains the recording up to its noise (the
data are that model's simulation plus white sensor noise), so the answer is "no discrepancy";
with Coulomb friction in the truth the residual is the friction's, which the Coulomb hypothesis
reproduces (its force is a function of the model's own velocity, fed through the loop).
"""

from __future__ import annotations

import copy
import json

import yaml

FS = 1000.0
MASS, DAMPING = 4.0, 10.0
KP, KD = 2.0e4, 300.0  # crossover about sqrt(KP / MASS) = 71 rad/s, phase lead about 46 degrees

DESIGN = """fs: 1000.0
seed: 5
unit: m
multisine:
  period: 1000
  band: [1.0, 100.0]
  lines: odd
  realizations: 4
  periods: 2
  transient_periods: 2
  rms_levels: [0.01, 0.02]
"""
# The closed-loop poles, roots of MASS s^2 + (DAMPING + KD) s + KP, decay as e^{-38.75 t}: after
# the 2 s of transient the model's noise-free simulation of the loop repeats to the last bit, so
# its input has exactly zero period-to-period variance (the diagnosis runs the model noise-free).

# u[k] = C(z) e[k] with C(z) = z^-1 (KP + KD fs (1 - z^-1)): the PD law computed from e[k-1] and
# e[k-2], one sample late (ascending powers of z^-1, docs/configs.md)
MODEL = {
    "model": {"type": "mass_spring_damper", "mass": MASS, "damping": DAMPING, "stiffness": 0.0,
              "output": "position"},
    "closed_loop": {"controller": {"type": "transfer_function", "domain": "discrete",
                                   "num": [0.0, KP + KD * FS, -KD * FS], "den": [1.0]}},
}


def _diagnose(run_cli, tmp_path, truth: dict) -> dict:
    (tmp_path / "design.yaml").write_text(DESIGN)
    (tmp_path / "model.yaml").write_text(yaml.safe_dump(MODEL))
    (tmp_path / "true.yaml").write_text(yaml.safe_dump(truth))
    for args in (("design", tmp_path / "design.yaml", "-o", tmp_path / "e.h5"),
                 ("simulate", tmp_path / "true.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "r.h5")):
        result = run_cli(*args)
        assert result.exit_code == 0, result.stderr
    result = run_cli("diagnose", "--model", tmp_path / "model.yaml", "--data", tmp_path / "r.h5", "-o",
                     tmp_path / "d", "--json")
    assert result.exit_code == 0, result.stderr
    assert "Traceback" not in result.stderr
    return json.loads(result.stdout)


def test_right_linear_model_of_a_free_mass_loop_shows_nothing_beyond_noise(run_cli, tmp_path):
    truth = copy.deepcopy(MODEL)
    truth["disturbances"] = {"y_noise": 1.0e-5, "seed": 3}
    summary = _diagnose(run_cli, tmp_path, truth)
    assert summary["verdict"]["status"] == "no_discrepancy", summary["headline"]
    assert not summary["evidence"]["error_above_noise"]["significant"]


def test_coulomb_friction_on_a_free_mass_loop_is_named(run_cli, tmp_path):
    truth = copy.deepcopy(MODEL)
    truth["model"]["nonlinearities"] = [{"type": "coulomb", "fc": 20.0}]  # 10 % of KP x the 0.01 m rms
    truth["disturbances"] = {"y_noise": 1.0e-5, "seed": 3}
    summary = _diagnose(run_cli, tmp_path, truth)
    assert summary["evidence"]["error_above_noise"]["significant"]
    assert summary["verdict"]["status"] == "explained" and summary["verdict"]["winner"] == "coulomb", summary["headline"]
    coulomb = next(h for h in summary["hypotheses"] if h["name"] == "coulomb")
    assert abs(coulomb["values"]["fc"] - 20.0) < 2.0  # within 10 % of the hidden level
    # every hypothesis that could not run says why instead of stopping the diagnosis
    assert all(h["scored"] or h["reason"] for h in summary["hypotheses"])
