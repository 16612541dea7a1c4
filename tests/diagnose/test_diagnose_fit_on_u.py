"""``nlsid diagnose --fit-on u``: a closed loop judged on the command u the controller computes.

In closed loop the controller keeps the position error small, and what the plant gets wrong shows
in the command it needs. The axis is the EMPS stand-in (tests/generators/emps_cases.py: exact
between samples, stick events located, quantised encoder, Coulomb friction and an offset force),
here on short back-and-forth records of four and three moves at different speeds (so that Coulomb
and viscous friction are told apart). The model is viscous only, its mass 4 % high and its damping
4 % low. The diagnosis on u must name Coulomb friction with fc within 3 % of the truth,
and its errors must be those of u: the base model's reported validation error equals the rms of
u - u_model over the validation record, u_model from an independent simulation of the model (the
generator's exact solution with the friction, the offset and the encoder's steps taken out). With
y judged instead, the error would be that of the position, some 1e-5 m instead of some 0.1 V.

A periodic reference with white noise on the recorded command (as a logger's converter adds it):
the noise floor is then the period-to-period noise of u, which the test computes from u alone, and
the true model's error is within it (no discrepancy); judged on y, whose record has no noise
here, the floor would be zero.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from generators import emps_cases as E  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

LOOP = {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                       "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"}}
MASS, DAMPING = 1.04 * E.MASS, 0.96 * E.VISCOUS  # the model's, a few % off
ESTIMATION = ([0.2, 0.05, 0.15, 0.1], [0.125, 0.05, 0.1, 0.03])  # targets (m), top speeds (m/s)
VALIDATION = ([0.15, 0.05, 0.1], [0.08, 0.11, 0.04])
FINE = 1e-15  # an encoder step far below the motion: the generator's axis read exactly

pytestmark = pytest.mark.xdist_group("emps")


def _record(run_id: str, moves) -> Run:
    r = E.move_profile(*moves)
    u, y = E.closed_loop(r)
    return Run(run_id, E.FS, "arbitrary", u, y=y, r=r, units={"u": "V", "y": "m", "r": "m"})


def _viscous_axis(mass: float, damping: float) -> dict:
    return {"model": {"type": "mass_spring_damper", "mass": mass, "damping": damping, "gain": E.GAIN},
            "closed_loop": LOOP}


def test_diagnose_on_u_names_coulomb_and_judges_u(run_cli, tmp_path):
    estimation, validation = _record("estimation", ESTIMATION), _record("validation", VALIDATION)
    est = write_recording(tmp_path / "estimation.h5", [estimation], {"tool": "test"})
    val = write_recording(tmp_path / "validation.h5", [validation], {"tool": "test"})
    config = tmp_path / "axis.yaml"
    config.write_text(yaml.safe_dump(_viscous_axis(MASS, DAMPING), sort_keys=False))
    result = run_cli("--json", "diagnose", "--model", config, "--data", est, "--validate-on", val, "--fit-on", "u",
                     "-o", tmp_path / "d")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["fit_on"] == "u"
    assert "judged on u" in summary["headline"], summary["headline"]
    assert [step["cause"] for step in summary["chain"]] == ["coulomb"], summary["headline"]
    assert summary["chain"][0]["values"]["fc"] == pytest.approx(E.COULOMB, rel=0.03)

    # the base model's validation error is that of u: the record starts at rest, so the model's
    # command is the exact solution of the viscous axis from rest on the recorded reference
    u_model, _ = E.closed_loop(validation.r, mass=MASS, viscous=DAMPING, coulomb=0.0, offset=0.0, encoder=FINE)
    e = validation.u - u_model
    expected = np.sqrt(np.mean((e - e.mean()) ** 2))  # the error without its mean, as diagnose reports it
    # diagnose leaves out the Nyquist line besides the mean: one line of N/2, a share below 1e-3 here
    assert summary["original"]["error_rms"] == pytest.approx(expected, rel=1e-3)
    assert expected > 0.1  # volts: far from the position's error (about 1e-5 m), which y would give
    assert summary["chain"][0]["error_rms"] < 0.05 * expected



def test_the_noise_floor_is_that_of_u_on_periodic_runs(tmp_path):
    """A periodic reference (two realizations of an odd multisine, one transient and four steady
    periods each), the axis without friction (the model is the truth) and white noise of 0.01 V on
    the recorded command only. The floor diagnose reports is the noise in the averaged period of
    u's residual; the model's u being periodic, that residual varies from period to period as u
    does, so the floor is computed here from u alone: per run the mean over the period of u's
    period-to-period variance over P, without the mean and Nyquist lines (Parseval: the AC lines
    1 .. N/2 - 1 that diagnose sums), averaged over the runs. Judged on y, whose record has no
    noise here, the floor would be zero."""
    import nlsid

    N, P, sigma = 512, 4, 0.01
    rng = np.random.default_rng(3)
    bins = np.arange(1, 22, 2)
    runs = []
    for i in range(2):
        X = np.zeros(N // 2 + 1, complex)
        X[bins] = np.exp(2j * np.pi * rng.uniform(size=bins.size))
        period = np.fft.irfft(X, n=N)
        r = np.tile(1e-3 * period / np.sqrt(np.mean(period ** 2)), P + 1)  # 1 mm rms
        u, y = E.closed_loop(r, coulomb=0.0, offset=0.0, encoder=FINE)
        runs.append(Run(f"ms{i}", E.FS, "multisine", u + sigma * rng.standard_normal(u.size), y=y, r=r, period=N,
                        transient_periods=1, realization=i, level=1.0, excited_bins=bins,
                        units={"u": "V", "y": "m", "r": "m"}))
    data = write_recording(tmp_path / "periodic.h5", runs, {"tool": "test"})
    result = nlsid.diagnose(_viscous_axis(E.MASS, E.VISCOUS), data, fit_on="u")
    summary = result.summary()

    powers = []
    for run in runs:
        d = run.u[N:].reshape(P, N)
        d = d - d.mean(axis=0)  # period-to-period deviations
        n = np.arange(N)
        d = d - d.mean(axis=1, keepdims=True) - np.outer(np.mean(d * (-1.0) ** n, axis=1), (-1.0) ** n)
        powers.append(np.mean(np.sum(d ** 2, axis=0) / (P - 1)) / P)
    floor = np.sqrt(np.mean(powers))  # about sigma / sqrt(P) = 0.005 V
    assert summary["fit_on"] == "u"
    assert summary["evidence"]["noise_rms"] == pytest.approx(floor, rel=1e-6)
    assert floor == pytest.approx(sigma / np.sqrt(P), rel=0.1)
    # the true model's error is noise: nothing beyond it (a false alarm has probability 0.001)
    assert summary["verdict"]["status"] == "no_discrepancy", summary["headline"]
