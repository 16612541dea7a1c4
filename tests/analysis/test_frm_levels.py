"""``nlsid bla`` on runs with several inputs or outputs: the frequency response matrix per level.

The measured data are made here, independently of nlsid's simulator: every output is a sum of
scipy ``lfilter`` responses to the designed inputs, run over the whole record, so that the
transient period (poles of modulus <= 0.5: 0.5^64 ~ 5e-20 after one period) leaves exact periodic
steady state. The truth is ``scipy.signal.freqz`` of the same filters.

- 2 x 2, noise-free, orthogonal multisines from ``nlsid.design(inputs: 2)``: the FRM equals the
  truth to numerical precision (1e-10 relative to |G|), the book's claim for n_u experiments.
- 1 x 3 with output noise (one input, three outputs, as a ground vibration test): each entry is
  the single-input robust BLA of that output computed by ``nlsid.bla`` on its own (another code
  path, ``nlsid.analysis.levels``): G, total and noise variances agree to 1e-9 relative.
- ``bla.h5`` holds the FRM (format version 3); a bad run is one line, exit 2.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import signal

import nlsid
from nlsid.errors import InputError
from nlsid.io.bla_file import read_bla
from nlsid.stages.recording import Recording

FS = 100.0
N = 64
FILTERS_2X2 = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (0, 1): ([0.2], [1.0, -0.5]),
               (1, 0): ([0.0, 0.4], [1.0]), (1, 1): ([1.0], [1.0, 0.2])}


def design(inputs: int, realizations: int = 2, periods: int = 2) -> nlsid.stages.design.Excitation:
    return nlsid.design({"fs": FS, "seed": 3, "multisine": {
        "period": N, "band": [1.0, 45.0], "lines": "odd", "realizations": realizations, "periods": periods,
        "transient_periods": 1, "rms_levels": [1.0], "inputs": inputs}})


def respond(U: np.ndarray, filters: dict, n_outputs: int) -> np.ndarray:
    """Outputs (n_y, n) of the filters (output, input) -> (b, a) driven by the inputs U (n_u, n)."""
    Y = np.zeros((n_outputs, U.shape[1]))
    for (i, a), (b, den) in filters.items():
        Y[i] += signal.lfilter(b, den, U[a])
    return Y


def measured(exc, filters: dict, n_outputs: int, noise: float = 0.0, seed: int = 0) -> Recording:
    """The excitation's runs with outputs y, y2, ... of the filters, plus white output noise."""
    rng = np.random.default_rng(seed)
    names = ("y",) + tuple(f"y{i + 1}" for i in range(1, n_outputs))
    runs = []
    for run in exc.runs:
        Y = respond(run.input_matrix(), filters, n_outputs) + noise * rng.standard_normal((n_outputs, run.n_samples))
        runs.append(dataclasses.replace(run, y=Y[0], channels={**run.channels, **dict(zip(names[1:], Y[1:]))},
                                        outputs=names))
    return Recording(runs, {}, None)


def truth(filters: dict, frequency: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    G = np.zeros((frequency.size, *shape), dtype=complex)
    for (i, a), (b, den) in filters.items():
        G[:, i, a] = signal.freqz(b, den, worN=frequency, fs=FS)[1]
    return G


def test_2x2_noise_free_equals_the_truth(tmp_path):
    result = nlsid.bla(measured(design(inputs=2), FILTERS_2X2, 2))
    assert result.levels == [] and len(result.frm_levels) == 1
    level = result.frm_levels[0]
    assert (level.inputs, level.outputs) == (("u", "u2"), ("y", "y2"))
    assert level.run_ids == [["ms_l00_m00_e00", "ms_l00_m00_e01"], ["ms_l00_m01_e00", "ms_l00_m01_e01"]]
    G = truth(FILTERS_2X2, level.frm.frequency, (2, 2))
    assert np.max(np.abs(level.frm.G - G) / np.abs(G)) < 1e-10

    path = result.write(tmp_path / "bla.h5")
    content = read_bla(path)
    assert content["attrs"]["nlsid_format_version"] == 3 and content["levels"] == []
    (stored,) = content["frm_levels"]
    np.testing.assert_array_equal(stored["G"], level.frm.G)
    assert stored["cov_total"].shape == (level.frm.bins.size, 4, 4)
    assert stored["attrs"]["inputs"] == ["u", "u2"] and stored["attrs"]["n_experiments"] == 2
    assert set(stored["bounds"]) == {"radius", "mag_lo", "mag_hi", "phase_lo", "phase_hi"}
    assert stored["detection"] is not None  # an odd grid: odd and even levels per output


def test_1x3_entries_are_the_single_output_blas():
    filters = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (1, 0): ([0.2], [1.0, -0.5]), (2, 0): ([0.0, 0.4], [1.0, 0.2])}
    exc = design(inputs=1, realizations=4, periods=3)
    recording = measured(exc, filters, 3, noise=1e-2, seed=1)
    (level,) = nlsid.bla(recording).frm_levels
    assert level.outputs == ("y", "y2", "y3") and level.frm.G.shape[1:] == (3, 1)
    for i, name in enumerate(level.outputs):
        single = [dataclasses.replace(run, y=run.output_matrix()[i], channels={}, outputs=("y",))
                  for run in recording.runs]
        robust = nlsid.bla(Recording(single, {}, None), method="frf").levels[0].robust
        np.testing.assert_allclose(level.frm.G[:, i, 0], robust.G, rtol=1e-9)
        np.testing.assert_allclose(level.frm.std_total[:, i, 0] ** 2, robust.var_total, rtol=1e-9)
        np.testing.assert_allclose(level.frm.std_noise[:, i, 0] ** 2, robust.var_noise, rtol=1e-9)


def test_fewer_experiments_than_inputs_is_refused():
    recording = measured(design(inputs=2), FILTERS_2X2, 2)
    recording.runs = [run for run in recording.runs if run.experiment == 0]
    with pytest.raises(InputError, match="1 experiment\\(s\\) \\(runs\\), fewer than the 2 inputs"):
        nlsid.bla(recording)


def test_a_run_that_is_no_multisine_is_refused_in_one_line(run_cli, tmp_path):
    """A sine with several inputs: neither orthogonal multisines nor an arbitrary record."""
    recording = measured(design(inputs=2), FILTERS_2X2, 2)
    first = recording.runs[0]
    recording.runs[0] = dataclasses.replace(first, kind="sine", frequency=FS / N, excited_bins=None,
                                            realization=None, experiment=None)
    path = recording.write(tmp_path / "rec.h5")
    result = run_cli("bla", path, "-o", tmp_path / "bla.h5")
    result.assert_one_line_error("rec.h5:/runs/ms_l00_m00_e00",
                                 "must be a multisine or an arbitrary run for the frequency response matrix")
    assert not (tmp_path / "bla.h5").exists()
    verdict = run_cli("info", path, "--json").json()["stages"]["bla"]  # info says what bla says
    assert not verdict["feeds"] and verdict["reason"] in result.stderr


def test_info_says_bla_feeds_on_orthogonal_multisine_experiments(run_cli, tmp_path):
    path = measured(design(inputs=2), FILTERS_2X2, 2).write(tmp_path / "rec.h5")
    verdict = run_cli("info", path, "--json").json()["stages"]["bla"]
    assert verdict == {"feeds": True, "reason": None,
                       "notes": ["4 runs with several inputs or outputs: the frequency response matrix per level"]}
