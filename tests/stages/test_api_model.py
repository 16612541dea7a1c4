"""The library face of the design and simulate stages: ``nlsid.design`` and ``nlsid.Model``.

Truth comes from outside the code under test: a linear mass-spring-damper against scipy's exact
zero-order-hold discretisation (``cont2discrete``) of the same continuous system, designed
multisines against the line grid and levels the config asks for, sines against their formula.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import nlsid
from nlsid.errors import InputError

# The simulator runs a continuous LTI model through its zero-order-hold equivalent, exact for an
# input held between samples (docs/commands.md, "Numerical method and its error"); scipy's
# cont2discrete "zoh" is the same map computed independently, so the two differ by rounding only
# (about 1e-13 relative measured); 1e-9 relative is the bound that page asserts.
ZOH_RTOL = 1e-9


def msd_reference(u: np.ndarray, fs: float, mass: float, damping: float, stiffness: float,
                  gain: float = 1.0) -> np.ndarray:
    """Position of m x'' + c x' + k x = gain u from rest, u held over each sample (scipy ZOH)."""
    a = np.array([[0.0, 1.0], [-stiffness / mass, -damping / mass]])
    b = np.array([[0.0], [gain / mass]])
    c = np.array([[1.0, 0.0]])
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b, c, np.zeros((1, 1))), 1.0 / fs, method="zoh")
    _, y, _ = signal.dlsim((ad, bd, cd, dd, 1.0 / fs), u)
    return y[:, 0]


def msd(mass=2.0, damping=20.0, stiffness=2000.0, **extra) -> dict:
    return {"model": {"type": "mass_spring_damper", "mass": mass, "damping": damping, "stiffness": stiffness},
            **extra}


@pytest.fixture(scope="module")
def noise_input() -> np.ndarray:
    return np.random.default_rng(12).standard_normal(3000)


def test_linear_model_matches_the_exact_zoh_discretisation(noise_input):
    model = nlsid.Model.from_dict(msd())
    y = model.simulate(noise_input, fs=1000.0)
    ref = msd_reference(noise_input, 1000.0, 2.0, 20.0, 2000.0)
    assert y.shape == noise_input.shape
    assert np.max(np.abs(y - ref)) < ZOH_RTOL * np.max(np.abs(ref))


def test_with_parameters_simulates_the_changed_system(noise_input):
    base = nlsid.Model.from_dict(msd())
    changed = base.with_parameters({"model.mass": 0.5, "model.stiffness": np.float64(800.0)})
    y = changed.simulate(noise_input, fs=500.0)
    ref = msd_reference(noise_input, 500.0, 0.5, 20.0, 800.0)
    assert np.max(np.abs(y - ref)) < ZOH_RTOL * np.max(np.abs(ref))
    # the original is unchanged, and differs from the changed system by far more than rounding
    assert base.parameters == {"model.mass": 2.0, "model.damping": 20.0, "model.stiffness": 2000.0}
    assert np.max(np.abs(base.simulate(noise_input, fs=500.0) - ref)) > 0.1 * np.max(np.abs(ref))


def test_a_default_key_can_be_set_and_the_gain_scales_the_output(noise_input):
    model = nlsid.Model.from_dict(msd()).with_parameters({"model.gain": 3.0})
    ref = msd_reference(noise_input, 1000.0, 2.0, 20.0, 2000.0, gain=3.0)
    y = model.simulate(noise_input, fs=1000.0)
    assert np.max(np.abs(y - ref)) < ZOH_RTOL * np.max(np.abs(ref))
    assert model.parameters["model.gain"] == 3.0


def test_simulate_recording_gives_each_run_as_the_array_path(tmp_path, noise_input):
    model = nlsid.Model.from_dict(msd())
    exc = nlsid.design({"fs": 1000.0, "seed": 4, "multisine": {"period": 500, "band": [1.0, 100.0],
                                                                "realizations": 2, "periods": 2,
                                                                "rms_levels": [0.5]}})
    sim = model.simulate(exc)
    assert sim.run_ids == exc.run_ids and sim.signals == ["u", "y"]
    for run, source in zip(sim, exc):
        ref = msd_reference(source.u, 1000.0, 2.0, 20.0, 2000.0)
        assert np.array_equal(run.u, source.u)
        assert np.max(np.abs(run.y - ref)) < ZOH_RTOL * np.max(np.abs(ref))
        assert (run.period, run.level, run.realization) == (source.period, source.level, source.realization)
    path = exc.write(tmp_path / "exc.h5")
    from_file = model.simulate(path)
    assert all(np.array_equal(a.y, b.y) for a, b in zip(from_file, sim))
    assert str(path) in from_file.provenance["inputs"]


