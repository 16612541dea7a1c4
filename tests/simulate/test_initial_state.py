"""An arbitrary record that does not start at rest (issue 17 item 1: "otherwise from the recorded
start with an estimated initial state"; nlsid/simulate/initial_state.py).

The truth is tests/generators/independent_plant.py's exact ZOH stepping of the mass-spring-damper of
tests/generators/diagnose_cases.py (p'' + 20 p' + 4e4 p = 1e4 u, slowest decay 10 /s) on a long filtered-noise
record, from rest; the records given to nlsid are cut from it 3000 samples in, where the mass is
moving (a transient of about 0.3 against a response of 0.34 rms), with sensor noise of 1e-3 and a
sensor offset.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from generators.diagnose_cases import FS, MSD  # noqa: E402
from generators.independent_plant import linear_response, transfer_function  # noqa: E402
from nlsid.diagnose.diagnosis import diagnose  # noqa: E402
from nlsid.diagnose.simulation import ModelRunner  # noqa: E402
from nlsid.diagnose.verdict import EXPLAINED  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.simulate.initial_state import transient_length  # noqa: E402

NOISE, OFFSET, START, SAMPLES = 1e-3, 0.05, 3000, 8192


def _cut(run_id: str, rng) -> tuple[Run, np.ndarray]:
    """(the record cut mid-run with noise and offset, its noise-free output without the offset)."""
    u = lfilter(*butter(4, 150 / (FS / 2)), rng.standard_normal(START + SAMPLES))
    u /= np.std(u)
    clean = linear_response(*transfer_function(MSD["model"]), u, FS)[START:]
    y = clean + OFFSET + NOISE * rng.standard_normal(SAMPLES)
    return Run(run_id, FS, "arbitrary", u[START:], y=y), clean


def _transient(run: Run, clean: np.ndarray) -> np.ndarray:
    """The free response of the state at the cut: the output less the response from rest to the
    record's own input (superposition, exact for the LTI plant)."""
    return clean - linear_response(*transfer_function(MSD["model"]), run.u, FS)


@pytest.fixture(scope="module")
def records():
    rng = np.random.default_rng(11)
    return _cut("estimation", rng), _cut("validation", rng)


def test_the_record_is_simulated_from_the_fitted_initial_state(records):
    """With the true model (and its offset) the simulation from the fitted initial state is the
    noise-free output but for the noise's share in x0: least squares over the L samples of the
    transient with n = 2 states takes n of the noise's L dimensions, an error of rms
    NOISE sqrt(n / L) there (0.04 NOISE); from rest the start misses the transient."""
    (run, clean), _ = records
    model = ModelRunner.from_data({"model": {**MSD["model"], "output_offset": OFFSET}}, "true.yaml")
    length = transient_length(model.plant, None, run)
    assert length == pytest.approx(np.log(1e6) / 10 * FS, abs=1)  # ln(1e6) / sigma in samples
    estimated = model.simulate(run).y - OFFSET
    from_rest = model.simulate(Run(run.run_id, FS, "arbitrary", run.u)).y - OFFSET  # a run without y: from rest
    start = slice(0, length)
    bound = 0.15 * NOISE  # 4 x NOISE sqrt(2 / L)
    assert np.sqrt(np.mean((estimated[start] - clean[start]) ** 2)) < bound
    assert np.sqrt(np.mean((from_rest[start] - clean[start]) ** 2)) > 30 * NOISE
    np.testing.assert_allclose(estimated[length:], clean[length:], atol=5e-6 * np.max(np.abs(clean)))


def test_a_correct_model_names_no_cause_on_records_cut_mid_run(records):
    """Diagnosed on records that start moving, the correct model is not 'explained' by anything:
    with the initial state estimated, its validation error is the noise (no cause can beat it
    significantly), and the offset is the nuisance it is."""
    (estimation, clean_est), (validation, clean_val) = records
    result = diagnose(MSD, "nominal.yaml", [estimation], "est.h5", validate_on=[validation])
    assert result.verdict.status != EXPLAINED, result.headline()
    assert result.nuisances.values["output_offset"] == pytest.approx(OFFSET, abs=1e-4)
    # the initial state is reported (summary.json nuisances.initial_state) for both records: its
    # free response is the true transient but for the noise's share (0.15 NOISE, as above)
    reported = {entry["run_id"]: entry for entry in result.summary()["nuisances"]["initial_state"]}
    names = [f"{name}[0:{SAMPLES}]" for name in ("estimation", "validation")]  # the split's names of the records
    assert sorted(reported) == names
    for name, (run, clean) in zip(names, ((estimation, clean_est), (validation, clean_val))):
        state, entry = result.nuisances.initial[name], reported[name]
        truth = _transient(run, clean)[:state.samples]
        assert np.sqrt(np.mean((state.transient - truth) ** 2)) < 0.15 * NOISE
        assert entry["transient_rms"] == pytest.approx(np.sqrt(np.mean(truth ** 2)), abs=0.15 * NOISE)
        # x0[0] is the position at the cut, the output's first sample: its error is one sample of
        # the transient's, at most the root of their sum of squares
        assert entry["x0"][0] == pytest.approx(clean[0], abs=0.15 * NOISE * np.sqrt(state.samples))
        assert entry["samples"] == state.samples and len(entry["x0"]) == 2
    assert any("initial state fitted to the start of 2 arbitrary record(s)" in f for f in result.findings())
    # the baseline's validation error without its mean, against the noise: within 3 % (the
    # validation record's 8192 samples give its rms a relative spread of 0.8 %)
    assert result.baseline.error_rms == pytest.approx(NOISE, rel=0.03)
