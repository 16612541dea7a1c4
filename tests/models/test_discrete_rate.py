"""A discrete model's sample rate (``fs`` on a discrete LTI config): a run at another rate is
refused, since its z = e^{s Ts} refers to its own Ts (a mode at nu fs_model would run at nu fs);
a z-domain fit stores the rate it was fitted at; a continuous model takes none."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
import yaml

from nlsid.io.recording import write_recording
from nlsid.io.run import Run
from nlsid.models.lti import TransferFunction

# a discrete first-order low-pass y[k] = 0.9 y[k-1] + 0.1 u[k-1]
MODEL = {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.0, 0.1], "den": [1.0, -0.9],
                   "fs": 1000.0}}


def excitation(tmp_path, fs):
    u = np.random.default_rng(3).standard_normal(400)
    return write_recording(tmp_path / "excitation.h5", [Run("noise", fs, "arbitrary", u)], {"tool": "test"}), u


def test_a_discrete_model_runs_at_its_rate_and_is_refused_at_another(run_cli, tmp_path):
    config = tmp_path / "model.yaml"
    config.write_text(yaml.safe_dump(MODEL))
    data, u = excitation(tmp_path, 1000.0)
    out = tmp_path / "out.h5"
    result = run_cli("simulate", config, "--excitation", data, "-o", out)
    assert result.exit_code == 0, result.stderr
    from nlsid.io.recording import read_runs

    y = read_runs(out)[0].y
    expected = scipy.signal.lfilter([0.0, 0.1], [1.0, -0.9], u)  # an independent evaluation of the same z
    assert np.max(np.abs(y - expected)) < 1e-12

    (tmp_path / "b").mkdir()
    data2, _ = excitation(tmp_path / "b", 2000.0)
    wrong = tmp_path / "wrong.h5"
    result = run_cli("simulate", config, "--excitation", data2, "-o", wrong)
    assert result.exit_code == 2
    assert "model.fs" in result.stderr and "1000 Hz" in result.stderr and "2000 Hz" in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not wrong.exists()


def test_a_continuous_model_with_a_rate_is_refused(run_cli, tmp_path):
    config = tmp_path / "model.yaml"
    config.write_text(yaml.safe_dump({"model": {"type": "transfer_function", "num": [1.0], "den": [1.0, 1.0],
                                                "fs": 1000.0}}))
    data, _ = excitation(tmp_path, 1000.0)
    result = run_cli("simulate", config, "--excitation", data, "-o", tmp_path / "out.h5")
    assert result.exit_code == 2
    assert "fs" in result.stderr and "continuous" in result.stderr


def test_a_z_domain_fit_stores_its_rate_and_an_s_domain_one_none():
    z = TransferFunction("z", np.array([0.0, 0.1]), np.array([1.0, -0.9]), 0, 512.0).config()
    s = TransferFunction("s", np.array([1.0]), np.array([1.0, 1.0]), 0, 512.0).config()
    assert z["fs"] == 512.0 and "fs" not in s


def test_the_model_page_of_a_discrete_resonator_with_its_rate_is_in_hertz(tmp_path):
    """A pole pair z = r e^{+-j theta} (theta = 2 pi 50 / 1000, r = e^{-0.02 theta}): s = ln z fs
    is the continuous pole it samples, so its natural frequency is |ln z| fs / (2 pi), about 50 Hz,
    computed here from the pole itself."""
    from nlsid.report.render_model import render_model

    theta = 2 * np.pi * 50.0 / 1000.0
    r = np.exp(-0.02 * theta)
    den = [1.0, float(-2 * r * np.cos(theta)), float(r * r)]
    config = tmp_path / "model.yaml"
    config.write_text(yaml.safe_dump({"model": {"type": "transfer_function", "domain": "discrete",
                                                "num": [0.0, sum(den)], "den": den,
                                                "fs": 1000.0}}))
    page = render_model(config)
    natural = abs(complex(np.log(r), theta)) * 1000.0 / (2 * np.pi)  # 50.01 Hz
    mode = page.numbers["elements"][0]["modes"][0]
    assert mode["frequency"] == pytest.approx(natural, rel=1e-9)
    assert page.numbers["elements"][0]["fs"] == 1000.0
    assert page.findings == ["linear plant: mode 50 Hz (ζ 0.02)"]  # not "0.05 × fs"