def test_noise_follows_the_config_seed_and_level(noise_input):
    sigma = 1e-4
    clean = nlsid.Model.from_dict(msd()).simulate(noise_input, fs=1000.0)
    noisy = nlsid.Model.from_dict(msd(disturbances={"y_noise": sigma, "seed": 3}))
    a, b = noisy.simulate(noise_input, fs=1000.0), noisy.simulate(noise_input, fs=1000.0)
    assert np.array_equal(a, b)  # the seed fixes the noise
    assert not np.array_equal(a, noisy.simulate(noise_input, fs=1000.0, seed=4))
    e = a - clean
    # the sample standard deviation of n white Gaussian samples has relative sd 1/sqrt(2 n): 1.3 %
    # at n = 3000; 5 of those is the tolerance
    assert abs(e.std() / sigma - 1) < 5 / np.sqrt(2 * e.size)
    assert abs(e.mean()) < 5 * sigma / np.sqrt(e.size)


def test_sweep_model_gives_one_run_per_value_and_refuses_an_array():
    model = nlsid.Model.from_dict(msd(sweep={"parameter": "model.damping", "name": "c", "values": [10.0, 40.0]}))
    assert model.points == [{"c": 10.0}, {"c": 40.0}]
    exc = nlsid.design({"fs": 1000.0, "seed": 1, "sines": {"period": 100, "frequencies": [50.0], "amplitudes": [1.0]}})
    sim = model.simulate(exc)
    assert sim.run_ids == ["sine_f000_a00_r00_s0", "sine_f000_a00_r00_s1"]
    for run, c in zip(sim, (10.0, 40.0)):
        assert run.params["c"] == c
        ref = msd_reference(exc[0].u, 1000.0, 2.0, c, 2000.0)
        assert np.max(np.abs(run.y - ref)) < ZOH_RTOL * np.max(np.abs(ref))
    with pytest.raises(InputError, match="^u: the model sweeps model.damping over 2 values"):
        model.simulate(np.ones(10))


def test_parameters_are_the_key_paths_of_sweep_and_free():
    config = {"model": {"type": "nonlinear_feedback",
                        "linear": {"type": "zpk", "poles": [[-5.0, 30.0]], "gain": 900.0},
                        "nonlinearities": [{"type": "coulomb", "fc": 0.5, "fv": 1}]},
              "closed_loop": {"controller": {"type": "pid", "kp": 2.0}, "computation_delay": 1},
              "disturbances": {"y_noise": 1e-6}}
    model = nlsid.Model.from_dict(config)
    assert model.parameters == {"model.linear.poles[0][0]": -5.0, "model.linear.poles[0][1]": 30.0,
                                "model.linear.gain": 900.0, "model.nonlinearities[0].fc": 0.5,
                                "model.nonlinearities[0].fv": 1, "closed_loop.controller.kp": 2.0,
                                "closed_loop.computation_delay": 1}
    changed = model.with_parameters({"model.linear.poles[0][1]": 40.0, "closed_loop.computation_delay": 2})
    assert changed.to_dict()["model"]["linear"]["poles"] == [[-5.0, 40.0]]
    assert changed.parameters["closed_loop.computation_delay"] == 2
    assert model.to_dict() == config  # unchanged, and a copy
    config["model"]["linear"]["gain"] = 1.0
    assert model.parameters["model.linear.gain"] == 900.0


@pytest.mark.parametrize("values, message", [
    ({"model.mass": -1.0}, "model.mass: must be > 0.0, got -1.0"),
    ({"model.mass": "heavy"}, "model.mass: expected a number, got 'heavy'"),
    ({"model.mass": True}, "model.mass: expected a number, got True"),
    ({"model.mass": float("nan")}, "model.mass: expected a finite number, got .nan"),
    ({"model.nonlinearities[0].fc": 1.0}, "model.nonlinearities[0].fc: no item [0]: model.nonlinearities has 0 items"),
    ({"sweep.values[0]": 1.0}, "sweep.values[0]: the sweep section holds no model parameter"),
    ({"model.mas": 1.0}, "model.mas: unknown key"),
])
def test_with_parameters_names_the_key_path(values, message):
    model = nlsid.Model.from_dict({"model": {**msd()["model"], "nonlinearities": []}})
    with pytest.raises(InputError) as error:
        model.with_parameters(values)
    assert str(error.value) == message


def test_dict_errors_name_the_key_path_without_a_line():
    with pytest.raises(InputError) as error:
        nlsid.Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": -3.0}})
    assert str(error.value) == "model.damping: must be >= 0.0, got -3.0"
    with pytest.raises(InputError) as error:
        nlsid.Model.from_dict([1, 2])
    assert str(error.value) == "config: expected a mapping of keys (a dict), got list"
    with pytest.raises(InputError) as error:
        nlsid.design({"fs": 1000.0, "seed": 1, "multisine": {"period": 64, "band": [1.0, 100.0],
                                                             "rms_levels": [1.0, -2.0]}})
    assert str(error.value) == "multisine.rms_levels[1]: must be > 0 and finite, got -2"
    with pytest.raises(InputError) as error:
        nlsid.design({"fs": 1000.0, "seed": 1})
    assert str(error.value) == "top level: give 'multisine', 'sines' or both"


