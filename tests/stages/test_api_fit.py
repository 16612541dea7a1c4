"""The library face of ``fit``: ``nlsid.fit_tf`` and ``nlsid.fit_model``.

Truth is independent of the fit: BLAs of exactly known systems built here (scipy.signal.lfilter,
and cont2discrete for the zero-order hold), costs recomputed with numpy from the returned
coefficients, responses evaluated by scipy and python-control, and the command line's outputs.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import signal

import nlsid
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

from generators.bla_cases import odd_random_bins, runs_of_level  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_data" / "stage.h5"
FC_FREE = ROOT / "configs" / "stage_fc_free.yaml"

# a resonant discrete 2/2 system (poles 0.95 e^{+-j 0.2}, zeros inside the unit circle)
B_Z = np.array([0.2, -0.1, 0.05])
A_Z = np.array([1.0, -2 * 0.95 * np.cos(0.2), 0.95**2])


def _multisine_recording(system, fs: float, rng, noise_y: float = 0.0, M: int = 2) -> Recording:
    N = 1024
    bins = odd_random_bins(1, 200, 4, rng)
    runs = runs_of_level(M, N, bins, 1.0, system, 2, rng, fs=fs, noise_y=noise_y, level=1.0)
    return Recording(runs)


def test_fit_tf_returns_the_coefficients_of_an_exactly_known_discrete_system():
    # noise-free: the BLA is G0 at the excited lines to rounding, so the 2/2 fit (unweighted least
    # squares at the precision floor) must give B_Z, A_Z to far better than 1e-6
    rec = _multisine_recording(lambda u: signal.lfilter(B_Z, A_Z, u), 100.0, np.random.default_rng(1))
    tf = nlsid.fit_tf(nlsid.bla(rec), order=(2, 2), domain="z")
    assert tf.domain == "z" and tf.delay == 0 and tf.fs == 100.0
    np.testing.assert_allclose(tf.num, B_Z, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(tf.den, A_Z, rtol=1e-6, atol=1e-9)
    assert tf.summary()["weighted"] is False


def test_fit_tf_returns_the_coefficients_of_a_continuous_system_seen_through_the_hold():
    fs, w0, zeta = 100.0, 2 * np.pi * 5.0, 0.1
    num_s = np.array([0.5, 30.0, w0**2])
    den_s = np.array([1.0, 2 * zeta * w0, w0**2])
    bd, ad, _ = signal.cont2discrete((num_s, den_s), 1 / fs, method="zoh")
    rec = _multisine_recording(lambda u: signal.lfilter(np.ravel(bd), ad, u), fs, np.random.default_rng(2))
    tf = nlsid.fit_tf(nlsid.bla(rec), order=(2, 2), domain="s")
    np.testing.assert_allclose(tf.num, num_s, rtol=1e-6)
    np.testing.assert_allclose(tf.den, den_s, rtol=1e-6)
    # the sampled response is that of the ZOH-discretised system; the continuous one B(jw)/A(jw)
    f = np.array([0.7, 3.1, 5.0, 12.0])
    _, h_zoh = signal.freqz(np.ravel(bd), ad, worN=f, fs=fs)
    np.testing.assert_allclose(tf.frequency_response(f), h_zoh, rtol=1e-6)
    _, h_s = signal.freqs(num_s, den_s, worN=2 * np.pi * f)
    np.testing.assert_allclose(tf.frequency_response(f, sampled=False), h_s, rtol=1e-6)
    # to_scipy: an lti whose own response is B(jw)/A(jw)
    _, h_lti = tf.to_scipy().freqresp(2 * np.pi * f)
    np.testing.assert_allclose(h_lti, h_s, rtol=1e-6)


def test_noisy_fit_covers_the_truth_and_its_cost_is_recomputable():
    # 40 dB SNR, M = 8: the fitted coefficients lie within their uncertainty of the truth (Mahalanobis
    # distance below the chi2(5) 0.999 quantile 20.5), and the cost is sum |G - G_model|^2 / var_total
    rng = np.random.default_rng(3)
    rec = _multisine_recording(lambda u: signal.lfilter(B_Z, A_Z, u), 100.0, rng, noise_y=0.01, M=8)
    b = nlsid.bla(rec)
    tf = nlsid.fit_tf(b, order=(2, 2), domain="z")
    fit_ = tf.fitted.fit
    truth = np.concatenate([A_Z[1:], B_Z])  # the order of fit_.names: a1, a2, b0, b1, b2
    assert fit_.names == ["a1", "a2", "b0", "b1", "b2"]
    d = fit_.values - truth
    assert d @ np.linalg.solve(fit_.covariance, d) < 20.5
    level = b.levels[0]
    z = np.exp(2j * np.pi * level.lines.excited / level.lines.period)
    model = np.polyval(tf.num[::-1], 1 / z) / np.polyval(tf.den[::-1], 1 / z)
    cost = np.sum(np.abs(level.robust.G - model) ** 2 / level.robust.var_total)
    assert tf.cost == pytest.approx(cost, rel=1e-9)
    # the dlti of to_scipy has this response at the excited frequencies
    _, h = tf.to_scipy().freqresp(2 * np.pi * level.lines.excited / level.lines.period)
    np.testing.assert_allclose(h, model, rtol=1e-9)


def _arbitrary_recording(rng, records: int = 4, n: int = 4096) -> Recording:
    runs = []
    for i in range(records):
        u = rng.standard_normal(n)
        y = signal.lfilter(B_Z, A_Z, u) + 0.02 * rng.standard_normal(n)
        runs.append(Run(run_id=f"noise{i}", fs=100.0, kind="arbitrary", u=u, y=y, period=None, transient_periods=0,
                        realization=None, level=None, excited_bins=None))
    return Recording(runs)


@pytest.fixture(scope="module")
def lpm_bla():
    return nlsid.bla(_arbitrary_recording(np.random.default_rng(4)))


def test_an_lpm_level_is_weighted_by_its_smoothed_variance_as_the_command_does(lpm_bla, tmp_path, run_cli):
    (level,) = lpm_bla.lpm_levels
    tf = nlsid.fit_tf(lpm_bla, order=(2, 2), domain="z")
    z = np.exp(2j * np.pi * level.bins / level.result.n_samples)
    error = np.abs(level.G - np.polyval(tf.num[::-1], 1 / z) / np.polyval(tf.den[::-1], 1 / z)) ** 2
    smoothed = level.result.var_G_smoothed[level.band]
    assert tf.cost == pytest.approx(np.sum(error / smoothed), rel=1e-9)
    assert not np.allclose(smoothed, level.var_G)  # the raw variance would be another cost
    # the command on the file of the same BLA: the same numbers
    bla_h5 = lpm_bla.write(tmp_path / "bla.h5")
    out = run_cli("fit", str(bla_h5), "--order", "2/2", "-o", str(tmp_path / "m.yaml"), "--json")
    assert out.exit_code == 0, out.output
    assert json.loads(out.stdout) == {**json.loads(json.dumps(_json_safe(tf.summary()))),
                                      "output": str(tmp_path / "m.yaml"),
                                      "report": str(tmp_path / "m.fit.json"), "plot": None}


def _json_safe(value):
    from nlsid.io.result_file import json_safe

    return json_safe(value)


@pytest.fixture(scope="module")
def sample_bla_file(tmp_path_factory):
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    path = tmp_path_factory.mktemp("bla") / "bla.h5"
    result = CliRunner().invoke(cli, ["bla", str(SAMPLE), "-o", str(path)])
    assert result.exit_code == 0, result.output
    return path


@pytest.mark.parametrize("order, domain, level", [((2, 2), "z", 0), ((2, 2), "s", 1), ("auto", "z", 2)])
def test_fit_tf_of_the_bla_in_memory_gives_the_command_s_numbers_and_files(sample_bla_file, tmp_path, run_cli,
                                                                          order, domain, level):
    flag = order if isinstance(order, str) else f"{order[0]}/{order[1]}"
    out = run_cli("fit", str(sample_bla_file), "--order", flag, "--domain", domain, "--level", str(level),
                  "-o", str(tmp_path / "cli.yaml"), "--plot", str(tmp_path / "cli.png"), "--json")
    assert out.exit_code == 0, out.output
    cli_json = json.loads(out.stdout)
    tf = nlsid.fit_tf(nlsid.bla(nlsid.read(SAMPLE)), order=order, domain=domain, level=level)
    summary = _json_safe(tf.summary())
    for key in ("num", "den", "cost", "expected_cost", "cost_bound", "parameters", "order", "order_reason",
                "weights", "stability"):
        assert summary[key] == cli_json[key], key
    # from the file the command wrote the same model, and write() writes the command's two files
    from_file = nlsid.fit_tf(sample_bla_file, order=order, domain=domain, level=level)
    from_file.write(tmp_path / "api.yaml")
    header_cli = (tmp_path / "cli.yaml").read_text()
    assert (tmp_path / "api.yaml").read_text() == header_cli.replace("cli.fit.json", "api.fit.json")
    a = json.loads((tmp_path / "api.fit.json").read_text())
    b = json.loads((tmp_path / "cli.fit.json").read_text())
    assert a.pop("provenance")["inputs"] == b.pop("provenance")["inputs"]
    assert a == b
    assert from_file.png() == (tmp_path / "cli.png").read_bytes()


def test_to_control_gives_the_same_response_or_says_how_to_install(monkeypatch):
    rec = _multisine_recording(lambda u: signal.lfilter(B_Z, A_Z, u), 100.0, np.random.default_rng(5))
    tf = nlsid.fit_tf(nlsid.bla(rec), order=(2, 2), domain="z")
    try:
        import control
    except ImportError:
        control = None
    if control is not None:
        system = tf.to_control()
        f = np.array([1.0, 7.5, 20.0])
        h = np.array([complex(system(np.exp(2j * np.pi * x / 100.0))) for x in f])
        np.testing.assert_allclose(h, tf.frequency_response(f), rtol=1e-9)
        assert system.dt == pytest.approx(0.01)
    monkeypatch.setitem(sys.modules, "control", None)  # as when python-control is not installed
    with pytest.raises(ImportError, match="pip install control"):
        tf.to_control()


@pytest.mark.filterwarnings("error::scipy.signal.BadCoefficients")  # the delay's zeros are not leading zeros
def test_a_discrete_dead_time_is_found_and_kept_in_the_dlti():
    fs = 100.0
    rec = _multisine_recording(lambda u: np.concatenate([np.zeros(2), signal.lfilter(B_Z, A_Z, u)[:-2]]), fs,
                               np.random.default_rng(7))
    tf = nlsid.fit_tf(nlsid.bla(rec), order=(2, 2), domain="z", delay="auto")
    assert tf.delay == 2
    np.testing.assert_allclose(tf.num, B_Z, rtol=1e-6)
    f = np.array([1.0, 5.0, 20.0])
    _, truth = signal.freqz(np.concatenate([[0.0, 0.0], B_Z]), A_Z, worN=f, fs=fs)
    _, h = tf.to_scipy().freqresp(2 * np.pi * f / fs)
    np.testing.assert_allclose(h, truth, rtol=1e-6)
    np.testing.assert_allclose(tf.frequency_response(f), truth, rtol=1e-6)


def test_a_continuous_model_with_a_dead_time_is_not_silently_dropped_into_an_lti():
    fs = 100.0
    bd, ad, _ = signal.cont2discrete(([400.0], [1.0, 8.0, 400.0]), 1 / fs, method="zoh")
    delayed = lambda u: np.concatenate([np.zeros(3), signal.lfilter(np.ravel(bd), ad, u)[:-3]])  # noqa: E731
    rec = _multisine_recording(delayed, fs, np.random.default_rng(6))
    tf = nlsid.fit_tf(nlsid.bla(rec), order=(0, 2), domain="s", delay="auto")
    assert tf.delay == 3 and tf.delay_seconds == pytest.approx(0.03)
    np.testing.assert_allclose(tf.den, [1.0, 8.0, 400.0], rtol=1e-6)
    with pytest.raises(nlsid.InputError, match="to_scipy: the continuous model has a dead time of 3 samples"):
        tf.to_scipy()


@pytest.mark.parametrize("kwargs, message", [
    (dict(order="2x2", level=0), "order: expected NB/NA"),
    (dict(order=(2, 2)), "BlaResult: 3 levels in the BLA; choose one with level 0..2"),
    (dict(order=(2, 2), level=7), "level: expected 0..2"),
    (dict(order=(3, 2), domain="s", level=0), "order: 3/2: orders must be >= 0 and a continuous model proper"),
    (dict(order=(2, 2), domain="w", level=0), "domain: expected s or z, got 'w'"),
    (dict(order=(2, 2), delay=-1, level=0), "delay: expected a whole number of samples >= 0 or auto, got -1"),
    (dict(order="auto", max_order=0, level=0), "max_order: expected a whole number >= 1"),
])
def test_fit_tf_names_the_argument_in_error(kwargs, message):
    b = _sample_bla()
    with pytest.raises(nlsid.InputError) as error:
        nlsid.fit_tf(b, **kwargs)
    assert str(error.value).startswith(message), str(error.value)


_CACHE = {}


def _sample_bla():
    if "bla" not in _CACHE:
        _CACHE["bla"] = nlsid.bla(nlsid.read(SAMPLE))
    return _CACHE["bla"]


def test_the_notebook_views_show_the_fit():
    import matplotlib

    matplotlib.use("Agg")
    tf = nlsid.fit_tf(_sample_bla(), order=(0, 2), level=2)
    html = tf._repr_html_()
    assert "0/2 (s-domain, delay 0 samples)" in html and "<td>b0</td>" in html and "stable" in html
    figure = tf.plot()
    assert type(figure).__name__ == "Figure" and len(figure.axes) == 1


def test_fit_tf_refuses_what_is_not_a_bla():
    with pytest.raises(nlsid.InputError, match="^b: expected a BlaResult"):
        nlsid.fit_tf(42)


# ---------------------------------------------------------------------------------------------------
# fit_model


@pytest.fixture(scope="module")
def sample_model_fit():
    return nlsid.fit_model(str(FC_FREE), nlsid.read(str(SAMPLE)))


def test_fit_model_finds_the_sample_machine_s_friction_and_writes_the_command_s_files(sample_model_fit, run_cli,
                                                                                      tmp_path):
    fit_ = sample_model_fit
    # the machine of sample_data (configs/stage_true.yaml) has 0.5 N of Coulomb friction
    (fc,) = fit_.values
    (std,) = fit_.std
    assert fit_.names == ["model.nonlinearities[0].fc"]
    assert abs(fc - 0.5) < 5 * std
    assert fit_.config["model"]["nonlinearities"][0]["fc"] == fc and "free" not in fit_.config
    assert fit_.validation_rms < 2 * fit_.fitted.noise_rms_validation  # the fitted model predicts held-out runs
    out = run_cli("fit", "--model", str(FC_FREE), "--data", str(SAMPLE),
                  "-o", str(tmp_path / "cli.yaml"), "--json")
    assert out.exit_code == 0, out.output
    cli_json = json.loads(out.stdout)
    assert {k: v for k, v in cli_json.items() if k not in ("output", "report")} == _json_safe(fit_.summary())
    fit_.write(tmp_path / "api.yaml")
    assert ((tmp_path / "api.yaml").read_text()
            == (tmp_path / "cli.yaml").read_text().replace("cli.fit.json", "api.fit.json"))
    a = json.loads((tmp_path / "api.fit.json").read_text())
    b = json.loads((tmp_path / "cli.fit.json").read_text())
    pa, pb = a.pop("provenance"), b.pop("provenance")
    assert a == b and pa["inputs"] == pb["inputs"] and pa["configs"] == pb["configs"]


def test_fit_model_of_a_dict_with_free_given_matches_the_config_file(sample_model_fit):
    config = yaml.safe_load(FC_FREE.read_text())
    free = config.pop("free")
    fit_ = nlsid.fit_model(config, nlsid.read(SAMPLE), free=free)
    assert fit_.values.tolist() == sample_model_fit.values.tolist()
    assert fit_.std.tolist() == sample_model_fit.std.tolist()
    assert fit_.model_source == "model" and "Model fit" in fit_._repr_html_()
    from_model = nlsid.fit_model(nlsid.Model.from_yaml(FC_FREE), nlsid.read(SAMPLE))
    assert from_model.values.tolist() == sample_model_fit.values.tolist()
    assert from_model.model.parameters["model.nonlinearities[0].fc"] == from_model.values[0]
    # held out by default: the highest realization (m = 2 of 0..2) of each of the three multisine levels
    assert sorted(r.run_id for r in from_model.runs if r.role == "validation") == [
        "ms_l00_m02", "ms_l01_m02", "ms_l02_m02"]


def test_fit_model_names_the_argument_in_error():
    rec = nlsid.read(SAMPLE)
    with pytest.raises(nlsid.InputError, match="^fit_on: expected y or u, got 'q'"):
        nlsid.fit_model(FC_FREE, rec, fit_on="q")
    with pytest.raises(nlsid.InputError, match="^validate_on: .* is the rec recording .*pass allow_overlap=True"):
        nlsid.fit_model(FC_FREE, rec, validate_on=nlsid.read(SAMPLE))
    in_memory = Recording(rec.runs)  # no path: only the same object is the same recording
    with pytest.raises(nlsid.InputError, match=r"\(the same Recording\)"):
        nlsid.fit_model(FC_FREE, in_memory, validate_on=in_memory)
    with pytest.raises(nlsid.InputError, match=r"\(the same file\)"):
        nlsid.fit_model(FC_FREE, str(SAMPLE), validate_on=str(SAMPLE))
    with pytest.raises(nlsid.InputError, match="^estimation_range: nothing to validate on: give validation_range or "
                                               "validate_on"):
        nlsid.fit_model(FC_FREE, rec, estimation_range=(0, 100))
    with pytest.raises(nlsid.InputError, match="^model: expected a Model \\(nlsid.Model\\), a model config"):
        nlsid.fit_model(3.5, rec)
    no_y = Recording([Run(run_id="r", fs=1.0, kind="arbitrary", u=np.ones(8), y=None, period=None,
                          transient_periods=0, realization=None, level=None, excited_bins=None)])
    with pytest.raises(nlsid.InputError, match="^rec: run 'r' has no measured output y"):
        nlsid.fit_model(FC_FREE, no_y)
