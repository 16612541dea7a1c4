"""``nlsid fit`` on a bla.h5 level of several inputs and outputs (frm_levels): a MIMO state-space
model (nlsid.stages.frm_fit). The bla.h5 is written here from an FRM computed in the test: a
continuous 2x2 system of order 2 seen through the zero-order hold (scipy.signal.cont2discrete), M
realizations with complex Gaussian noise of a known covariance, their mean and scatter covariance."""

from __future__ import annotations

import json

import numpy as np
import yaml
from scipy import signal
from scipy.stats import chi2

from nlsid.analysis.confidence import Bounds
from nlsid.analysis.frm import FrequencyResponseMatrix
from nlsid.analysis.frm_levels import FrmLevel
from nlsid.io.bla_file import write_bla
from nlsid.io.model_config import validate_simulate_config
from nlsid.models.from_config import mimo_state_space

FS, PERIOD, M = 100.0, 200, 12
BINS = np.arange(1, 31)
W0 = 2 * np.pi * 6.0
A_TRUE = np.array([[0.0, 1.0], [-W0**2, -2 * 0.08 * W0]])
B_TRUE = np.array([[0.0, 0.0], [1000.0, 400.0]])
C_TRUE = np.array([[1.0, 0.0], [0.3, 0.002]])


def zoh_frm(A, B, C, D, f) -> np.ndarray:
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), 1 / FS, "zoh")
    z = np.exp(2j * np.pi * np.asarray(f) / FS)
    return np.stack([Cd @ np.linalg.solve(zk * np.eye(A.shape[0]) - Ad, Bd) + Dd for zk in z])


def write_frm_file(path, rng, levels=(None,)) -> tuple[np.ndarray, np.ndarray]:
    """The bla.h5 of FRM levels (the runs' level attribute per level); returns the truth and the
    covariance of the mean's vec(G)."""
    made = [frm_level_of(rng, value) for value in levels]
    write_bla(path, [], {"tool": "test"}, 0.95, [], {}, frm_levels=[level for level, _, _ in made])
    return made[0][1], made[0][2]


def frm_level_of(rng, value) -> tuple[FrmLevel, np.ndarray, np.ndarray]:
    """One FRM level of M realizations of the truth with noise, the truth and the mean's covariance."""
    f = BINS * FS / PERIOD
    G0 = zoh_frm(A_TRUE, B_TRUE, C_TRUE, np.zeros((2, 2)), f)
    F = f.size
    L = 0.03 * np.mean(np.abs(G0)) * (np.eye(4) + 0.3 * np.tri(4, k=-1))   # one realization's noise factor
    w = (rng.standard_normal((M, F, 4)) + 1j * rng.standard_normal((M, F, 4))) / np.sqrt(2)
    e = np.einsum("ij,mfj->mfi", L, w)                                       # vec order: column-stacked
    realizations = G0[None] + np.swapaxes(e.reshape(M, F, 2, 2), 2, 3)
    G = realizations.mean(axis=0)
    d = (realizations - G).transpose(0, 1, 3, 2).reshape(M, F, 4)
    cov_total = np.einsum("mfa,mfb->fab", d, d.conj()) / (M * (M - 1))
    nan = np.full((F, 2, 2), np.nan)
    bounds = Bounds(nan, nan, nan, nan, nan)
    result = FrequencyResponseMatrix(
        bins=BINS, frequency=f, G=G, std_noise=nan, std_total=np.sqrt(np.abs(np.einsum("fii->fi", cov_total)))
        .reshape(F, 2, 2).transpose(0, 2, 1), cov_noise=np.full((F, 4, 4), np.nan + 0j), cov_total=cov_total,
        n_realizations=M, n_experiments=2, n_periods=1, confidence=0.95, bounds=bounds, noise_bounds=bounds)
    level = FrmLevel(level=value, fs=FS, period=PERIOD, inputs=("u", "u2"), outputs=("y", "acc"),
                     run_ids=[[f"r{m}e{e}" for e in range(2)] for m in range(M)], units={}, frm=result)
    return level, G0, (L @ L.conj().T) / M