def test_file_errors_keep_file_and_line(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("model:\n  type: mass_spring_damper\n  mass: 0.0\n")
    with pytest.raises(InputError) as error:
        nlsid.Model.from_yaml(path)
    assert str(error.value) == f"{path}:3: model.mass: must be > 0.0, got 0.0"


@pytest.mark.parametrize("kwargs, message", [
    ({"fs": 0.0}, "fs: expected a sample rate > 0 in Hz, got 0.0"),
    ({"fs": float("inf")}, "fs: expected a sample rate > 0 in Hz, got inf"),
    ({"steady": True}, "steady: needs a Recording"),
])
def test_simulate_array_arguments_are_named(kwargs, message):
    with pytest.raises(InputError, match=f"^{message}"):
        nlsid.Model.from_dict(msd()).simulate(np.ones(8), **kwargs)


def test_simulate_refuses_bad_samples_and_fs_with_a_recording():
    model = nlsid.Model.from_dict(msd())
    with pytest.raises(InputError, match=r"^u: 1 NaN or Inf samples \(first at index 2\)"):
        model.simulate(np.array([0.0, 1.0, np.nan]))
    with pytest.raises(InputError, match=r"^u: expected a 1-D real array, got shape \(2, 2\)"):
        model.simulate(np.ones((2, 2)))
    exc = nlsid.design({"fs": 1000.0, "seed": 1, "sines": {"period": 100, "frequencies": [50.0], "amplitudes": [1.0]}})
    with pytest.raises(InputError, match="^fs: a Recording carries its own sample rate"):
        model.simulate(exc, fs=1000.0)


def test_write_reads_back_the_same_config(tmp_path):
    config = {"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 1.0e-7, "stiffness": 2000,
                        "nonlinearities": [{"type": "coulomb", "fc": 0.5, "at": "on"}]},
              "sweep": {"parameter": "model.nonlinearities[0].fc", "name": "1e3", "values": [0.1, 0.2]},
              "free": {"model.mass": {"lower": 0.0, "upper": float("inf")}}}
    model = nlsid.Model.from_dict(config)  # "on" and "1e3" are text that YAML could read otherwise
    path = model.write(tmp_path / "model.yaml")
    back = nlsid.Model.from_yaml(path)
    assert back.to_dict() == config and back.path == str(path)
    assert back.points == [{"1e3": 0.1}, {"1e3": 0.2}]  # the name stays text, not the number 1000
    with pytest.raises(InputError, match="output exists"):
        model.write(path)
    with pytest.raises(InputError, match="suffix '.txt'"):
        model.write(tmp_path / "model.txt")


def test_design_multisine_lines_and_levels_follow_the_config():
    exc = nlsid.design("configs/stage_design.yaml")
    # configs/stage_design.yaml: fs 1024, N 2048 (0.5 Hz lines), band 0.5..60 Hz, random-odd in
    # groups of 3, levels 1, 2, 4 (rms), 3 realizations, 1 + 2 periods; sines 2, 5, 10 Hz x 1, 2, 4 x 3
    odd = np.arange(1, 121, 2)  # odd bins k with 0.5 <= 0.5 k <= 60
    m = exc.design["multisine"]
    excited, detection = np.array(m["excited_bins"]), np.array(m["detection_bins"])
    assert np.array_equal(np.union1d(excited, detection), odd) and np.intersect1d(excited, detection).size == 0
    # one detection line in each group of 3 consecutive odd lines
    assert all(np.isin(group, detection).sum() == 1 for group in odd.reshape(-1, 3))
    multisines = [run for run in exc if run.kind == "multisine"]
    assert len(multisines) == 9 and len(exc) == 9 + 27
    assert sorted({run.level for run in multisines}) == [1.0, 2.0, 4.0]
    for run in multisines:
        assert run.n_samples == 3 * 2048 and run.period == 2048 and run.transient_periods == 1
        one = run.u[:2048]
        assert np.array_equal(run.u, np.tile(one, 3))
        assert abs(np.sqrt(np.mean(one ** 2)) / run.level - 1) < 1e-12
        amplitude = 2 * np.abs(np.fft.rfft(one)) / 2048
        # equal amplitudes a sqrt(2 / F) on the F = 40 excited lines, nothing elsewhere
        assert np.allclose(amplitude[excited], run.level * np.sqrt(2 / 40), rtol=1e-12)
        assert np.max(np.delete(amplitude, excited)) < 1e-12 * run.level
    crest = [np.max(np.abs(r.u)) / np.sqrt(np.mean(r.u ** 2)) for r in multisines]
    assert np.allclose(m["crest_factors"], crest, rtol=1e-12)
    assert exc.design["duration_s"] == (9 * 3 * 2048 + 27 * 3 * 1024) / 1024
    assert "configs/stage_design.yaml" in exc.provenance["configs"] and exc.path is None
    # simulated, the excitation is no input file: the model config alone is named
    sim = nlsid.Model.from_yaml("configs/stage_true.yaml").simulate(exc)
    assert list(sim.provenance["configs"]) == ["configs/stage_true.yaml"] and sim.provenance["inputs"] == {}


