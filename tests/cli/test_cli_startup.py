"""Start-up cost: importing the command line and printing any command's help loads click and the
standard library only, so `nlsid --help`, `nlsid CMD --help` and shell completion stay fast
(numpy alone takes about 0.15 s to import, scipy.signal about 2 s: ecosystem notes)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numpy", "scipy", "numba", "llvmlite", "matplotlib", "pydantic", "h5py", "mcap", "yaml", "rich", "dask",
         "distributed")
COMMANDS = ("design", "import", "simulate", "bla", "hosidf", "fit", "diagnose", "report", "run", "batch", "info")

PROBE = """
import json, sys
from click.testing import CliRunner
from nlsid.cli.main import cli
args = json.loads(sys.argv[1])
if args is not None:
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
print(json.dumps(sorted(sys.modules)))
"""


def loaded_modules(args: list[str] | None) -> set[str]:
    """The top-level packages a fresh interpreter holds after importing the CLI (and running ``args``)."""
    out = subprocess.run([sys.executable, "-c", PROBE, json.dumps(args)], capture_output=True, text=True, check=True)
    return {name.split(".")[0] for name in json.loads(out.stdout)}


@pytest.mark.parametrize("args", [None, ["--help"], ["--version"], *[[c, "--help"] for c in COMMANDS]],
                         ids=lambda a: "import" if a is None else " ".join(a))
def test_help_loads_no_heavy_package(args):
    heavy = sorted(set(HEAVY) & loaded_modules(args))
    assert heavy == [], f"loaded before any command ran: {heavy}"


def test_the_probe_sees_a_heavy_import():
    """The probe itself works: a command that runs (design) does load numpy."""
    probe = PROBE.replace("from nlsid.cli.main import cli", "from nlsid.cli.main import cli\nimport numpy")
    out = subprocess.run([sys.executable, "-c", probe, "null"], capture_output=True, text=True, check=True)
    assert "numpy" in {name.split(".")[0] for name in json.loads(out.stdout)}
