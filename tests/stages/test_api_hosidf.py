"""``nlsid.hosidf`` -> HosidfResult against a static cubic whose HOSIDFs are known in closed form.

y = a1 u + a3 u^3 driven by u = A cos(w0 t + phi): since cos^3 x = (3 cos x + cos 3x)/4,
Y(w0) = (a1 A + (3/4) a3 A^3) e^{i phi} and Y(3 w0) = (1/4) a3 A^3 e^{3 i phi}, so
H_1 = Y(w0)/U(w0) = a1 + (3/4) a3 A^2, H_3 = Y(3 w0)/U(w0)^3 = a3/4, H_0 = H_2 = H_4 = 0, and in
the seed 000 form |Y(3 w0)|/|U(w0)| = (1/4) a3 A^2. The recordings are generated here with numpy.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

import nlsid
from nlsid.io.recording import open_recording, write_recording
from nlsid.io.run import make_run
from nlsid.stages.recording import Recording

FS, N = 256.0, 256  # one period of 1 s; bin b is b Hz
A1, A3 = 1.5, -0.4
BINS, AMPLITUDES = (3, 7), (0.5, 1.0, 2.0)


def cubic(u):
    return A1 * u + A3 * u**3


def sine_run(run_id, line, amplitude, phase, periods, system=cubic, noise=0.0, rng=None, params=None):
    t = np.arange(periods * N) / FS
    u = amplitude * np.cos(2 * np.pi * line * t + phase)
    y = system(u) + (noise * rng.standard_normal(u.size) if noise else 0.0)
    attrs = {"fs": FS, "kind": "sine", "period": N, "level": amplitude, "frequency": line * FS / N}
    if params is not None:
        import json

        attrs["params"] = json.dumps(params)
    return make_run(run_id, attrs, {"u": u, "y": y}, run_id, True, units={"u": "V", "y": "m"})


def grid_recording(repeats=2, periods=2, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    runs = [sine_run(f"s_b{b}_a{a}_r{r}", b, a, rng.uniform(-np.pi, np.pi), periods, noise=noise, rng=rng)
            for b in BINS for a in AMPLITUDES for r in range(repeats)]
    return Recording(runs)


def test_static_cubic_hosidfs_are_exact():
    h = nlsid.hosidf(grid_recording(), harmonics=4)
    np.testing.assert_allclose(h.frequencies, BINS)
    np.testing.assert_allclose(h.levels, AMPLITUDES)
    np.testing.assert_array_equal(h.bins, BINS)
    np.testing.assert_array_equal(h.n_repeats, 2)
    np.testing.assert_array_equal(h.n_periods, 2)
    a = np.array(AMPLITUDES)[None, :]
    # rounding of sums over 512 samples of O(1) values: 1e-12 relative
    np.testing.assert_allclose(h.H[:, :, 1], np.broadcast_to(A1 + 0.75 * A3 * a**2, (2, 3)), rtol=1e-12)
    np.testing.assert_allclose(h.H[:, :, 3], np.full((2, 3), A3 / 4), rtol=1e-12)
    for k in (0, 2, 4):
        assert np.abs(h.H[:, :, k]).max() < 1e-12
    np.testing.assert_allclose(np.abs(h.H000[:, :, 3]), np.broadcast_to(abs(A3) / 4 * a**2, (2, 3)), rtol=1e-12)
    np.testing.assert_allclose(np.abs(h.Y[:, :, 3]), np.broadcast_to(abs(A3) / 4 * a**3, (2, 3)), rtol=1e-12)
    # noise-free: the tone and the cubic's harmonic stand far above a bound made of rounding
    assert h.significant[:, :, 1].all() and h.significant[:, :, 3].all()
    assert h.warnings == [] and h.units == {"u": "V", "y": "m"} and h.input_signal == "u"


def test_the_analytic_hosidfs_of_a_model_config(tmp_path):
    """The cubic as a Hammerstein model with a unit discrete block: Lemma 2 gives the closed form too."""
    config = tmp_path / "cubic.yaml"
    config.write_text("model:\n  type: hammerstein\n"
                      f"  nonlinear: {{type: polynomial, coefficients: [0, {A1}, 0, {A3}]}}\n"
                      "  linear: {type: transfer_function, domain: discrete, num: [1.0], den: [1.0]}\n")
    h = nlsid.hosidf(grid_recording(), harmonics=3, model=config)
    a = np.array(AMPLITUDES)[None, :]
    np.testing.assert_allclose(h.analytic[:, :, 1], np.broadcast_to(A1 + 0.75 * A3 * a**2, (2, 3)), rtol=1e-12)
    np.testing.assert_allclose(h.analytic[:, :, 3], np.full((2, 3), A3 / 4), rtol=1e-12)
    assert np.abs(h.analytic[:, :, 2]).max() < 1e-12
    assert h.configs == [str(config)]
    # the same model in memory (a Model, or its dict): the same closed form, no config file named
    for model in (nlsid.Model.from_yaml(config), nlsid.Model.from_yaml(config).to_dict()):
        again = nlsid.hosidf(grid_recording(), harmonics=3, model=model)
        np.testing.assert_allclose(again.analytic[:, :, 3], np.full((2, 3), A3 / 4), rtol=1e-12)
        assert again.configs == []
    with pytest.raises(nlsid.InputError, match="model: expected a Model"):
        nlsid.hosidf(grid_recording(), harmonics=3, model=3.0)


def test_noisy_cubic_within_its_measured_and_its_theoretical_variance():
    """White output noise of sd s: a period's X[k] = 2 DFT[k b]/N has E|X|^2 = 4 s^2/N, so the mean of
    R x P periods normalised by U^k has variance 4 s^2/(N R P A^(2k)) (the same for every k >= 1)."""
    repeats, periods, s = 4, 4, 0.05
    h = nlsid.hosidf(grid_recording(repeats, periods, noise=s, seed=1), harmonics=4)
    a = np.array(AMPLITUDES)[None, :, None]
    k = np.arange(1, 5)[None, None, :]
    theory = 4 * s**2 / (N * repeats * periods) / a ** (2 * k)
    sigma1 = np.sqrt(theory[..., 0])
    error = np.abs(h.H[:, :, 1] - (A1 + 0.75 * A3 * a[..., 0] ** 2))
    assert (error < 5 * sigma1).all()  # |complex Gaussian| > 5 sigma: probability e^-25
    assert (np.abs(h.H[:, :, 3] - A3 / 4) < 5 * np.sqrt(theory[..., 2])).all()
    # each variance estimate is chi-square: 2R(P-1) real dof over periods, 2(R-1) over repeats;
    # the mean of the 24 ratios has relative sd sqrt(1/(R(P-1) 24)) and sqrt(1/((R-1) 24))
    for name, dof in (("H_var_periods", repeats * (periods - 1)), ("H_var_repeats", repeats - 1)):
        ratio = float(np.mean(getattr(h, name)[:, :, 1:] / theory))
        assert abs(ratio - 1) < 5 / np.sqrt(dof * 24), (name, ratio)


def test_sweep_of_the_cubic_coefficient():
    """y = u + p u^3: Definition 2's cost over k = 2..3 is (|p| A^3/4)/2 / |A + (3/4) p A^3| and Eq. 7's
    error max rms(u - y) = |p| A^3 sqrt(10/32); both are smallest at p = 0."""
    amplitude, values = 0.8, [-0.3, -0.1, 0.0, 0.2, 0.4]
    runs = [sine_run(f"p{i}", 5, amplitude, 0.4, 2, system=lambda u, p=p: u + p * u**3, params={"p": p})
            for i, p in enumerate(values)]
    h = nlsid.hosidf(Recording(runs), harmonics=3, sweep="p")
    p = np.array(values)
    np.testing.assert_allclose(h.values, p)
    expected = np.abs(p) * amplitude**3 / 4 / 2 / np.abs(amplitude + 0.75 * p * amplitude**3)
    np.testing.assert_allclose(h.cost_all, expected, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(h.time_error, np.abs(p) * amplitude**3 * np.sqrt(10 / 32), rtol=1e-9, atol=1e-13)
    assert h.optimum == 0.0 and h.time_optimum == 0.0
    assert h.summary()["sweep"]["parameter"] == "p" and "grid" not in h.summary()
    with pytest.raises(AttributeError, match="sweep of p, not a grid"):
        h.H
    assert set(h.figures()) == {"sweep_harmonics.png", "sweep_spectrum.png", "sweep_hosidf.png",
                                "sweep_performance.png"}


def test_a_path_an_open_file_and_a_recording_give_one_result(tmp_path):
    path = tmp_path / "cubic.h5"
    rec = grid_recording()
    write_recording(path, rec.runs, provenance={})
    by_path = nlsid.hosidf(path, harmonics=3)
    with open_recording(path) as handle:
        by_handle = nlsid.hosidf(handle, harmonics=3)
    by_object = nlsid.hosidf(nlsid.read(path), harmonics=3)
    for other in (by_handle, by_object):
        np.testing.assert_array_equal(other.H, by_path.H)
        assert other.summary() == by_path.summary()
    assert by_path.inputs == [str(path)]


def test_bad_arguments_are_named():
    rec = grid_recording()
    for kwargs, name in ((dict(harmonics=1), "harmonics"), (dict(harmonics=2.5), "harmonics"),
                         (dict(variance="all"), "variance"), (dict(input="y"), "input"),
                         (dict(sweep="p", model="m.yaml"), "model")):
        with pytest.raises(ValueError, match=f"^{name}: ") as error:
            nlsid.hosidf(rec, **kwargs)
        assert isinstance(error.value, nlsid.InputError)
    multisine = make_run("ms", {"fs": FS, "kind": "multisine", "period": N, "excited_bins": np.array([1, 3])},
                         {"u": np.ones(N), "y": np.ones(N)}, "ms", True)
    with pytest.raises(nlsid.InputError, match="holds no single-sine runs"):
        nlsid.hosidf(Recording([multisine]))
    mixed = nlsid.hosidf(Recording([*rec.runs, multisine]), harmonics=3)
    assert mixed.warnings == ["skipped 1 runs that are not single sines (ms)"]


def _datasets(path):
    out = {}
    with h5py.File(path) as handle:
        handle.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        out.update({f"@{k}": v for k, v in handle.attrs.items() if k != "provenance"})
    return out


def test_the_command_is_the_function(run_cli, tmp_path):
    """hosidf.h5, the figures and --json of `nlsid hosidf` are those of the result's write, figures, summary."""
    path, out, folder = tmp_path / "cubic.h5", tmp_path / "cli.h5", tmp_path / "figs"
    write_recording(path, grid_recording().runs, provenance={})
    cli = run_cli("hosidf", path, "-o", out, "--harmonics", 4, "--plots", folder, "--json")
    assert cli.exit_code == 0, cli.stderr
    h = nlsid.hosidf(path, harmonics=4)
    written = h.write(tmp_path / "api.h5")
    a, b = _datasets(out), _datasets(written)
    assert a.keys() == b.keys()
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=np.asarray(a[key]).dtype.kind == "f"), key
    figures = h.figures()
    assert [str(folder / name) for name in figures] == cli.json()["plots"]
    assert all((folder / name).read_bytes() == png for name, png in figures.items())
    summary = cli.json()
    assert summary.pop("output") == str(out) and summary.pop("plots")
    assert summary == h.summary()
    with pytest.raises(nlsid.InputError, match="exists"):
        h.write(written)
    assert "<table>" in h._repr_html_()
    import matplotlib.pyplot as plt

    shown = h.plot()
    assert len(shown) == len(figures) and all(plt.fignum_exists(f.number) for f in shown)
    for figure in shown:
        plt.close(figure)


def test_the_command_names_its_flags(run_cli, tmp_path):
    path, out = tmp_path / "cubic.h5", tmp_path / "o.h5"
    write_recording(path, grid_recording().runs, provenance={})
    run_cli("hosidf", path, "-o", out, "--harmonics", 1).assert_one_line_error("--harmonics:", "at least 2")
    run_cli("hosidf", path, "-o", out, "--sweep", "p", "--model", tmp_path / "m.yaml").assert_one_line_error(
        "--model:", "not to --sweep")
    assert not out.exists()
