"""How much a verdict explains: a named cause that leaves error above the floor is "partly
explained", a not significant leader is named as such with the data that would decide it, and a
nuisance that moves once the cause is in the model is not reported as a converter fact.

The integration case is a voice-coil-like actuator on the mass-spring-damper of
tests/generators/effect_cases.py: a hardening cubic spring (in the library) and a force factor
that depends on the position, F = gain u (1 + b p) (the Bl(x) of a loudspeaker; in no family of
the library). Its generator is written here: classical Runge-Kutta with 16 steps per sample,
checked against 32 (the fourth-order method's error falls 16-fold, so the difference bounds the
coarser record's error).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numba
import numpy as np
import pytest
from scipy.stats import f as f_dist

from generators import effect_cases
from nlsid.diagnose import nuisances
from nlsid.diagnose import verdict as rules

pytestmark = pytest.mark.yardstick

K3, B = 2e4, 0.2  # N/m^3; 1/m: the force factor changes by 20 % over 1 m (outputs of about 0.35 m rms)


@numba.njit(cache=False)
def _voice_coil(U, fs, substeps, m, c, k, gain, k3, b):
    h = 1.0 / fs / substeps
    out = np.empty_like(U)
    for r in range(U.shape[0]):
        p, v = 0.0, 0.0
        for i in range(U.shape[1]):
            out[r, i] = p
            u = U[r, i]
            for _ in range(substeps):
                a1 = (gain * u * (1 + b * p) - c * v - k * p - k3 * p**3) / m
                p2, v2 = p + 0.5 * h * v, v + 0.5 * h * a1
                a2 = (gain * u * (1 + b * p2) - c * v2 - k * p2 - k3 * p2**3) / m
                p3, v3 = p + 0.5 * h * v2, v + 0.5 * h * a2
                a3 = (gain * u * (1 + b * p3) - c * v3 - k * p3 - k3 * p3**3) / m
                p4, v4 = p + h * v3, v + h * a3
                a4 = (gain * u * (1 + b * p4) - c * v4 - k * p4 - k3 * p4**3) / m
                p = p + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    return out


def voice_coil(U: np.ndarray) -> np.ndarray:
    e = effect_cases
    coarse = _voice_coil(U, e.FS, 16, e.MASS, e.DAMPING, e.STIFFNESS, e.GAIN, K3, B)
    fine = _voice_coil(U, e.FS, 32, e.MASS, e.DAMPING, e.STIFFNESS, e.GAIN, K3, B)
    assert np.max(np.abs(fine - coarse)) < 1e-7 * np.std(fine), "Runge-Kutta not converged"
    return fine


def test_data_to_decide_is_where_the_f_rule_passes():
    """The multiple k of the validation data at which an observed ratio R is significant: the F
    distribution's upper ALPHA point at k nu degrees of freedom equals R (scipy's survival
    function, not the module's quantile), and below 1 of it the ratio is not significant."""
    for ratio, dof in [(10 ** 0.64, 5.0), (1.5, 20.0), (1.05, 400.0)]:
        k = rules.data_to_decide(ratio, dof)
        assert k > 1
        assert f_dist.sf(ratio, k * dof, k * dof) == pytest.approx(rules.ALPHA, rel=1e-4)
        assert f_dist.sf(ratio, 0.9 * k * dof, 0.9 * k * dof) > rules.ALPHA
    assert rules.data_to_decide(100.0, 50.0) == 1.0  # already significant
    assert rules.data_to_decide(0.9, 50.0) == math.inf  # no gain to confirm


def test_partly_and_suggestive_thresholds():
    assert rules.partly(1.5, 1e-5) and not rules.partly(0.8, 1e-9) and not rules.partly(5.0, 0.01)
    assert not rules.partly(float("nan"), 0.0)  # a zero or unknown floor measures no remainder
    # suggestive: above the 90 % point of F(nu, nu), below the 99.9 % one
    dof = 8.0
    assert rules.suggestive(f_dist.isf(0.05, dof, dof), dof)
    assert not rules.suggestive(f_dist.isf(0.2, dof, dof), dof)


def test_a_nuisance_that_moves_is_found():
    before = nuisances.Nuisances({"output_timing": 0.63, "output_offset": 1e-3}, {"output_timing": 0.05,
                                                                                  "output_offset": 1e-4})
    after = nuisances.Nuisances({"output_timing": 0.02, "output_offset": 1.1e-3}, {"output_timing": 0.04,
                                                                                   "output_offset": 1e-4})
    moved = nuisances.moved(before, after, 3.0)
    assert [m["key"] for m in moved] == ["output_timing"]
    assert moved[0]["standard_errors"] == pytest.approx(0.61 / math.hypot(0.05, 0.04))


