"""Input hypotheses of ``diagnose`` of a ``mimo_state_space`` model (:mod:`nlsid.diagnose.mimo`, 5.).

The records come from a plain loop written here, x[k+1] = A x[k] + B p[k], y[k] = C x[k] (poles of
modulus 0.6: one transient period leaves 0.6^256 of the start), p the inputs after the actuator
(np.clip of u2 where a saturation is applied), as Hadamard pairs of experiments (u2 = +b, then -b),
P = 2 steady periods, the inputs with offsets (0.1, -0.05) that the plant sees and the model is
given, white output noise of std 0.02 (y) and 0.05 (y2). A saturation of u2 moves both outputs
(column 2 of B feeds both states), one of y2 only y2."""

from __future__ import annotations

import json

import numpy as np
import yaml

from nlsid.diagnose.mimo import diagnose_mimo
from nlsid.fit.run_split import split_runs
from nlsid.io.run import Run
from nlsid.stages.mimo_diagnosis import MimoDiagnosisResult
from nlsid import Model

from generators.mimo_state_loop import CONFIG, loop

N, P, T = 256, 2, 1
SIGMA = np.array([0.02, 0.05])
OFFSET = np.array([0.1, -0.05])
LEVEL = 0.8
A2, A3 = 0.1, -0.15  # the actuator polynomial p = u + A2 u^2 + A3 u^3 of u2


def records(where: str | None, seed: int = 2, realizations: int = 3) -> list[Run]:
    """``where``: None (linear), "u2" (actuator saturation of u2 at +-LEVEL), "cubic" (the actuator
    polynomial of u2) or "y2" (sensor saturation of y2 at +-1.2, before the noise)."""
    rng = np.random.default_rng(seed)
    out = []
    for r in range(realizations):
        a, b = rng.standard_normal((2, N))
        for e, sign in enumerate((1, -1)):
            U = np.tile(np.stack([a, sign * b]), (1, P + T)) + OFFSET[:, None]
            plant = U.copy()
            if where == "u2":
                plant[1] = np.clip(plant[1], -LEVEL, LEVEL)
            if where == "cubic":
                plant[1] = U[1] + A2 * U[1] ** 2 + A3 * U[1] ** 3
            Y = loop(plant)
            if where == "y2":
                Y[1] = np.clip(Y[1], -1.2, 1.2)
            Y += SIGMA[:, None] * rng.standard_normal(Y.shape)
            out.append(Run(f"r{r}e{e}", 100.0, "multisine", U[0], Y[0], period=N, transient_periods=T,
                           realization=r, experiment=e, excited_bins=np.arange(1, N // 2),
                           channels={"u2": U[1], "y2": Y[1]}, inputs=("u", "u2"), outputs=("y", "y2")))
    return out


def diagnosis(where: str | None):
    estimation, validation = split_runs(records(where))
    return diagnose_mimo(CONFIG, "model", estimation, validation)


def test_an_actuator_saturation_of_u2_is_named_on_the_input_and_carried_by_the_extended_model(tmp_path):
    result = diagnosis("u2")
    cause = result.input_cause
    assert cause is not None and cause.input == "u2" and cause.hypothesis == "input_saturation"
    assert abs(cause.values["upper"] / LEVEL - 1) < 0.05 and abs(-cause.values["lower"] / LEVEL - 1) < 0.05
    assert cause.gained_on() == ["y", "y2"]  # an input block moves every output it drives
    assert all(o.cause is None and o.input_cause is cause for o in result.outputs)  # not output saturations
    assert result.side["chosen"] == "input u2 input_saturation"
    assert result.headline().startswith("input u2: actuator saturation at ") and "gained on y, y2" in result.headline()
    # what the input cause leaves is the noise: each output's error within 1 dB of it (the F(512, 1536)
    # ratio's 0.001 quantiles lie within 0.8 dB)
    assert all(not o.remainder_significant and abs(o.remainder_above_noise_db) < 1.0 for o in result.outputs)
    # the extended model carries it as u2's block and runs as the test's loop with u2 clipped at the levels
    extended = result.extended.config
    assert "output_nonlinearity" not in extended["model"]
    assert extended["model"]["input_nonlinearity"] == {
        "u2": {"type": "saturation", "lower": cause.values["lower"], "upper": cause.values["upper"]}}
    U = np.random.default_rng(9).standard_normal((2, 300))
    clipped = U.copy()
    clipped[1] = np.clip(U[1], cause.values["lower"], cause.values["upper"])
    assert np.max(np.abs(Model.from_dict(extended).simulate(U, 100.0) - loop(clipped))) < 1e-9
    folder = MimoDiagnosisResult(result).write(tmp_path / "diagnosis")
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["input_cause"]["hypothesis"] == "input_saturation" and summary["input_cause"]["input"] == "u2"
    assert summary["models"] == [{"file": "extended_model.yaml", "kind": "extended", "outputs": [], "inputs": ["u2"]}]
    assert yaml.safe_load((folder / "extended_model.yaml").read_text()) == extended


def test_an_output_saturation_of_y2_stays_on_y2():
    result = diagnosis("y2")
    y, y2 = result.outputs
    assert result.input_cause is None and result.side["chosen"] == "outputs y2"
    assert y.cause is None and y2.cause.hypothesis.name == "output_saturation"
    assert result.extended.inputs == [] and "input_nonlinearity" not in result.extended.config["model"]


def test_a_linear_record_gives_no_cause():
    result = diagnosis(None)
    assert result.status == "no_discrepancy" and result.input_cause is None
    assert all(o.cause is None for o in result.outputs) and result.extended is None


def test_an_actuator_polynomial_of_u2_is_named_within_its_cramer_rao_std():
    runs = records("cubic")
    estimation, validation = split_runs(runs)
    result = diagnose_mimo(CONFIG, "model", estimation, validation)
    cause = result.input_cause
    assert cause is not None and cause.input == "u2" and cause.hypothesis == "input_polynomial"
    assert cause.gained_on() == ["y", "y2"] and all(o.cause is None for o in result.outputs)
    # the outputs are linear in (a2, a3): their sensitivities are the loop's responses to u2^2 and u2^3
    # fed in at u2. The fit sees each estimation run's mean period (noise variance sigma_i^2 / P), so
    # the Cramer-Rao covariance is (sum J^T diag(P / sigma_i^2) J)^-1 over those periods
    information = np.zeros((2, 2))
    for run in estimation:
        u2 = run.channels["u2"]
        J = []
        for power in (2, 3):
            feed = np.zeros((2, u2.size))
            feed[1] = u2 ** power
            J.append(loop(feed)[:, -N:].ravel())  # the last (steady) period
        J = np.array(J).T
        weight = np.repeat(P / SIGMA ** 2, N)
        information += J.T @ (weight[:, None] * J)
    std = np.sqrt(np.diag(np.linalg.inv(information)))
    assert abs(cause.values["a2"] - A2) < 4 * std[0] and abs(cause.values["a3"] - A3) < 4 * std[1]
