"""Levels named one way: the index ``fit --level`` takes, beside the input's rms.

Two levels of a mildly cubic filter (input rms 0.5 N and 2 N, three realizations of a random-odd
multisine each, sum of cosines scaled to its rms: tests/generators/bla_cases.py) go through
``nlsid bla``; its table numbers them 0 and 1, and ``fit --level 1`` must say it fitted
"level 1 (rms 2 N)", in its output, its model's header and ``--json`` ``level`` ``{index, rms}``,
the rms equal to the one bla.h5 stores for level_01 (read here with h5py) and to the 2 N the
generator scaled the input to (a multisine without DC: its rms over whole periods is exact).
"""

from __future__ import annotations

import dataclasses
import json
import re

import h5py
import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level
from nlsid.analysis.level_names import level_name
from nlsid.io.recording import write_recording

RMS = (0.5, 2.0)


@pytest.fixture(scope="module")
def bla_file(tmp_path_factory):
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    folder = tmp_path_factory.mktemp("levels")
    rng = np.random.default_rng(5)
    bins = odd_random_bins(1, 41, 3, rng)
    b, a = signal.butter(2, 0.1)

    def system(u):
        x = signal.lfilter(b, a, u)
        return x + 0.05 * x**3

    runs = [dataclasses.replace(run, run_id=f"l{i}_{run.run_id}", units={"u": "N", "y": "m"})
            for i, rms in enumerate(RMS)
            for run in runs_of_level(3, 256, bins, rms, system, 2, rng, noise_y=0.01, level=rms)]
    write_recording(folder / "rec.h5", runs, provenance={"tool": "test"})
    result = CliRunner().invoke(cli, ["bla", str(folder / "rec.h5"), "-o", str(folder / "bla.h5")])
    assert result.exit_code == 0, result.stderr
    return folder / "bla.h5", result.stderr


def test_the_bla_table_numbers_levels_as_fit_takes_them(bla_file):
    _, printed = bla_file
    # the header wraps: "u rms" above "N", beside "level"
    assert re.search(r"u rms\s+\|G\|", printed) and re.search(r"^\s*level\s+N\s+M x P", printed, re.M), printed
    assert re.search(r"^\s*0\s+0\.5\s+3 x 2", printed, re.M), printed
    assert re.search(r"^\s*1\s+2\s+3 x 2", printed, re.M), printed


def test_fit_states_the_level_it_fitted(run_cli, bla_file, tmp_path):
    path, _ = bla_file
    with h5py.File(path, "r") as f:
        rms = float(f["levels/level_01"].attrs["u_rms"])
    assert rms == pytest.approx(RMS[1], rel=1e-9)
    name = f"level 1 (rms {rms:.3g} N)"
    assert name == "level 1 (rms 2 N)" == level_name(1, rms, "N")
    result = run_cli("fit", path, "--order", "0/2", "--level", "1", "-o", tmp_path / "tf.yaml")
    assert result.exit_code == 0, result.stderr
    assert f"fitted to {name}" in " ".join(result.stderr.split()), result.stderr
    assert name in (tmp_path / "tf.yaml").read_text().splitlines()[0]
    as_json = run_cli("fit", path, "--order", "0/2", "--level", "1", "-o", tmp_path / "tf2.yaml", "--json")
    assert as_json.exit_code == 0, as_json.stderr
    assert as_json.json()["level"] == {"index": 1, "rms": rms}
    assert as_json.json()["level"] == json.loads((tmp_path / "tf2.fit.json").read_text())["level"]


def test_the_library_names_the_level_too(bla_file):
    import nlsid

    path, _ = bla_file
    fit = nlsid.fit_tf(str(path), order=(0, 2), level=0)
    assert fit.level == {"index": 0, "rms": pytest.approx(RMS[0], rel=1e-9)}
    assert fit.level_name == "level 0 (rms 0.5 N)"