def test_a_leading_candidate_is_named_with_the_data_that_would_decide_it():
    """Built from its parts: a baseline error power 4.365 times a candidate's (+6.4 dB) on 807
    validation samples whose noise has 5 degrees of freedom: F*_0.999(5, 5) is 29.8 (+14.7 dB),
    so the gain is not significant, but above F_0.9(5, 5) = 3.45 (+5.4 dB): suggestive."""
    from nlsid.diagnose.outcome import Outcome
    from nlsid.diagnose.result import CANDIDATE, Diagnosis
    from nlsid.diagnose.gain import Score
    from nlsid.diagnose.hypotheses import LIBRARY
    from nlsid.diagnose.hypotheses.base import Estimate

    dof, base_rms = 5.0, 1.0
    lead_rms = base_rms / math.sqrt(10 ** 0.64)
    coulomb = next(h for h in LIBRARY if h.name == "coulomb")
    outcome = Outcome(coulomb, Estimate({"fc": 2.0}, {"fc": 0.3}, float("nan")),
                      Score(lead_rms, float("nan"), 6.4, float("nan"), float("nan"), float("nan"), float("nan")),
                      extended={"model": {}})
    verdict = rules.decide(None, base_rms ** 2, [rules.Candidate("coulomb", "friction", 1, lead_rms ** 2)], dof)
    assert verdict.status == rules.UNDETERMINED and verdict.dof == dof
    baseline = Score(base_rms, float("nan"), 0.0, float("nan"), float("nan"), float("nan"), float("nan"))
    diagnosis = Diagnosis("model.yaml", {}, SimpleNamespace(), baseline, [outcome], verdict,
                          baseline=baseline, validation_samples=807)
    from nlsid.diagnose.diagnosis import judge_extent

    judge_extent(diagnosis)
    lead = diagnosis.leading_summary()
    assert lead["name"] == "coulomb" and lead["file"] == CANDIDATE
    assert lead["gain_db"] == pytest.approx(6.4)
    assert lead["needed_db"] == pytest.approx(10 * math.log10(f_dist.isf(rules.ALPHA, dof, dof)))
    k = lead["data_factor"]
    assert f_dist.sf(10 ** 0.64, k * dof, k * dof) == pytest.approx(rules.ALPHA, rel=1e-4)
    assert lead["more_samples"] == pytest.approx((k - 1) * 807)
    assert diagnosis.candidate_header()[0].startswith("Leading candidate") and "NOT" in diagnosis.candidate_header()[0]


def test_a_cause_outside_the_library_leaves_the_verdict_partly_explained(tmp_path):
    """The cubic spring is named (its k3 within 10 % of the truth: the position-dependent force
    factor biases it), and the force factor, which no family holds, leaves the final model far
    above the floor: the status says "partly explained" and the headline how much remains."""
    from nlsid.diagnose.diagnosis import diagnose

    runs = effect_cases.recording(3, voice_coil)
    result = diagnose(effect_cases.MSD, "msd", runs, "voice_coil")
    assert result.chain and result.chain[0].hypothesis.name == "cubic_stiffness", result.headline()
    assert result.chain[0].estimate.values["k3"] == pytest.approx(K3, rel=0.1)
    assert result.verdict.status == rules.PARTLY_EXPLAINED, result.headline()
    explanation = result.summary()["explanation"]
    assert explanation["extent"] == "partial" and explanation["above_floor_db"] > 10
    assert "remain above the noise floor" in result.headline()
    # the yardstick: the force factor is a product of state and input, which the black-box model's
    # degree-2 monomials hold, so it gets significantly closer than the named cause
    assert result.yardstick.fitted and result.yardstick_ahead(result.final_score()), result.headline()
    assert "an effect outside the library remains" in result.headline()
    summary = result.summary()
    assert summary["best_model"] == "black_box_model.yaml"
    assert {m["file"] for m in summary["models"]} == {"extended_model.yaml", "black_box_model.yaml"}
    check_written(result, tmp_path)


def check_written(result, folder):
    """The folder holds both models, the black box simulates as its score says, and the report's
    validation table shows the named causes and the yardstick side by side."""
    import yaml

    from nlsid.diagnose.result import EXTENDED
    from nlsid.diagnose.yardstick import FILE
    from nlsid.report.render_diagnosis import render_diagnosis
    from nlsid.stages.diagnose import DiagnosisResult

    from nlsid.io.diagnosis_file import extended_yaml

    extended = extended_yaml(result.final.extended, result.extended_header())
    black_box = {FILE: extended_yaml(result.yardstick.config, result.yardstick.header("msd"))}
    DiagnosisResult(result, extended, {}, other_models=black_box).write(folder / "d", provenance={})
    assert sorted(p.name for p in (folder / "d").iterdir()) == sorted([EXTENDED, FILE, "results.h5", "summary.json"])
    assert yaml.safe_load((folder / "d" / FILE).read_text())["model"]["type"] == "pnlss"
    table = next(t for t in render_diagnosis(folder / "d").tables if t.caption == "Validation error")
    rows = {row[0]: row for row in table.rows}
    assert rows["black-box yardstick (PNLSS), best"][1] == f"{result.yardstick.score.error_rms:.4g}"
    assert rows["extended model (named causes)"][1] == f"{result.final_score().error_rms:.4g}"


def test_on_a_correct_linear_model_the_yardstick_gains_nothing_significant():
    """The true plant is the user's linear model (exact ZOH response, coloured noise, an offset):
    no discrepancy, no cause, and the black-box model, fitted to the same data, is not
    significantly better than the model with its nuisances."""
    from nlsid.diagnose.diagnosis import diagnose

    runs = effect_cases.recording(5, effect_cases.linear)
    result = diagnose(effect_cases.MSD, "msd", runs, "linear")
    assert result.verdict.status == rules.NO_DISCREPANCY and not result.chain, result.headline()
    assert result.yardstick.fitted and not result.yardstick_ahead(result.baseline)
    assert result.summary()["best_model"] is None  # no written model is significantly better than the user's
