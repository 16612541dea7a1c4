"""``nlsid design`` with ``multisine.inputs: n_u``: full random orthogonal multisines (book (6-118)).

Each realization is n_u runs (experiments), each holding every input (u, then channels u2 ..).
The test takes one period of each input of each experiment, computes its DFT with numpy (1/N
scaling, nlsid's convention), and checks the book's orthogonality at every excited line:
``U(k) U(k)^H = n_u |U_r|^2 I`` with column e of U(k) the input vector of experiment e and
``|U_r| = rms / sqrt(2 F)`` (a flat multisine of F lines, Parseval). Round-off in an N-point FFT is
about 1e-15 relative, so 1e-12 is "exact". Lines not excited must hold nothing (same tolerance).
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import yaml

import nlsid
from nlsid.io.recording import read_runs

FS = 128.0
N = 64
RMS = 0.7


def config(**multisine) -> dict:
    return {"fs": FS, "seed": 5, "multisine": {"period": N, "band": [2.0, 40.0], "lines": "odd", "realizations": 2,
                                               "periods": 2, "transient_periods": 1, "rms_levels": [RMS], **multisine}}


@pytest.mark.parametrize("n_inputs", [2, 3])
def test_experiments_are_orthogonal_at_every_excited_line(n_inputs):
    exc = nlsid.design(config(inputs=n_inputs))
    bins = np.array(exc.design["multisine"]["excited_bins"])
    names = ["u"] + [f"u{r}" for r in range(2, n_inputs + 1)]
    assert len(exc.runs) == 2 * n_inputs
    magnitude2 = RMS**2 / (2 * bins.size)                    # |U_r|^2 of a flat multisine of rms RMS
    others = np.setdiff1d(np.arange(1, N // 2), bins)
    for m in range(2):
        runs = [run for run in exc.runs if run.realization == m]
        assert [run.run_id for run in runs] == [f"ms_l00_m{m:02d}_e{e:02d}" for e in range(n_inputs)]
        assert [run.experiment for run in runs] == list(range(n_inputs))
        spectra = []
        for run in runs:
            assert run.inputs == tuple(names) and sorted(run.channels) == names[1:]
            x = run.input_matrix()
            assert x.shape == (n_inputs, 3 * N)
            periods = x.reshape(n_inputs, 3, N)
            np.testing.assert_allclose(periods, np.broadcast_to(periods[:, :1], periods.shape), rtol=0, atol=1e-12)
            np.testing.assert_allclose(np.sqrt(np.mean(periods[:, 0] ** 2, axis=1)), RMS, rtol=1e-12)
            X = np.fft.fft(periods[:, 0], axis=1) / N
            assert np.max(np.abs(X[:, others])) < 1e-12 * np.sqrt(magnitude2)
            spectra.append(X[:, bins])                       # (inputs, F)
        U = np.stack(spectra, axis=-1)                       # (inputs, F, experiments)
        U = np.transpose(U, (1, 0, 2))                       # U(k): rows inputs, columns experiments
        gram = U @ np.conj(np.transpose(U, (0, 2, 1)))
        expected = n_inputs * magnitude2 * np.eye(n_inputs)
        np.testing.assert_allclose(gram, np.broadcast_to(expected, gram.shape), rtol=0, atol=1e-12 * magnitude2)
    transform = exc.design["multisine"]["transform"]
    assert transform == ("hadamard" if n_inputs == 2 else "dft")


def test_single_input_design_is_unchanged_by_the_new_keys():
    plain = nlsid.design(config())
    explicit = nlsid.design(config(inputs=1))
    assert [r.run_id for r in plain.runs] == ["ms_l00_m00", "ms_l00_m01"]
    for a, b in zip(plain.runs, explicit.runs):
        np.testing.assert_array_equal(a.u, b.u)
        assert b.inputs == ("u",) and b.channels == {} and b.experiment is None
    assert "inputs" not in plain.design["multisine"]


def test_written_as_version_3_and_read_back(run_cli, tmp_path):
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(config(inputs=2, transform="dft")))
    result = run_cli("design", path, "-o", tmp_path / "e.h5", "--json")
    assert result.exit_code == 0, result.stderr
    m = result.json()["multisine"]
    assert (m["inputs"], m["experiments"], m["input_names"], m["transform"]) == (2, 2, ["u", "u2"], "dft")
    with h5py.File(tmp_path / "e.h5") as f:
        assert f.attrs["nlsid_format_version"] == 3 and f["runs/ms_l00_m01_e01"].attrs["experiment"] == 1
    runs = read_runs(tmp_path / "e.h5", require_y=False)
    assert [(r.realization, r.experiment, r.inputs) for r in runs][-1] == (1, 1, ("u", "u2"))
    assert runs[0].units == {"u": "V", "u2": "V"}
    listed = run_cli("info", tmp_path / "e.h5", "--json").json()["runs"]
    assert [(row["inputs"], row["experiment"]) for row in listed[:2]] == [(["u", "u2"], 0), (["u", "u2"], 1)]


@pytest.mark.parametrize("keys, fragment", [
    ({"inputs": 2, "phases": "schroeder", "realizations": 1}, "multisine.phases: orthogonal multisines (inputs: 2)"),
    ({"inputs": 2, "crest_factor_iterations": 5}, "multisine.crest_factor_iterations"),
    ({"inputs": 3, "transform": "hadamard"}, "multisine.transform: a Hadamard matrix needs a power of two inputs"),
    ({"transform": "dft"}, "multisine.transform: applies to orthogonal multisines"),
    ({"inputs": 0}, "multisine.inputs"),
])
def test_bad_keys_refused_in_one_line(run_cli, tmp_path, keys, fragment):
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(config(**keys)))
    run_cli("design", path, "-o", tmp_path / "e.h5").assert_one_line_error("design.yaml", fragment)
    assert not (tmp_path / "e.h5").exists()