def test_design_sines_follow_their_formula():
    exc = nlsid.design({"fs": 1000.0, "seed": 0, "unit": "N",
                        "sines": {"period": 200, "frequencies": [5.0, 35.0], "amplitudes": [0.5, 2.0], "repeats": 2,
                                  "periods": 3, "transient_periods": 0}})
    assert len(exc) == 8 and exc.design["sines"]["frequencies"] == [5.0, 35.0] and exc.units == {"u": "N"}
    t = np.arange(600) / 1000.0
    for run in exc:
        assert run.kind == "sine" and run.frequency in (5.0, 35.0) and run.level in (0.5, 2.0)
        assert np.max(np.abs(run.u - run.level * np.sin(2 * np.pi * run.frequency * t))) < 1e-12
    assert exc.design["duration_s"] == 8 * 0.6


def test_design_is_reproducible_and_the_seed_draws_the_phases():
    config = {"fs": 1000.0, "seed": 5, "multisine": {"period": 256, "band": [2.0, 200.0], "rms_levels": [1.0]}}
    a, b = nlsid.design(config), nlsid.design(dict(config))
    c = nlsid.design({**config, "seed": 6})
    assert np.array_equal(a[0].u, b[0].u)
    assert not np.array_equal(a[0].u, c[0].u)
    assert isinstance(a, nlsid.Recording) and a.path is None and a.provenance["configs"] == {}


def test_iter_runs_makes_one_run_at_a_time_and_then_the_summary():
    from nlsid.stages.design import iter_runs

    config = {"fs": 1000.0, "seed": 2, "multisine": {"period": 128, "band": [2.0, 200.0], "realizations": 3,
                                                     "rms_levels": [1.0, 2.0]}}
    made, summary = [], {}
    runs = iter_runs(config, summary, on_run=made.append)
    first = next(runs)
    assert [run.run_id for run in made] == [first.run_id] and summary == {}  # nothing made ahead
    rest = list(runs)
    whole = nlsid.design(config)
    assert [first.run_id] + [run.run_id for run in rest] == whole.run_ids and len(whole) == 6
    assert summary == whole.design and summary["runs"] == 6


def test_closed_loop_array_is_the_reference_and_integral_action_removes_the_static_error():
    # PI around m x'' + c x' + k x = u: characteristic polynomial 2 s^3 + 20 s^2 + 4000 s + 20000
    # (continuous), slowest root near -5 /s, so after 20 s the transient is exp(-100) of the step;
    # an integrator (a pole at z = 1) leaves no static error (final value theorem): y -> r to rounding
    model = nlsid.Model.from_dict({**msd(), "closed_loop": {"controller": {"type": "pid", "kp": 2000.0, "ki": 20000.0}}})
    y = model.simulate(np.full(20000, 1e-3), fs=1000.0)
    assert abs(y[-1] / 1e-3 - 1) < 1e-9
    # without the integrator y / r = kp / (k + kp) in steady state (poles -5 +- 44j /s): 1/2 here
    proportional = model.with_parameters({"closed_loop.controller.ki": 0.0})
    y = proportional.simulate(np.full(20000, 1e-3), fs=1000.0)
    assert abs(y[-1] / 1e-3 - 2000.0 / 4000.0) < 1e-9


def test_the_notebook_view_lists_every_number_of_the_config_file():
    """The table holds each number of the YAML file (read here with yaml, not through nlsid) by key path."""
    import re

    import yaml as pyyaml

    from generators import REPO

    path = REPO / "configs" / "stage_true.yaml"
    model = pyyaml.safe_load(path.read_text())["model"]
    html = nlsid.Model.from_yaml(path)._repr_html_()
    cells = dict(re.findall(r"<tr><td><code>([^<]+)</code></td><td>([^<]+)</td></tr>", html))
    expected = {f"model.{key}": value for key, value in model.items() if isinstance(value, (int, float))}
    expected["model.nonlinearities[0].fc"] = model["nonlinearities"][0]["fc"]
    for key, value in expected.items():
        assert float(cells[key]) == value, key
