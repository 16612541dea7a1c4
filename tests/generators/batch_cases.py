"""Recordings of a small fleet for the `nlsid batch` tests: two machines, three nights each.

Machine A keeps its Coulomb friction at fc = 0.5 N; machine B's rises 0.5, 0.6, 0.7 N over three
nights (one day apart), so a fit of fc drifts on B only. Each recording is a mass-spring-damper
with Coulomb friction under two realizations of a random-odd multisine (256 samples per period,
two periods after one transient period), simulated by `nlsid simulate` with its own noise seed,
and carries the optional root attributes `recorded` and `machine` (docs/formats.md).

The recordings are built once per test session (simulating loads numba's kernels, a few seconds)
into the session's temporary folder, and copied into each test's folder.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import time
from pathlib import Path

import h5py
import yaml
from click.testing import CliRunner

from nlsid.cli.main import cli

DESIGN = {"fs": 256.0, "seed": 3, "unit": "N",
          "multisine": {"period": 256, "band": [1.0, 40.0], "lines": "random-odd", "realizations": 2,
                        "periods": 2, "transient_periods": 1, "rms_levels": [1.0]}}
PLANT = {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0, "gain": 1.0,
         "output": "position"}
FC = {"A": (0.5, 0.5, 0.5), "B": (0.5, 0.6, 0.7)}
NIGHTS = ("2026-05-01T22:00:00Z", "2026-05-02T22:00:00Z", "2026-05-03T22:00:00Z")
# the user's model with the friction level free: `fit --model` estimates fc of each recording
FIT_MODEL = {"model": {**PLANT, "nonlinearities": [{"type": "coulomb", "fc": 0.3}]}, "simulation": {"substeps": 2},
             "free": {"model.nonlinearities[0].fc": {"lower": 1.0e-6, "upper": 5.0}}}
USER_MODEL = {"model": dict(PLANT)}  # without friction: `diagnose` names it
FIT_PARAMETER = "model.nonlinearities[0].fc"
PIPELINE = {"steps": ["bla {recording} -o {out}/bla.h5",
                      "fit --model fit_model.yaml --data {recording} -o {out}/fitted.yaml"]}
_MARK = "complete"


def _build(folder: Path) -> None:
    runner = CliRunner()

    def nlsid(*args: str) -> None:
        result = runner.invoke(cli, ["-q", *map(str, args)])
        assert result.exit_code == 0, (args, result.output, result.exception)

    (folder / "design.yaml").write_text(yaml.safe_dump(DESIGN))
    nlsid("design", folder / "design.yaml", "-o", folder / "excitation.h5")
    for machine, levels in FC.items():
        (folder / "rec" / machine).mkdir(parents=True)
        for night, (fc, recorded) in enumerate(zip(levels, NIGHTS)):
            config = {"model": {**PLANT, "nonlinearities": [{"type": "coulomb", "fc": fc}]},
                      "disturbances": {"y_noise": 2.0e-7, "seed": 100 + 10 * night + ord(machine)},
                      "simulation": {"substeps": 2}}
            path = folder / f"machine_{machine}{night}.yaml"
            path.write_text(yaml.safe_dump(config))
            out = folder / "rec" / machine / f"night{night}.h5"
            nlsid("simulate", path, "--excitation", folder / "excitation.h5", "-o", out)
            with h5py.File(out, "a") as handle:
                handle.attrs["recorded"] = recorded
                handle.attrs["machine"] = f"stage-{machine}"
    (folder / _MARK).write_text("")


def fleet_project(tmp_path_factory, into: Path) -> Path:
    """A project folder ``into`` with ``rec/{A,B}/night{0,1,2}.h5``, ``fit_model.yaml``,
    ``user_model.yaml`` and ``pipeline.yaml`` (bla and fit of each recording)."""
    shared = tmp_path_factory.getbasetemp() / "batch_fleet_recordings"
    if not (shared / _MARK).exists():
        shutil.rmtree(shared, ignore_errors=True)
        shared.mkdir()
        _build(shared)
    into.mkdir(parents=True, exist_ok=True)
    shutil.copytree(shared / "rec", into / "rec")
    (into / "fit_model.yaml").write_text(yaml.safe_dump(FIT_MODEL))
    (into / "user_model.yaml").write_text(yaml.safe_dump(USER_MODEL))
    (into / "pipeline.yaml").write_text(yaml.safe_dump(PIPELINE))
    return into


def add_corrupt_recording(project: Path, relative: str = "rec/B/corrupt.h5") -> Path:
    """A file named .h5 that starts like HDF5 and is not: what a cut copy or a bad disk gives."""
    path = project / relative
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"not an HDF5 file any more " * 40)
    return path


def work_folders(fleet: Path) -> list[Path]:
    """Work folders of tasks left in the batch folder (there must be none after a batch)."""
    return [p for p in fleet.rglob("*") if p.is_dir() and (".partial-" in p.name or ".replaced-" in p.name)]


def kill_first_task(fleet: Path, process, timeout: float = 60.0) -> tuple[int, Path] | None:
    """SIGKILL the worker process of the first task seen running (its work folder names its pid)
    while ``process`` (the batch) runs; return that pid and folder, or None if none was seen."""
    deadline = time.time() + timeout
    while time.time() < deadline and process.poll() is None:
        for folder in work_folders(fleet):
            match = re.search(r"\.partial-(\d+)-", folder.name)
            if match:
                os.kill(int(match.group(1)), signal.SIGKILL)
                return int(match.group(1)), folder
        time.sleep(0.02)
    return None
