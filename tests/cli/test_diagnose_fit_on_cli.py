"""``diagnose --fit-on u`` refused in open loop, in one line, before anything is read or written:
without a ``closed_loop`` the recorded u is the input the simulation is driven by, so there is no
simulated u to judge. The face refuses it alike, naming its argument."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import nlsid
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

OPEN = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 10.0, "stiffness": 1000.0}}


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(1)
    u = rng.standard_normal(2000)
    data = write_recording(tmp_path / "open.h5", [Run("r0", 1000.0, "arbitrary", u, y=np.cumsum(u) * 1e-3)],
                           {"tool": "test"})
    config = tmp_path / "open.yaml"
    config.write_text(yaml.safe_dump(OPEN))
    return config, data


def test_fit_on_u_is_refused_in_open_loop(run_cli, tmp_path, files):
    config, data = files
    out = tmp_path / "d"
    result = run_cli("diagnose", "--model", config, "--data", data, "--fit-on", "u", "-o", out)
    result.assert_one_line_error("--fit-on", "closed_loop")
    assert not out.exists()


def test_fit_on_other_than_y_or_u_is_refused(run_cli, tmp_path, files):
    config, data = files
    result = run_cli("diagnose", "--model", config, "--data", data, "--fit-on", "r", "-o", tmp_path / "d")
    result.assert_one_line_error("--fit-on")


def test_the_face_refuses_u_in_open_loop_naming_fit_on(files):
    config, data = files
    with pytest.raises(nlsid.InputError) as refused:
        nlsid.diagnose(config, data, fit_on="u")
    assert refused.value.where == "fit_on" and "closed_loop" in refused.value.what
    with pytest.raises(nlsid.InputError) as refused:
        nlsid.diagnose(config, data, fit_on="position")
    assert refused.value.where == "fit_on"


def test_the_terminal_table_names_the_judged_signal(monkeypatch):
    import io
    from types import SimpleNamespace

    from rich.console import Console

    from nlsid.cli import diagnose as diagnose_cli

    fitted = SimpleNamespace(hypothesis=SimpleNamespace(title="Coulomb friction", main="fc"),
                             estimate=SimpleNamespace(values={"fc": 20.4}, note=""), reason="",
                             score=SimpleNamespace(gain_db=41.2, exact=False, distortion_gain_db=float("nan"),
                                                   summary=lambda: {"above_floor_db": float("nan")}),
                             unit=lambda name, units: "V")
    result = SimpleNamespace(headline=lambda: "Cause: Coulomb friction [judged on u]",
                             evidence=SimpleNamespace(findings=lambda: []), outcomes=[fitted], winner=fitted,
                             findings=lambda: [], units={"u": "V", "y": "m"})
    shown = {}
    for signal in ("y", "u"):
        buffer = io.StringIO()
        console = Console(file=buffer, width=100, color_system=None)
        monkeypatch.setattr(diagnose_cli, "settings", lambda: SimpleNamespace(console=console, verbose=0))
        diagnose_cli._print(result, "d/", fit_on=signal)
        shown[signal] = " ".join(buffer.getvalue().split())
    assert "validation runs, error of u" in shown["u"] and "error of u" not in shown["y"]
