"""A ``mimo_state_space`` model where a stage takes a model of one input and one output
(``hosidf --model``, ``fit --pnlss``, a pipeline's such step): one line,
exit 2, nothing written. ``report`` draws its page: the modes of A and the frequency response matrix."""

from __future__ import annotations

import math

import yaml

MODEL = {"type": "mimo_state_space", "A": [[-20.0, 5.0], [-5.0, -30.0]], "B": [[1.0, 0.0], [0.5, 2.0]],
         "C": [[1.0, 0.0], [0.0, 1.0]]}
WHAT = ("takes the models of one input u and one output y (a linear one as state_space), not a mimo_state_space "
        "model (inputs u, u2; outputs y, y2); nlsid simulate runs it (docs/mimo.md)")


def test_stages_of_one_input_and_output_refuse_it_in_one_line(run_cli, tmp_path):
    from generators import REPO

    model = tmp_path / "mimo.yaml"
    model.write_text(yaml.safe_dump({"model": MODEL, "free": {"model.A[0][0]": {}}}))
    data = REPO / "sample_data" / "stage.h5"
    # fit --model and diagnose take it (nlsid.fit.mimo_output_error, nlsid.diagnose.mimo) on runs of its
    # inputs and outputs: not these
    for args in (("fit", "--model", model, "--data", data, "-o", tmp_path / "f.yaml"),
                 ("diagnose", "--model", model, "--data", data, "-o", tmp_path / "d")):
        run_cli(*args).assert_one_line_error(
            f"{data}:/runs/ms_l00_m00: has no input 'u2' (the model's inputs: u, u2; the run's channels: none)")
    run_cli("hosidf", data, "--model", model, "-o", tmp_path / "h.h5").assert_one_line_error(
        "analytic HOSIDFs need a wiener, hammerstein, wiener_hammerstein or lpl model, got 'mimo_state_space'")
    run_cli("fit", "--pnlss", "--model", model, "--data", data, "-o", tmp_path / "p.yaml").assert_one_line_error(
        "a PNLSS fit starts from a linear model", "not mimo_state_space")
    pipeline = tmp_path / "pipeline.yaml"
    step = f"hosidf {data} --model mimo.yaml -o h.h5"
    pipeline.write_text(yaml.safe_dump({"root": str(tmp_path), "steps": [step]}))
    run_cli("run", pipeline).assert_one_line_error(f"mimo.yaml: model.type: nlsid hosidf {WHAT}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mimo.yaml", "pipeline.yaml"]  # nothing written


def test_report_draws_the_modes_and_the_response_matrix(run_cli, tmp_path):
    model = tmp_path / "mimo.yaml"
    model.write_text(yaml.safe_dump({"model": MODEL}))
    result = run_cli("report", model, "-o", tmp_path / "m.html", "--json")
    assert result.exit_code == 0, result.stderr
    page = result.json()
    assert page["figures"] == ["bode_matrix"] and page["numbers"]["inputs"] == ["u", "u2"]
    # A has the double eigenvalue -25 (trace -50, determinant 625): 25 / (2 pi) Hz, critically damped
    (mode,) = page["numbers"]["elements"][0]["modes"]
    assert abs(mode["frequency"] - 25 / (2 * math.pi)) < 1e-6 and abs(mode["damping"] - 1) < 1e-6
