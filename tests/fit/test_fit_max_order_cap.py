"""``nlsid fit bla.h5 --order auto --max-order N`` from N = 5 on: the pole count by vector fitting,
capped at N (nlsid.fit.bla_fit, nlsid.fit.order_poles.select_at_cap).

The measured FRF is generated here with numpy alone: a discrete-time modal sum
G0(z) = sum_n r_n / (z - p_n) + r_n* / (z - p_n*) of twelve modes (24 poles; p_n = e^{s_n / fs},
zero-order-hold poles of modes of damping 1-3 % over 15-350 Hz, each 50-200 noise std high at its
peak), evaluated exactly at the lines z_k = e^{j 2 pi k / N}, plus circular complex Gaussian
noise of known variance sigma^2, written as the fast method's BLA of one realization (the
variance taken as exact: the cost of a correct model of n_theta parameters is
(1/2) chi^2(2F - n_theta), Schoukens, Pintelon and Rolain 2012, 4.7 L).

* ``--max-order 12``: a model of 12 poles cannot hold 24 (six modes at least are missing, each
  far above the noise), so its cost lies above its bound; the result has at most 12 poles, is
  stable, and says that the cap was reached.
* ``--max-order 28``: above the 24 the data need, the count finds them as without the option:
  24 +- 2 poles (a pole fewer misses a mode's pair; two more are allowed by the likelihood-ratio
  step), the cost inside the two-sided 0.999 band of its chi-square distribution.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from scipy import stats

MODES, FS, PERIOD, SIGMA = 12, 1000.0, 4096, 0.01
BINS = np.arange(4, 1600)


def _structure(seed: int) -> np.ndarray:
    """The noisy FRF at BINS of the modal sum (module docstring)."""
    rng = np.random.default_rng(seed)
    fn = np.geomspace(15.0, 350.0, MODES)
    zeta = rng.uniform(0.01, 0.03, MODES)
    wn = 2 * np.pi * fn
    poles = np.exp((-zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)) / FS)
    height = rng.uniform(0.5, 2.0, MODES)
    residues = height * (1 - np.abs(poles)) * np.exp(1j * rng.uniform(-np.pi, np.pi, MODES))
    z = np.exp(2j * np.pi * BINS / PERIOD)
    G0 = sum(r / (z - p) + np.conj(r) / (z - np.conj(p)) for p, r in zip(poles, residues))
    return G0 + SIGMA / np.sqrt(2) * (rng.standard_normal(BINS.size) + 1j * rng.standard_normal(BINS.size))


def _write_bla(path, G: np.ndarray) -> None:
    """A bla.h5 of one level as nlsid.io.bla_file.read_bla reads it: one realization of two periods,
    the fast method's G and var_total = sigma^2 at every line."""
    from nlsid.io.bla_file import FORMAT, FORMAT_VERSION
    from nlsid.io.result_file import create_result, put

    with create_result(path, FORMAT, FORMAT_VERSION, {"generator": "tests/fit/test_fit_max_order_cap.py"}) as handle:
        handle.attrs["units"] = "{}"
        level = handle.create_group("levels").create_group("level_00")
        level.attrs.update({"fs": FS, "period": PERIOD, "n_periods": 2, "n_realizations": 1})
        put(level, "excited_bins", BINS.astype(np.int64))
        put(level, "frequency", BINS * FS / PERIOD)
        put(level.create_group("robust"), "G", G)
        fast = level.create_group("fast")
        put(fast, "G", G)
        put(fast, "var_total", np.full(BINS.size, SIGMA**2))
        level.create_group("lines")


def _poles(model: dict) -> np.ndarray:
    """The written model's poles from the YAML alone (discrete state space or transfer function)."""
    assert model["domain"] == "discrete"
    if model["type"] == "state_space":
        return np.linalg.eigvals(np.array(model["A"], dtype=float))
    return np.roots(model["den"])   # den in powers of z^-1: its roots in z


@pytest.fixture(scope="module")
def bla(tmp_path_factory):
    path = tmp_path_factory.mktemp("cap") / "bla.h5"
    _write_bla(path, _structure(seed=3))
    return path


def test_a_cap_below_the_poles_needed_is_stated(bla, run_cli):
    out_path = bla.parent / "m12.yaml"
    result = run_cli("fit", bla, "--order", "auto", "--max-order", "12", "-o", out_path, "--json")
    assert result.exit_code == 0, (result.stdout, result.stderr)
    out = result.json()
    nb, na = map(int, out["order"].split("/"))
    assert na <= 12 and nb <= 12, out["order_reason"]
    assert out["stable"] and out["stability"] == "stable"
    poles = _poles(yaml.safe_load(out_path.read_text())["model"])
    assert poles.size == na and np.max(np.abs(poles)) < 1
    assert out["cost"] > out["cost_bound"]   # 12 poles cannot hold 24 far above the noise
    assert "cap of 12 poles was reached" in out["order_reason"]
    assert any("cap of 12 poles was reached" in w for w in out["warnings"])
    assert all(int(row["order"].split("/")[1]) <= 12 for row in out["order_scan"])


def test_a_cap_above_the_poles_needed_finds_them(bla, run_cli):
    result = run_cli("fit", bla, "--order", "auto", "--max-order", "28", "-o", bla.parent / "m28.yaml", "--json")
    assert result.exit_code == 0, (result.stdout, result.stderr)
    out = result.json()
    nb, na = map(int, out["order"].split("/"))
    assert abs(na - 2 * MODES) <= 2 and nb == na, out["order_reason"]
    assert out["stable"] and "cap of" not in out["order_reason"]
    dof = 2 * BINS.size - (2 * na + 1)
    low, high = stats.chi2.ppf([0.0005, 0.9995], dof) / 2
    assert low <= out["cost"] <= high, (out["cost"], low, high)
