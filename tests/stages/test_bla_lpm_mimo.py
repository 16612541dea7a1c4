"""``nlsid bla`` on arbitrary runs with two inputs and two outputs: the frequency response matrix
by the Local Polynomial Method for several inputs, per level, into ``bla.h5`` and ``--json``.

The recording is written here: independent white-noise inputs u, u2 through scipy ``lfilter``
filters (started from rest, not periodic), white output noise; the truth is ``freqz``. One
record of 4096 samples: the default window of 7 lines leaves q = 7 - 9 < 1 with two inputs, so the
stage widens it to 11 (q = 2) and says so. The numbers are those of ``lpm_mimo`` on the same arrays
(checked to rounding: the stage only groups, cuts and stores), and the truth lies in the 95 %
circles of lines a window apart at 95 % within the binomial band.
"""

from __future__ import annotations

import dataclasses
import math

import h5py
import numpy as np
import pytest
from scipy import signal

import nlsid
from generators.lpm_cases import binomial_band
from nlsid.analysis.frm_levels import NOT_SEPARABLE
from nlsid.analysis.lpm_mimo import lpm_mimo
from nlsid.errors import InputError
from nlsid.io.bla_file import read_bla
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

FS, N = 50.0, 4096
FILTERS = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (0, 1): ([0.3], [1.0, -0.5]),
           (1, 0): ([0.0, 0.5, 0.2], [1.0, -0.2]), (1, 1): ([1.0, -0.4], [1.0, -0.7])}
SIGMA = 0.05


def record(seed: int, collinear: bool = False) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((2, N))
    if collinear:
        u[1] = 0.5 * u[0]
    y = SIGMA * rng.standard_normal((2, N))
    for (i, a), (b, den) in FILTERS.items():
        y[i] += signal.lfilter(b, den, u[a])
    return u, y


def recording(*records) -> Recording:
    runs = [Run(f"noise{m}", FS, "arbitrary", u[0], y=y[0], level=1.0, channels={"u2": u[1], "y2": y[1]},
                inputs=("u", "u2"), outputs=("y", "y2"), units={"u": "N", "u2": "N", "y": "m", "y2": "m"})
            for m, (u, y) in enumerate(records)]
    return Recording(runs, {}, None)


def test_bla_gives_the_lpm_frm_with_bounds_that_cover_the_truth(tmp_path):
    u, y = record(1)
    result = nlsid.bla(recording((u, y)))
    assert result.levels == [] and result.lpm_levels == [] and result.frm_levels == []
    (level,) = result.frm_lpm_levels
    assert (level.inputs, level.outputs, level.run_ids) == (("u", "u2"), ("y", "y2"), ["noise0"])
    assert level.warnings[0] == NOT_SEPARABLE and "widened to 11 lines" in level.warnings[1]
    direct = lpm_mimo(u, y, FS, half_width=5)
    assert level.result.dof == direct.dof == 2 and level.band.size == direct.lines.size  # white inputs: every line
    np.testing.assert_allclose(level.G, direct.G, rtol=1e-12)
    np.testing.assert_allclose(level.var_G, direct.var_G, rtol=1e-12)

    apart = np.arange(5, level.band.size - 5, 11)                      # windows that share no line
    G = np.zeros((apart.size, 2, 2), dtype=complex)
    for (i, a), (b, den) in FILTERS.items():
        G[:, i, a] = signal.freqz(b, den, worN=level.frequency[apart], fs=FS)[1]
    hits = np.abs(level.G[apart] - G) <= level.bounds.radius[apart]
    assert abs(hits.mean() - 0.95) < binomial_band(0.95, apart.size), hits.mean()

    summary = result.summary()["frm_lpm_levels"][0]
    assert summary["noise_floor"] == "upper_bound" and NOT_SEPARABLE in summary["warnings"]
    assert summary["lpm"] == {"lines": 11, "degree": 2, "dof": 2} and summary["records"] == 1
    entry = summary["entries"][0]          # y <- u: |G| = |1 + 0.5 z^-1| / |1 - 0.3 z^-1|, band mean in dB
    z = np.exp(-2j * np.pi * level.frequency / FS)
    assert abs(entry["bla_db"] - np.mean(20 * np.log10(np.abs((1 + 0.5 * z) / (1 - 0.3 * z))))) < 0.05
    assert any(NOT_SEPARABLE in message for message in result.messages())

    content = read_bla(result.write(tmp_path / "bla.h5"))
    assert content["attrs"]["nlsid_format_version"] == 4
    (stored,) = content["frm_lpm_levels"]
    np.testing.assert_array_equal(stored["G"], level.G)
    np.testing.assert_array_equal(stored["bounds"]["radius"], level.bounds.radius)
    assert stored["transient"].shape == (1, level.band.size, 2) and stored["cov_G"].shape == (level.band.size, 4, 4)
    np.testing.assert_array_equal(stored["cov_G_smoothed"], level.result.cov_G_smoothed[level.band])
    assert stored["attrs"]["smoothing_lines"] == level.result.smoothing_lines > 1
    assert stored["attrs"]["inputs"] == ["u", "u2"] and stored["attrs"]["dof"] == 2
    assert math.isclose(stored["attrs"]["u_rms"][1], np.std(u[1]), rel_tol=1e-12)


def test_cli_json_and_one_line_refusal(run_cli, tmp_path):
    path = recording(record(2), record(3)).write(tmp_path / "rec.h5")
    result = run_cli("bla", path, "-o", tmp_path / "bla.h5", "--json")
    assert result.exit_code == 0, result.stderr
    (level,) = result.json()["frm_lpm_levels"]
    assert level["records"] == 2 and level["lpm"]["dof"] == 2 * 7 - 3 * 4   # two records: 7 lines suffice
    assert [(e["output"], e["input"]) for e in level["entries"]] == [("y", "u"), ("y", "u2"), ("y2", "u"), ("y2", "u2")]
    assert NOT_SEPARABLE in level["warnings"]
    assert "cannot separate the nonlinear distortion from the noise" in " ".join(result.stderr.split())
    with h5py.File(tmp_path / "bla.h5") as handle:
        assert sorted(handle) == ["frm_lpm_levels", "levels"]

    bad = recording(record(4, collinear=True)).write(tmp_path / "bad.h5")
    result = run_cli("bla", bad, "-o", tmp_path / "bad_bla.h5")
    result.assert_one_line_error("bad.h5: level 1.0 (arbitrary runs): u: the inputs are collinear over the window")
    assert not (tmp_path / "bad_bla.h5").exists()


def test_records_of_one_level_must_share_inputs_outputs_and_fs():
    u, y = record(5)
    runs = recording((u, y), (u, y)).runs
    for change, fragment in (({"fs": 2 * FS}, "fs 100.0 differ from those of run noise0"),
                             ({"outputs": ("y",)}, "outputs ('y',) differ from those of run noise0")):
        runs[1] = dataclasses.replace(runs[0], run_id="noise1", **change)
        with pytest.raises(InputError) as error:
            nlsid.bla(Recording(list(runs), {}, None))
        assert error.value.where == "recording:/runs/noise1" and fragment in error.value.what, str(error.value)
