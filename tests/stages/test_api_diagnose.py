"""The library face of ``diagnose``: ``nlsid.diagnose(model, rec) -> DiagnosisResult``.

Truth is independent of nlsid's simulator: the "measured" output is the exact stick-slip response
of a mass-spring-damper with hidden Coulomb friction (tests/generators/independent_plant.py, the
motion solved in closed form between stick and slip events), with white sensor noise and input
measurement noise of the levels of tests/generators/diagnose_cases.py. The diagnosis must name the
hidden cause with its value and leave the validation error at the noise floor. The command line's
folder is compared with the face's ``write`` (they must be the same files but the provenance).
"""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

import nlsid
from nlsid.io.recording import write_recording
from nlsid.io.result_file import json_safe
from nlsid.stages.recording import Recording

from generators.diagnose_cases import FS, MSD, NOISE, U_NOISE, excitation  # noqa: E402
from generators.independent_plant import coulomb_response  # noqa: E402

FC = 100.0  # the hidden Coulomb force (N)
STD_BOUND = 4.0  # a Gaussian estimate lies within 4 standard errors of the truth but for p = 6e-5


def _measured(seed: int) -> list:
    """The excitation runs with the output of the true system (MSD with Coulomb friction FC)."""
    rng = np.random.default_rng(seed)
    true = copy.deepcopy(MSD)["model"] | {"nonlinearities": [{"type": "coulomb", "fc": FC}]}
    out = []
    for run in excitation(rng):
        y = coulomb_response(true, run.u, FS) + rng.standard_normal(run.n_samples) * NOISE
        out.append(dataclasses.replace(run, u=run.u + rng.standard_normal(run.n_samples) * U_NOISE, y=y))
    return out


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("diagnose")
    runs = _measured(11)
    write_recording(folder / "rec.h5", runs)
    (folder / "model.yaml").write_text(yaml.safe_dump(MSD))
    steps = []
    result = nlsid.diagnose(MSD, Recording(runs), progress=lambda: steps.append(1))
    return folder, Recording(runs), result, len(steps)


def test_the_hidden_coulomb_friction_is_named_with_its_force(case):
    _, _, d, _ = case
    assert isinstance(d, nlsid.DiagnosisResult)
    assert d.status == "explained" and d.cause == "coulomb"
    assert [step["cause"] for step in d.chain] == ["coulomb"]
    step = d.chain[0]
    truth = {"fc": FC, "mass": 1.0, "damping": 20.0, "stiffness": 4e4}  # MSD with the hidden force
    for name, value in truth.items():
        std = step["std"][name]
        assert 0 < std < 0.01 * value, (name, std)  # the noise (-53 dB) determines every value to 1 %
        assert abs(step["values"][name] - value) < STD_BOUND * std, (name, step["values"][name], std)
    # the extended model leaves the noise: its validation error within 3 dB of the noise floor
    assert abs(step["above_floor_db"]) < 3.0
    assert d.gain_db == pytest.approx(step["gain_db"]) and d.gain_db > 10.0
    assert "Coulomb friction" in d.headline


def test_the_extended_model_simulates_the_measured_output(case):
    """The extended model (a Model) reproduces the measured output to the noise level: the rms of
    measured minus simulated over the steady periods is the sensor noise plus the input noise
    through the plant, both known, and not more."""
    _, rec, d, _ = case
    model = d.extended_model
    assert isinstance(model, nlsid.Model)
    force = model.to_dict()["model"]["nonlinearities"][0]
    assert force["type"] == "coulomb" and abs(force["fc"] - FC) < STD_BOUND * d.chain[0]["std"]["fc"]
    run = rec.runs[-1]
    y = np.asarray(model.simulate(run.u, fs=run.fs)).reshape(-1)
    steady = slice(run.period * run.transient_periods, None)
    residual = run.y[steady] - y[steady]
    # input noise U_NOISE through the resonance (gain up to 2.5 over the band, diagnose_cases) and NOISE
    assert np.sqrt(np.mean(residual**2)) < np.hypot(NOISE, 2.5 * U_NOISE) * 1.2


def test_a_correct_model_has_no_cause():
    """The model with the true friction: nothing to explain, no extended model."""
    runs = _measured(12)
    true = copy.deepcopy(MSD)
    true["model"]["nonlinearities"] = [{"type": "coulomb", "fc": FC}]
    d = nlsid.diagnose(true, Recording(runs))
    assert d.cause is None and d.chain == [] and d.extended_model is None and d.gain_db is None
    assert d.status == "no_discrepancy", d.headline


def test_face_and_command_line_write_the_same_folder(case, run_cli, tmp_path):
    folder, _, _, _ = case
    model, rec = folder / "model.yaml", folder / "rec.h5"
    cli = run_cli("diagnose", "--model", str(model), "--data", str(rec), "-o", str(tmp_path / "cli"), "--json")
    assert cli.exit_code == 0, cli.stderr
    d = nlsid.diagnose(nlsid.Model.from_yaml(model), str(rec))
    d.write(tmp_path / "face")
    files = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert files == sorted(p.name for p in (tmp_path / "face").iterdir()) == [
        "extended_model.yaml", "results.h5", "summary.json"]  # the suite leaves the yardstick out (conftest)
    first, second = (json.loads((tmp_path / name / "summary.json").read_text()) for name in ("cli", "face"))
    assert first.pop("provenance")["inputs"] == second.pop("provenance")["inputs"]
    assert first == second
    printed = json.loads(cli.stdout)
    assert printed.pop("output") == str(tmp_path / "cli")
    written = {k: v for k, v in second.items() if k not in ("nlsid_format", "nlsid_format_version", "files")}
    assert printed == written
    assert json.loads(json.dumps(json_safe(d.summary()))) == printed  # the summary, as JSON writes it
    assert (tmp_path / "cli" / "extended_model.yaml").read_bytes() == (tmp_path / "face" / "extended_model.yaml").read_bytes()
    with h5py.File(tmp_path / "cli" / "results.h5") as a, h5py.File(tmp_path / "face" / "results.h5") as b:
        names = _names(a)
        assert names and names == _names(b)
        for name in names:
            assert dict(a[name].attrs) == dict(b[name].attrs), name
            if isinstance(a[name], h5py.Dataset):
                np.testing.assert_array_equal(a[name][()], b[name][()])
    with pytest.raises(nlsid.InputError, match="force"):
        d.write(tmp_path / "face")


