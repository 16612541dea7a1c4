"""``nlsid simulate`` of a ``mimo_state_space`` model on an excitation of orthogonal multisines for
two inputs: a recording of format version 3 naming the inputs and outputs, each output with the
noise of its own std; a run lacking an input refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import nlsid
from nlsid.io.model_config import validate_simulate_config
from nlsid.models.from_config import model as build
from nlsid.simulate.mimo import simulate_mimo

MODEL = {"type": "mimo_state_space", "A": [[-20.0, 5.0], [-5.0, -30.0]], "B": [[1.0, 0.0], [0.5, 2.0]],
         "C": [[1.0, 0.0], [0.0, 1.0]], "D": [[0.0, 0.0], [0.3, 0.0]]}
DESIGN = {"fs": 100.0, "seed": 2, "multisine": {"period": 64, "band": [2.0, 40.0], "realizations": 2,
                                                "rms_levels": [1.0]}}


@pytest.fixture
def files(tmp_path):
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump({"model": MODEL, "disturbances": {"y_noise": [0.1, 0.3], "seed": 7}}))
    exc = nlsid.design({**DESIGN, "multisine": {**DESIGN["multisine"], "inputs": 2}})
    return path, exc.write(tmp_path / "exc.h5")


def test_simulate_writes_both_outputs_named_with_their_noise(run_cli, tmp_path, files):
    model, excitation = files
    result = run_cli("simulate", model, "--excitation", excitation, "-o", tmp_path / "sim.h5", "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["runs"] == 4  # 2 realizations x 2 experiments
    quiet = build(validate_simulate_config({"model": MODEL}, None, {}))
    sim = nlsid.read(tmp_path / "sim.h5")
    noise = []
    for run, source in zip(sim.runs, nlsid.read(excitation).runs):
        assert (run.run_id, run.inputs, run.outputs, run.experiment) == (source.run_id, ("u", "u2"), ("y", "y2"),
                                                                         source.experiment)
        np.testing.assert_array_equal(run.input_matrix(), source.input_matrix())  # no input noise configured
        noise.append(run.output_matrix() - simulate_mimo(quiet, source).output_matrix())
    noise = np.concatenate(noise, axis=1)  # 2 outputs x 512 samples
    # each output's noise white with its std (0.1, 0.3): sample variance within 5 sigma of its
    # chi2(512) / 512, the two outputs' noises independent: |correlation| < 5 / sqrt(512)
    assert np.all(np.abs(noise.var(axis=1) / [0.01, 0.09] - 1) < 5 * np.sqrt(2 / 512)), noise.var(axis=1)
    assert abs(np.corrcoef(noise)[0, 1]) < 5 / np.sqrt(512)


def test_a_run_lacking_an_input_is_refused_in_one_line(run_cli, tmp_path, files):
    model, _ = files
    siso = nlsid.design(DESIGN).write(tmp_path / "siso.h5")
    result = run_cli("simulate", model, "--excitation", siso, "-o", tmp_path / "sim.h5")
    result.assert_one_line_error(f"{siso}:/runs/ms_l00_m00: has no input 'u2' (the model's inputs: u, u2; the run's "
                                 "channels: none)")
    assert not (tmp_path / "sim.h5").exists()


def test_design_simulate_bla_gives_the_zero_order_hold_response():
    """Orthogonal multisines through the model in its periodic steady state: the FRM of `bla` is
    the model's response under the hold, computed here by scipy (cont2discrete, then freqz per
    input), to numerical precision (no noise: each experiment's periods are identical)."""
    from scipy import signal

    design = {**DESIGN, "multisine": {**DESIGN["multisine"], "inputs": 2, "periods": 2, "transient_periods": 0}}
    recording = nlsid.Model.from_dict({"model": MODEL}).simulate(nlsid.design(design), steady=True)
    frm = nlsid.bla(recording).frm_levels[0].frm
    a, b, c, d = (np.array(MODEL[key]) for key in "ABCD")
    phi, gamma, *_ = signal.cont2discrete((a, b, c, d), 1 / DESIGN["fs"], method="zoh")
    truth = np.empty_like(frm.G)
    for i in range(2):
        num, den = signal.ss2tf(phi, gamma, c, d, input=i)
        for o in range(2):
            truth[:, o, i] = signal.freqz(num[o], den, worN=frm.frequency, fs=DESIGN["fs"])[1]
    assert np.max(np.abs(frm.G - truth)) < 1e-10 * np.max(np.abs(truth))