def test_fit_writes_a_mimo_state_space_of_the_frm(tmp_path, run_cli):
    bla = tmp_path / "bla.h5"
    G0, cov = write_frm_file(bla, np.random.default_rng(5))
    out = tmp_path / "model.yaml"
    result = run_cli("fit", bla, "--order", "auto", "--max-order", "3", "--domain", "s", "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["kind"] == "mimo_state_space" and summary["order"] == 2, summary["order_reason"]
    assert summary["inputs"] == ["u", "u2"] and summary["outputs"] == ["y", "acc"]
    assert summary["covariance_dof"] == M - 1 and summary["stable"] and summary["lines"] == BINS.size
    # the cost against its expected value: (M-1)/(M-1-4) (F m - n_theta/2) for the 4 x 4 covariance of
    # M = 12 realizations (complex Hotelling T^2), n_theta = 2 (2 + 2) + 4 = 12
    expected = (M - 1) / (M - 5) * (BINS.size * 4 - 12 / 2)
    assert abs(summary["expected_cost"] - expected) < 1e-9 * expected
    assert summary["cost"] < summary["cost_bound"]
    # the model config: the shared spec's shape, loaded by the schema and the model builder
    config = yaml.safe_load(out.read_text())
    model = config["model"]
    assert set(model) == {"type", "A", "B", "C", "D", "domain", "inputs", "outputs"}
    assert model["type"] == "mimo_state_space" and model["domain"] == "continuous"
    A, B, C, D = (np.array(model[k], dtype=float) for k in "ABCD")
    assert A.shape == (2, 2) and B.shape == (2, 2) and C.shape == (2, 2) and D.shape == (2, 2)
    assert model["inputs"] == ["u", "u2"] and model["outputs"] == ["y", "acc"]
    # its sampled response (scipy's ZOH) within the noise of the truth: (1/2) chi^2(n_theta) for an
    # efficient estimator, with the variances estimated over 12 realizations (4 times the quantile)
    e = (zoh_frm(A, B, C, D, BINS * FS / PERIOD) - G0).transpose(0, 2, 1).reshape(BINS.size, 4)
    error = float(np.real(np.einsum("fi,ij,fj->", e.conj(), np.linalg.inv(cov), e)))
    assert error < 4 * chi2.ppf(0.999, 12) / 2, error
    loaded = mimo_state_space(validate_simulate_config(config, str(out), {}).model)
    assert loaded.inputs == ("u", "u2") and loaded.outputs == ("y", "acc") and loaded.domain == "continuous"
    Phi, Gamma = loaded.stepped(1 / FS)           # as nlsid simulate runs it: scipy's ZOH of the same matrices
    Ad, Bd, _, _, _ = signal.cont2discrete((A, B, C, D), 1 / FS, "zoh")
    assert np.allclose(Phi, Ad, atol=1e-12) and np.allclose(Gamma, Bd, rtol=1e-9, atol=1e-12)
    report = json.loads((tmp_path / "model.fit.json").read_text())
    assert report["nlsid_format"] == "fit" and report["kind"] == "mimo_state_space"
    assert np.allclose(np.array(report["A"]), A) and report["order_scan"][1]["order"] == 2
    assert sorted(np.round(np.hypot(*np.array(report["poles"]).T) / W0, 2)) == [1.0, 1.0]


def test_fit_of_an_frm_level_refuses_what_it_cannot_do(tmp_path, run_cli):
    bla = tmp_path / "bla.h5"
    write_frm_file(bla, np.random.default_rng(6))
    out = tmp_path / "model.yaml"
    run_cli("fit", bla, "--order", "2/2", "-o", out).assert_one_line_error("--order", "number of states")
    run_cli("fit", bla, "--order", "2", "--delay", "3", "-o", out).assert_one_line_error("--delay")
    (tmp_path / "f.png").write_bytes(b"kept")
    run_cli("fit", bla, "--order", "2", "--plot", tmp_path / "f.png", "-o", out).assert_one_line_error("f.png", "--force")
    assert (tmp_path / "f.png").read_bytes() == b"kept"
    run_cli("fit", bla, "--order", "2", "--level", "1", "-o", out).assert_one_line_error("--level", "0..0")
    assert not out.exists() and not (tmp_path / "model.fit.json").exists()


def test_discrete_fit_states_its_rate(tmp_path, run_cli):
    bla = tmp_path / "bla.h5"
    write_frm_file(bla, np.random.default_rng(8))
    out = tmp_path / "model.yaml"
    result = run_cli("fit", bla, "--order", "2", "--domain", "z", "-o", out)
    assert result.exit_code == 0, result.stderr
    config = yaml.safe_load(out.read_text())
    model = mimo_state_space(validate_simulate_config(config, str(out), {}).model)
    assert model.domain == "discrete" and model.fs == FS
    # the discrete poles are the continuous truth's mapped by z = exp(s / fs), within 1 % (noise 3 %)
    true = np.exp(np.linalg.eigvals(A_TRUE) / FS)
    assert np.allclose(np.sort_complex(model.poles()), np.sort_complex(true), atol=0.01)


def test_weights_follow_what_the_level_holds():
    """frm_data's choice: the full total covariance with M - 1 >= m + 2, its diagonal with fewer
    realizations, the noise covariance for M = 1, unit weights without either; and the cost
    statistics that go with each (cost_statistics: n/(n - d) (F m - n_theta/2))."""
    from nlsid.fit.mimo_fit import cost_statistics
    from nlsid.stages.frm_fit import frm_data

    rng = np.random.default_rng(2)
    F = 5
    G = rng.standard_normal((F, 2, 2)) + 1j * rng.standard_normal((F, 2, 2))
    R = rng.standard_normal((F, 4, 4)) + 1j * rng.standard_normal((F, 4, 4))
    definite = R @ np.conj(np.swapaxes(R, 1, 2)) + 0.1 * np.eye(4)
    nan = np.full((F, 4, 4), np.nan + 0j)

    def level(M, P, total, noise):
        return {"attrs": {"n_realizations": M, "n_experiments": 2, "n_periods": P, "fs": FS},
                "G": G, "frequency": np.arange(1, F + 1.0), "cov_total": total, "cov_noise": noise}

    full, notes = frm_data(level(7, 1, definite, nan), "here")
    assert full.dof == 6 and full.dimension == 4 and not notes
    diagonal, notes = frm_data(level(5, 1, definite, nan), "here")
    assert diagonal.diagonal and diagonal.dimension == 1 and diagonal.dof == 4
    assert np.allclose(diagonal.covariance[:, 0, 1], 0) and np.allclose(diagonal.covariance[:, 2, 2], definite[:, 2, 2])
    assert len(notes) == 1 and "each entry weighted by its own variance" in notes[0]
    noise, notes = frm_data(level(1, 4, nan, definite), "here")
    assert noise.dof == 1 * 2 * 3 and "noise covariance only" in notes[0]
    unit, notes = frm_data(level(1, 1, nan, nan), "here")
    assert np.allclose(unit.covariance, np.eye(4)) and "unit weights" in notes[0]
    # expected costs: F(2, 2n) terms for the diagonal (the SISO (M-1)/(M-2)), Hotelling for the full one
    assert np.isclose(cost_statistics(F, 4, 12, 4.0, 1)[0], 4 / 3 * (20 - 6))
    assert np.isclose(cost_statistics(F, 4, 12, 6.0, 4)[0], 6 / 2 * (20 - 6))
    assert cost_statistics(F, 4, 12, 0.0, 4)[0] == np.inf


def test_levels_of_arbitrary_runs_are_numbered_after_and_fitted():
    """frm_lpm_levels (the LPM for several inputs) come after frm_levels in the numbering, are
    weighted by cov_G (or var_G where it has too few degrees of freedom) and fitted like the others."""
    from nlsid.fit.mimo_fit import fit_frm
    from nlsid.stages.frm_fit import frm_data, frm_level

    f = np.arange(1, 41) * 0.4
    G0 = zoh_frm(A_TRUE, B_TRUE, C_TRUE, np.zeros((2, 2)), f)
    rng = np.random.default_rng(4)
    cov = np.broadcast_to(np.eye(4) * (0.02 * np.mean(np.abs(G0))) ** 2, (f.size, 4, 4)).astype(complex)
    noise = 0.02 * np.mean(np.abs(G0)) * (rng.standard_normal(G0.shape) + 1j * rng.standard_normal(G0.shape))
    lpm = {"name": "level_00", "attrs": {"dof": 30, "fs": FS, "half_width": 3}, "frequency": f, "G": G0 + noise / np.sqrt(2),
           "cov_G": cov, "var_G": np.full((f.size, 2, 2), cov[0, 0, 0].real)}
    content = {"levels": [{}], "lpm_levels": [], "frm_levels": [{"name": "level_00"}], "frm_lpm_levels": [lpm]}
    assert frm_level(content, 1, "b.h5")[1]["name"] == "level_00" and frm_level(content, 0, "b.h5") is None
    index, chosen = frm_level(content, 2, "b.h5")
    assert index == 2 and chosen is lpm
    data, notes = frm_data(chosen, "b.h5")
    # cov_G = [A^-1]_00 kron C: n_u = 2 Hotelling terms of the n_y = 2 outputs' C per line; windows
    # of 2 n + 1 = 7 lines overlap up to 6 lines apart
    assert data.dof == 30 and data.dimension == 2 and data.sharing == 2 and data.shared_lags == 6 and not notes
    result = fit_frm(data, None, "s", hold=True, max_order=3)
    assert result.fit.order == 2 and result.fit.stable, result.reason
    lpm["attrs"]["dof"] = 3                     # q - n_y = 1: the Hotelling terms have no finite variance
    data, notes = frm_data(lpm, "b.h5")
    assert data.diagonal and data.dimension == 1 and "each entry weighted by its own variance" in notes[0]


def test_every_level_fitted_where_the_file_holds_several(tmp_path, run_cli):
    """A file of FRM levels only, several of them, without --level: one model per level, named
    model.level_NN.yaml, all fitted before any is written; --json lists them under levels."""
    bla = tmp_path / "bla.h5"
    write_frm_file(bla, np.random.default_rng(9), levels=(1.0, 2.0))
    result = run_cli("fit", bla, "--order", "2", "-o", tmp_path / "model.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    entries = result.json()["levels"]
    assert [e["level"] for e in entries] == [{"index": 0, "level": 1.0}, {"index": 1, "level": 2.0}]
    assert [e["output"] for e in entries] == [str(tmp_path / f"model.level_0{i}.yaml") for i in (0, 1)]
    for i in (0, 1):
        config = yaml.safe_load((tmp_path / f"model.level_0{i}.yaml").read_text())
        assert config["model"]["type"] == "mimo_state_space"
        assert json.loads((tmp_path / f"model.level_0{i}.fit.json").read_text())["level"]["index"] == i
    assert not (tmp_path / "model.yaml").exists()
    # --level names one of them: that one alone, at -o
    result = run_cli("fit", bla, "--order", "2", "--level", "1", "-o", tmp_path / "one.yaml", "--json")
    assert result.exit_code == 0 and result.json()["level"]["index"] == 1 and (tmp_path / "one.yaml").exists()


def test_fit_plot_draws_the_model_over_the_frm(tmp_path, run_cli):
    """``--plot``: the PNG beside the model, its model curves those of the written config sampled by
    scipy's ZOH (independent of the fit's resolvent), its residual |G_model - G| per entry."""
    from nlsid.report.vector import columns
    from nlsid.stages.frm_fit import fit_frm_level

    bla = tmp_path / "bla.h5"
    write_frm_file(bla, np.random.default_rng(9))
    out, png = tmp_path / "model.yaml", tmp_path / "fit.png"
    result = run_cli("fit", bla, "--order", "2", "--domain", "s", "--plot", png, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["plot"] == str(png) and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    f = BINS * FS / PERIOD
    fitted = fit_frm_level(bla, 2, "s")
    # The figure is of this second fit; the first wrote the YAML. Two fits of the same data agree to
    # the optimiser's tolerance, not to the last bit, and |G_model - G| is a difference of close
    # numbers: so the curves are checked against this fit's own config, and the YAML against it.
    model = fitted.config()["model"]
    G_model = zoh_frm(*(np.array(model[k], dtype=float) for k in "ABCD"), f)
    written = yaml.safe_load(out.read_text())["model"]
    G_written = zoh_frm(*(np.array(written[k], dtype=float) for k in "ABCD"), f)
    assert np.allclose(G_written, G_model, rtol=1e-6, atol=0)
    G = np.asarray(fitted.stored["G"])
    drawn = dict(columns(fitted.figure()))
    for i, output in enumerate(["y", "acc"]):
        for a, input_ in enumerate(["u", "u2"]):
            head = f"{input_} to {output}: |G|, std"
            model_db = next(v for k, v in drawn.items() if k.startswith("|G model|: ") and head in k)
            residual_db = next(v for k, v in drawn.items() if k.startswith("|G model - G|: ") and head in k)
            assert np.allclose(model_db, 20 * np.log10(np.abs(G_model[:, i, a])), atol=1e-6)
            assert np.allclose(residual_db, 20 * np.log10(np.abs(G_model[:, i, a] - G[:, i, a])), atol=1e-6)
