"""Units from a CSV header carried through ``import`` and ``diagnose`` to the named parameter.

A mass-spring-damper with a cubic spring, m p'' + c p' + k p + k3 p^3 = gain u (m = 1 kg,
c = 20 N s/m, k = 4e4 N/m, k3 = 6000 N/m^3, gain 1e4 N per N), is driven by low-pass noise (one
estimation and one validation record of 4096 samples at 1024 Hz) and integrated independently of
nlsid's simulator (tests/generators/independent_plant.py: RK4, 8 steps per sample, an error of
order 1e-7 of the output), with white sensor noise of 1e-3 m (the output is about 0.4 m rms). The
CSV files say ``u (N)`` and ``y (m)``; the diagnosis (the cubic-stiffness hypothesis alone, to keep
the test short) must state k3 in N/m^3 in its headline, its terminal table, its summary and its
page, and fit --model must print it so. Without y's unit the headline gives k3 without a unit.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from click.testing import CliRunner

from generators.independent_plant import cubic_response
from nlsid.cli.main import cli
from nlsid.diagnose.hypotheses import LIBRARY

FS, SAMPLES, K3, NOISE = 1024.0, 4096, 6000.0, 1e-3
PLANT = {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4e4, "gain": 1e4}
MODEL = "model: {type: mass_spring_damper, mass: 1.0, damping: 20.0, stiffness: 4.0e4, gain: 1.0e4}\n"


def _write_csv(path, u, y, header: str) -> None:
    t = np.arange(u.size) / FS
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header=header, comments="", fmt="%.10g")


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """est/val CSV files with units on both signals, and the same without y's unit."""
    folder = tmp_path_factory.mktemp("units")
    rng = np.random.default_rng(3)
    U = np.stack([lfilter(*butter(4, 150 / (FS / 2)), rng.standard_normal(SAMPLES)) for _ in range(2)])
    U /= U.std(axis=1, keepdims=True)
    Y = cubic_response({**PLANT, "nonlinearities": [{"type": "cubic_stiffness", "k3": K3}]}, U, FS)
    Y += NOISE * rng.standard_normal(Y.shape)
    for name, u, y in zip(("est", "val"), U, Y):
        _write_csv(folder / f"{name}.csv", u, y, "time (s),u (N),y (m)")
        _write_csv(folder / f"{name}_bare.csv", u, y, "time (s),u (N),y")
    (folder / "model.yaml").write_text(MODEL)
    return folder


def _cli(*args):
    """``nlsid ARGS`` in-process (the run_cli fixture's way, usable in a module fixture)."""
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=True)


@pytest.fixture(scope="module")
def diagnosed(records):
    """Each pair imported and diagnosed once (``--json``; the human output, on stderr, of a second
    run): with the library cut to the cubic spring, since the units are tested, not the ranking."""
    out = {}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("nlsid.diagnose.diagnosis.LIBRARY", tuple(h for h in LIBRARY if h.name == "cubic_stiffness"))
        for suffix in ("", "_bare"):
            for name in ("est", "val"):
                result = _cli("import", records / f"{name}{suffix}.csv", "-o", records / f"{name}{suffix}.h5")
                assert result.exit_code == 0, result.stderr
            args = ("diagnose", "--model", records / "model.yaml", "--data", records / f"est{suffix}.h5",
                    "--validate-on", records / f"val{suffix}.h5", "--no-yardstick")
            result = _cli(*args, "-o", records / f"diag{suffix}", "--json")
            assert result.exit_code == 0, result.stderr
            out[suffix] = json.loads(result.stdout)
        printed = _cli(*args[:4], records / "est.h5", "--validate-on", records / "val.h5", "--no-yardstick",
                       "-o", records / "diag_printed")
        assert printed.exit_code == 0, printed.stderr
        out["printed"] = printed.stderr
    return out


def test_units_of_a_csv_header_reach_the_named_parameter(run_cli, records, diagnosed):
    summary = diagnosed[""]
    assert summary["units"] == {"u": "N", "y": "m"}
    assert summary["verdict"]["winner"] == "cubic_stiffness", summary["headline"]
    (cubic,) = summary["hypotheses"]
    k3, std = cubic["values"]["k3"], cubic["std"]["k3"]
    assert abs(k3 - K3) < 5 * std, (k3, std)  # unbiased within its standard error (generator error ~1e-7)
    assert f"k3 = {k3:.4g} N/m^3" in summary["headline"]
    assert cubic["unit"] == "N/m^3"
    assert cubic["units"] == {"k3": "N/m^3", "mass": "kg", "damping": "N s/m", "stiffness": "N/m"}
    assert summary["chain"][0]["units"]["k3"] == "N/m^3"
    extended = (records / "diag" / "extended_model.yaml").read_text()
    assert re.search(r"k3 = [0-9.]+ \+- [0-9.e+-]+ N/m\^3 \(one standard error\)", extended), extended
    page = records / "page.html"
    assert run_cli("report", records / "diag", "-o", page).exit_code == 0
    assert re.search(r"k3 = [0-9.]+ ± [0-9.e+-]+ N/m\^3", page.read_text())


def test_the_terminal_table_gives_the_unit(diagnosed):
    printed = " ".join(diagnosed["printed"].split())
    assert re.search(r"\(k3 = [0-9.]+ N/m\^3", printed), printed  # the headline
    table = printed.split("Hypotheses")[1]  # the cell wraps at 80 columns: the unit under the value
    assert re.search(r"k3 = [0-9.]+ ", table) and "N/m^3" in table, printed


def test_without_the_unit_of_y_no_unit_is_given(diagnosed):
    summary = diagnosed["_bare"]
    assert summary["units"] == {"u": "N"}
    headline = summary["headline"]
    assert re.search(r"k3 = [0-9.]+[;)]", headline) and "N/m" not in headline, headline
    assert summary["hypotheses"][0]["unit"] == ""
    assert summary["hypotheses"][0]["units"]["k3"] is None


def test_fit_model_prints_each_parameter_with_its_unit(run_cli, records, diagnosed):
    config = records / "free.yaml"
    config.write_text(MODEL.replace("}\n", ", nonlinearities: [{type: cubic_stiffness, k3: 1000.0}]}\n")
                      + "free:\n  model.nonlinearities[0].k3: {}\n  model.damping: {}\n")
    out = records / "fitted.yaml"
    result = run_cli("fit", "--model", config, "--data", records / "est.h5", "--validate-on", records / "val.h5",
                     "-o", out)
    assert result.exit_code == 0, result.stderr
    assert re.search(r"model\.nonlinearities\[0\]\.k3 = [0-9.]+ \+- [0-9.e+-]+ N/m\^3 \(start 1000\)", result.stderr)
    assert re.search(r"model\.damping = [0-9.]+ \+- [0-9.e+-]+ N s/m", result.stderr)
    report = json.loads((records / "fitted.fit.json").read_text())
    assert report["parameters"]["model.nonlinearities[0].k3"]["unit"] == "N/m^3"
    assert report["parameters"]["model.damping"]["unit"] == "N s/m"
    assert "N/m^3" in out.read_text().splitlines()[1]  # the header's "fitted:" line