def _names(handle) -> list:
    out = []
    handle.visit(out.append)
    return out


def test_report_plot_and_notebook_views(case, run_cli, tmp_path):
    """The page of ``report`` is the one ``nlsid report`` makes of the written folder (but its source
    line), with the five figures; ``plot`` gives the figures as pyplot figures."""
    import matplotlib.pyplot as plt

    _, _, d, _ = case
    d.write(tmp_path / "d")
    assert run_cli("report", str(tmp_path / "d"), "-o", str(tmp_path / "cli.html")).exit_code == 0
    page = d.report(tmp_path / "face.html").read_text()
    command = (tmp_path / "cli.html").read_text()
    assert page.count("<figure ") == command.count("<figure ") == 5
    assert "Coulomb friction" in page and d.headline.split(";")[0] in page
    figures = d.plot()
    try:
        assert len(figures) == 5 and all(f.number in plt.get_fignums() for f in figures)
    finally:
        for figure in figures:
            plt.close(figure)
    assert "Coulomb friction" in d._repr_html_() and "coulomb" in repr(d)


def test_arguments_are_named_in_messages(case):
    folder, rec, _, _ = case
    with pytest.raises(nlsid.InputError, match=r"^estimation_range: expected a:b"):
        nlsid.diagnose(MSD, rec, estimation_range="x")
    with pytest.raises(nlsid.InputError, match=r"^validation_range: needs estimation_range"):
        nlsid.diagnose(MSD, rec, validation_range="100:200")
    with pytest.raises(nlsid.InputError, match=r"^validate_on: .*pass allow_overlap=True"):
        nlsid.diagnose(MSD, str(folder / "rec.h5"), validate_on=str(folder / "rec.h5"))
    with pytest.raises(nlsid.InputError, match=r"^validate_on: .*\(the same Recording\)"):
        nlsid.diagnose(MSD, rec, validate_on=[rec])
    with pytest.raises(nlsid.InputError, match=r"^model: expected a Model"):
        nlsid.diagnose(3, rec)
    with pytest.raises(nlsid.InputError, match=r"^workers: expected a whole number"):
        nlsid.diagnose(MSD, rec, workers=0)
    with pytest.raises(nlsid.InputError, match=r"^rec: expected a Recording"):
        nlsid.diagnose(MSD, 3.5)
    with pytest.raises(nlsid.InputError, match=r"mass"):
        nlsid.diagnose({"model": {"type": "mass_spring_damper", "mass": -1.0}}, rec)
    no_y = Recording([dataclasses.replace(run, y=None) for run in rec.runs])
    with pytest.raises(nlsid.InputError, match=r"^rec: run 'ms_l0_m0' has no measured output y"):
        nlsid.diagnose(MSD, no_y)


@pytest.mark.parametrize("first", ["import nlsid.diagnose.diagnosis, nlsid; f = nlsid.diagnose",
                                   "import nlsid; f = nlsid.diagnose; import nlsid.diagnose.evidence"])
def test_nlsid_diagnose_is_the_package_and_the_call(first):
    """``nlsid.diagnose`` names both the stage's call and the package of its method: one object,
    callable with the face's signature whichever import came first."""
    import subprocess
    import sys

    probe = (f"{first}; import inspect; print(f is nlsid.diagnose, callable(f), "
             "'validate_on' in inspect.signature(f).parameters, f.diagnosis.Diagnosis.__name__ "
             "if hasattr(f, 'diagnosis') else None)")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.split()[:3] == ["True", "True", "True"], out.stdout + out.stderr


def test_validate_on_a_second_recording(case):
    """With ``validate_on`` every run of ``rec`` is estimated on and the other recording's runs (ids
    ``validate_on[0]:ID`` for an in-memory one) are the validation runs; the cause is the same. The
    two recordings: realizations 0-2 of each level, and realization 3 (the same lines, other phases
    and noise)."""
    _, rec, _, _ = case
    estimation = Recording([run for run in rec.runs if run.realization < 3])
    other = Recording([run for run in rec.runs if run.realization == 3])
    d = nlsid.diagnose(MSD, estimation, validate_on=other)
    split = d.summary()["split"]
    assert split["estimation"] == sorted(estimation.run_ids)
    assert split["validation"] == sorted(f"validate_on[0]:{run_id}" for run_id in other.run_ids)
    assert d.cause == "coulomb" and abs(d.chain[0]["values"]["fc"] - FC) < STD_BOUND * d.chain[0]["std"]["fc"]


def test_progress_is_called_after_each_step(case):
    """Once after the evidence, once after the nuisances, once per hypothesis scored (the sample's
    diagnosis needs one round: the first cause leaves the noise floor), once after the yardstick."""
    _, _, d, steps = case
    scored = sum(o.score is not None for o in d.diagnosis.outcomes)
    assert scored >= 1 and steps == 3 + scored
