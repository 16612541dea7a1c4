"""Outputs that would lie about their content are refused before anything is written: non-finite
samples (an absurd design level), and an output name whose suffix is not the format written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from nlsid.errors import InputError
from nlsid.io.recording import container_of, read_runs, write_recording
from nlsid.io.run import Run

DESIGN = {"fs": 1024.0, "seed": 1,
          "multisine": {"period": 256, "band": [1.0, 100.0], "rms_levels": [1.0, 1.0e308]},
          "sines": {"period": 256, "frequencies": [8.0], "amplitudes": [1.0]}}


def _config(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_design_refuses_a_level_that_overflows_naming_its_key(run_cli, tmp_path):
    config = _config(tmp_path, DESIGN)
    result = run_cli("design", config, "-o", tmp_path / "e.h5")
    line = next(n for n, text in enumerate(config.read_text().splitlines(), 1) if "1.0e+308" in text)
    result.assert_one_line_error(f"{config}:{line}: multisine.rms_levels[1]: rms 1e+308 gives non-finite samples",
                                 "nothing was written")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["design.yaml"]
    ok = _config(tmp_path, {**DESIGN, "multisine": {**DESIGN["multisine"], "rms_levels": [1.0, 1.0e300]}})
    assert run_cli("-q", "design", ok, "-o", tmp_path / "e.h5").exit_code == 0
    assert all(np.all(np.isfinite(run.u)) for run in read_runs(tmp_path / "e.h5", require_y=False))


def test_design_refuses_an_infinite_amplitude(run_cli, tmp_path):
    config = tmp_path / "design.yaml"
    config.write_text(yaml.safe_dump({**DESIGN, "multisine": None}).replace("- 1.0", "- .inf"))
    line = next(n for n, text in enumerate(config.read_text().splitlines(), 1) if ".inf" in text)
    run_cli("design", config, "-o", tmp_path / "e.h5").assert_one_line_error(
        f"{config}:{line}: sines.amplitudes[0]: expected a finite number, got .inf")


@pytest.mark.parametrize("container", ["h5", "mcap"])
def test_no_recording_is_written_with_non_finite_samples(tmp_path, container):
    good = Run("a", 100.0, "arbitrary", u=np.ones(8), y=np.ones(8))
    bad = Run("b", 100.0, "arbitrary", u=np.ones(8), y=np.array([1.0] * 5 + [np.inf, np.nan, 1.0]))
    path = tmp_path / f"rec.{container}"
    with pytest.raises(InputError) as error:
        write_recording(path, [good, bad])
    assert str(error.value) == f"{path}:/runs/b/y: 2 NaN or Inf samples (first at index 5); nothing was written"
    assert list(tmp_path.iterdir()) == []


def _commands(tmp_path: Path, output: Path) -> dict[str, list]:
    missing = tmp_path / "missing"
    return {
        "design": ["design", missing.with_suffix(".yaml"), "-o", output],
        "simulate": ["simulate", missing.with_suffix(".yaml"), "--excitation", missing.with_suffix(".h5"), "-o", output],
        "bla": ["bla", missing.with_suffix(".h5"), "-o", output],
        "hosidf": ["hosidf", missing.with_suffix(".h5"), "-o", output],
        "import": ["import", missing.with_suffix(".csv"), "-o", output],
    }


@pytest.mark.parametrize("command", ["design", "simulate", "bla", "hosidf", "import"])
@pytest.mark.parametrize("name", ["e.csv", "e", "e.h5.tmp"])
def test_an_output_suffix_that_is_not_the_format_written_is_refused_first(run_cli, tmp_path, command, name):
    """Before any work: the inputs do not even exist, and the suffix is what is reported."""
    output = tmp_path / name
    suffix = f"suffix '{output.suffix}'" if output.suffix else "no suffix"
    result = run_cli(*_commands(tmp_path, output)[command])
    result.assert_one_line_error(f"{output}: output name has {suffix}, but the file written is HDF5",
                                 ".h5" if command in ("bla", "hosidf") else ".mcap")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["bla", "hosidf"])
def test_result_files_are_hdf5_only(run_cli, tmp_path, command):
    output = tmp_path / "result.mcap"
    run_cli(*_commands(tmp_path, output)[command]).assert_one_line_error(
        f"{output}: output name has suffix '.mcap', but the file written is HDF5: name it .h5 or .hdf5")


@pytest.mark.parametrize("name, container", [("e.hdf5", "hdf5"), ("E.H5", "hdf5"), ("e.mcap", "mcap")])
def test_matching_suffixes_are_accepted(run_cli, tmp_path, name, container):
    config = _config(tmp_path, {**DESIGN, "multisine": {**DESIGN["multisine"], "rms_levels": [1.0]}})
    assert run_cli("-q", "design", config, "-o", tmp_path / name).exit_code == 0
    assert container_of(tmp_path / name) == container
