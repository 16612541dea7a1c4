"""The command line: every stage listed with help and example, version, exit codes, JSON output."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from nlsid import __version__

STAGES = ["design", "simulate", "bla", "hosidf", "fit", "diagnose", "report"]
ROOT = Path(__file__).resolve().parents[2]


def test_help_lists_every_stage(run_cli):
    result = run_cli("--help")
    assert result.exit_code == 0
    for stage in STAGES:
        assert f"  {stage} " in result.stdout


@pytest.mark.parametrize("stage", STAGES)
def test_each_stage_has_help_with_an_example(run_cli, stage):
    result = run_cli(stage, "--help")
    assert result.exit_code == 0
    assert "Example" in result.stdout and f"nlsid {stage} " in result.stdout


def test_version(run_cli):
    result = run_cli("--version")
    assert result.exit_code == 0 and __version__ in result.stdout


def test_version_matches_pyproject():
    assert tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"] == __version__


def test_unknown_option_is_usage_error(run_cli):
    assert run_cli("design", "--no-such-option").exit_code == 2


def test_info_json(run_cli, tmp_path):
    out = tmp_path / "e.h5"
    assert run_cli("-q", "design", ROOT / "configs" / "stage_design.yaml", "-o", out).exit_code == 0
    result = run_cli("info", out, "--json")
    assert result.exit_code == 0
    summary = result.json()
    # configs/stage_design.yaml: 3 levels x 3 realizations + 3 frequencies x 3 amplitudes x 3 repeats.
    assert summary["format"] == "excitation" and len(summary["runs"]) == 3 * 3 + 3 * 3 * 3
    assert summary["runs"][0]["signals"] == ["u"]


def test_console_script_is_installed():
    """The installed `nlsid` entry point runs (the package and its nlsid.cli mapping are installed)."""
    result = subprocess.run([sys.executable, "-c", "from nlsid.cli.entry import main; main()", "--version"],
                            capture_output=True, text=True)
    assert result.returncode == 0 and __version__ in result.stdout


def test_every_package_folder_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {"nlsid.cli"} | {
        ".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "nlsid").rglob("__init__.py")
    }
    found |= {"nlsid.cli." + ".".join(p.parent.relative_to(ROOT / "cli").parts)
              for p in (ROOT / "cli").rglob("__init__.py") if p.parent != ROOT / "cli"}
    assert found == listed
