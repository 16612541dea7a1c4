"""`nlsid simulate` end to end on the example configs, seeds and noise, and bad input (exit 2)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from nlsid.io.recording import read_runs, write_recording
from nlsid.io.run import Run

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def write_excitation(path: Path, runs: list[Run]) -> Path:
    write_recording(path, runs, {"tool": "test"})
    return path


def multisine(run_id: str, fs: float, N: int, bins: np.ndarray, periods: int, transient: int, seed: int) -> Run:
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, bins.size)
    n = np.arange(N * periods)
    u = sum(np.cos(2 * np.pi * k * n / N + p) for k, p in zip(bins, phases)) / np.sqrt(bins.size / 2)
    return Run(run_id, fs, "multisine", u, period=N, transient_periods=transient, excited_bins=bins,
               realization=seed, level=1.0, params={"note": "from design"})


def sine(run_id: str, fs: float, N: int, k0: int, amplitude: float, periods: int, transient: int, phase=0.0) -> Run:
    n = np.arange(N * periods)
    u = amplitude * np.cos(2 * np.pi * k0 * n / N + phase)
    return Run(run_id, fs, "sine", u, period=N, transient_periods=transient, frequency=k0 * fs / N, level=amplitude)


@pytest.fixture
def multisine_file(tmp_path) -> Path:
    bins = np.arange(1, 200, 2)
    runs = [multisine(f"ms_{i:02d}", 1000.0, 1000, bins, 4, 2, seed=i) for i in range(3)]
    return write_excitation(tmp_path / "excitation.h5", runs)


def test_open_loop_recording_keeps_runs_and_has_the_stated_noise(run_cli, tmp_path, multisine_file):
    out = tmp_path / "rec.h5"
    result = run_cli("simulate", CONFIGS / "model_resonance.yaml", "--excitation", multisine_file, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["runs"] == 3
    excitation = read_runs(multisine_file, require_y=False)
    recording = read_runs(out)
    assert [r.run_id for r in recording] == [r.run_id for r in excitation]
    with h5py.File(out) as handle:
        assert handle.attrs["nlsid_format"] == "recording"
        assert "model_resonance.yaml" in handle.attrs["provenance"]
    noise_u = []
    for exc, rec in zip(excitation, recording):
        rec_attrs, exc_attrs = rec.attrs(), exc.attrs()
        np.testing.assert_array_equal(rec_attrs.pop("excited_bins"), exc_attrs.pop("excited_bins"))
        assert rec_attrs == exc_attrs
        assert rec.r is None
        noise_u.append(rec.u - exc.u)
    # 3 runs x 4000 samples of white noise with std 0.01: the sample std lies within
    # 4 standard errors (std / sqrt(2 n)) of 0.01, and the runs' streams are independent
    # (|correlation| < 4 / sqrt(n)).
    n = noise_u[0].size
    for e in noise_u:
        assert abs(np.std(e) - 0.01) < 4 * 0.01 / np.sqrt(2 * n)
    assert abs(np.corrcoef(noise_u[0], noise_u[1])[0, 1]) < 4 / np.sqrt(n)


def test_chains_after_nlsid_design(run_cli, tmp_path):
    # The excitation file written by `nlsid design` is read as it is; every run comes back with y.
    exc = tmp_path / "excitation.h5"
    assert run_cli("-q", "design", CONFIGS / "stage_design.yaml", "-o", exc).exit_code == 0
    out = tmp_path / "rec.h5"
    result = run_cli("simulate", CONFIGS / "model_lpl.yaml", "--excitation", exc, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    excitation, recording = read_runs(exc, require_y=False), read_runs(out)
    assert [r.run_id for r in recording] == [r.run_id for r in excitation]
    for e, r in zip(excitation, recording):
        np.testing.assert_array_equal(r.u, e.u)
        assert r.y is not None and r.kind == e.kind and r.period == e.period


def test_mcap_output_holds_the_same_numbers_as_hdf5(run_cli, tmp_path):
    exc = write_excitation(tmp_path / "sine.h5", [sine("s", 1024.0, 1024, 5, 0.8, 2, 1)])
    paths = [tmp_path / "rec.h5", tmp_path / "rec.mcap"]
    for path in paths:
        assert run_cli("simulate", CONFIGS / "model_lpl.yaml", "--excitation", exc, "-o", path).exit_code == 0
    h5, mcap = (read_runs(p)[0] for p in paths)
    np.testing.assert_array_equal(mcap.y, h5.y)
    np.testing.assert_array_equal(mcap.u, h5.u)


def noise_config(tmp_path, text: str) -> Path:
    path = tmp_path / "noise.yaml"
    path.write_text(text)
    return path


def test_process_noise_enters_the_plant_input(run_cli, tmp_path, multisine_file):
    # Static plant y = 2 (u + n_p): y - 2 u is the process noise times 2, white with std 2 * 0.05.
    config = noise_config(tmp_path, "model: {type: transfer_function, num: [2.0], den: [1.0]}\n"
                                    "disturbances: {process_noise: 0.05, seed: 3}\n")
    out = tmp_path / "rec.h5"
    assert run_cli("simulate", config, "--excitation", multisine_file, "-o", out).exit_code == 0
    for run in read_runs(out):
        e = run.y - 2 * run.u
        # sample std within 4 standard errors (std / sqrt(2 n)) of 0.1
        assert abs(np.std(e) - 0.1) < 4 * 0.1 / np.sqrt(2 * e.size)


def test_sensor_noise_is_fed_back_in_closed_loop(run_cli, tmp_path):
    # Plant y[k] = u[k-1] (discrete z^-1), P controller u = 0.5 (r - y - n_y). The noise part of u
    # obeys du[k] = -0.5 du[k-1] - 0.5 n[k]: AR(1) with variance 0.25 s^2 / (1 - 0.25) = s^2 / 3.
    # Compared with the same loop without noise. The std estimate of an AR(1) with rho = -0.5 has
    # a relative standard error sqrt((1 + rho^2) / (1 - rho^2) / (2 n)): 4 of them allowed.
    text = ("model: {type: transfer_function, domain: discrete, num: [0.0, 1.0], den: [1.0]}\n"
            "closed_loop: {controller: {type: pid, kp: 0.5}}\n")
    exc = write_excitation(tmp_path / "ms.h5", [multisine("ms", 1000.0, 1000, np.arange(1, 200, 2), 20, 1, 0)])
    paths = []
    for name, extra in (("clean", ""), ("noisy", "disturbances: {y_noise: 0.1, seed: 4}\n")):
        paths.append(tmp_path / f"{name}.h5")
        cfg = noise_config(tmp_path, text + extra)
        assert run_cli("simulate", cfg, "--excitation", exc, "-o", paths[-1]).exit_code == 0
    clean, noisy = (read_runs(p)[0] for p in paths)
    du = noisy.u - clean.u
    expected = 0.1 / np.sqrt(3)
    rel_se = np.sqrt((1 + 0.25) / (1 - 0.25) / (2 * du.size))
    assert abs(np.std(du) / expected - 1) < 4 * rel_se
    np.testing.assert_array_equal(noisy.r, clean.r)


def test_same_seed_same_numbers_other_seed_other_numbers(run_cli, tmp_path, multisine_file):
    paths = {}
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        paths[name] = tmp_path / f"{name}.h5"
        result = run_cli("simulate", CONFIGS / "model_resonance.yaml", "--excitation", multisine_file,
                         "-o", paths[name], "--seed", seed, "--workers", 2 if name == "b" else 1)
        assert result.exit_code == 0, result.stderr
    a, b, c = (read_runs(paths[k]) for k in "abc")
    for ra, rb, rc in zip(a, b, c):
        np.testing.assert_array_equal(ra.y, rb.y)
        assert np.max(np.abs(ra.y - rc.y)) > 0


def test_lpl_config_reproduces_seed_002_example_2(run_cli, tmp_path):
    # Example 2: Y(2 w0) = b2 gamma^2 / 2 G2-(w0)^2 e^{2 i phi}, Y(3 w0) = a3 gamma^3 / 4 G1+(3 w0) e^{3 i phi}
    # (single-sided amplitudes, exact for discrete blocks: agreement to rounding, 1e-9 relative).
    N, k0, gamma, phi = 1024, 5, 0.8, 0.4
    exc = write_excitation(tmp_path / "sine.h5", [sine("s", 1024.0, N, k0, gamma, 3, 2, phi)])
    out = tmp_path / "rec.h5"
    assert run_cli("simulate", CONFIGS / "model_lpl.yaml", "--excitation", exc, "-o", out).exit_code == 0
    y = read_runs(out)[0].periods("y")[-1]
    Y = 2 * np.fft.fft(y) / N
    z1 = np.exp(-2j * np.pi * k0 / N)
    g2 = 0.5 / (1 - 0.8 * z1)
    z3 = z1**3
    g1_3 = (0.3 + 0.2 * z3) / (1 - 0.6 * z3 + 0.25 * z3**2)
    assert Y[2 * k0] == pytest.approx(0.3 * gamma**2 / 2 * g2**2 * np.exp(2j * phi), rel=1e-9)
    assert Y[3 * k0] == pytest.approx(0.5 * gamma**3 / 4 * g1_3 * np.exp(3j * phi), rel=1e-9)


def test_duffing_config_doubles_its_period_at_0_81(run_cli, tmp_path):
    # Book Ex 79.a: A = 0.81 on line 8 of the last 8 periods -> a subharmonic on line 4.
    N = 1024
    exc = write_excitation(tmp_path / "sine.h5", [sine("s", N * 3.5 / (2 * np.pi), N, 1, 0.81, 100, 92)])
    out = tmp_path / "rec.h5"
    assert run_cli("simulate", CONFIGS / "model_duffing.yaml", "--excitation", exc, "-o", out).exit_code == 0
    spectrum = np.abs(np.fft.rfft(read_runs(out)[0].periods("y").reshape(-1)))
    assert spectrum[4] / spectrum[8] > 1e-2


def test_stage_sweep_records_r_u_y_and_k_fc(run_cli, tmp_path):
    # Seed 003's experiment: K_fc in [0, 0.3] at 80 values, one run per value with K_fc in params.
    N = 4096
    exc = write_excitation(tmp_path / "sine.h5", [sine("sine_00", 2048.0, N, 2, 6e-3, 3, 1)])
    out = tmp_path / "rec.h5"
    result = run_cli("simulate", CONFIGS / "model_stage_lugre.yaml", "--excitation", exc, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    runs = read_runs(out)
    values = np.linspace(0.0, 0.3, 80)
    assert [r.run_id for r in runs] == [f"sine_00_s{i:02d}" for i in range(80)]
    np.testing.assert_allclose([r.params["K_fc"] for r in runs], values, rtol=0, atol=0)
    for run in runs:
        np.testing.assert_array_equal(run.r, read_runs(exc, require_y=False)[0].u)
    # Linearity cost (seed 003 Eq. 4, harmonics 2..6 of line 2): LuGre friction with Coulomb level
    # fc = 1 N and break-away level fs = 1.5 N behind 5 N/V is best compensated between
    # fc / gain = 0.2 V and fs / gain = 0.3 V (sliding near the Coulomb level most of the time).
    costs = []
    for run in runs:
        Y = np.abs(np.fft.fft(run.periods("y").mean(axis=0)))
        costs.append(np.mean(Y[2 * np.arange(2, 7)]) / Y[2])
    best = values[int(np.argmin(costs))]
    assert 0.2 - 0.3 / 79 <= best <= 0.3
    assert costs[0] / min(costs) > 5


def test_bad_excitation_and_existing_output(run_cli, tmp_path, multisine_file):
    missing = tmp_path / "nope.h5"
    result = run_cli("simulate", CONFIGS / "model_resonance.yaml", "--excitation", missing, "-o", tmp_path / "o.h5")
    assert result.exit_code == 2 and "nope.h5: file not found" in result.stderr
    existing = tmp_path / "exists.h5"
    existing.write_text("keep")
    result = run_cli("simulate", CONFIGS / "model_resonance.yaml", "--excitation", multisine_file, "-o", existing)
    assert result.exit_code == 2 and "--force" in result.stderr
    assert existing.read_text() == "keep"


BAD = {
    "unstable": ("model: {type: transfer_function, num: [1.0], den: [1.0, -2.0]}\n",
                 ":1: model: unstable model: pole with real part 2"),
    "improper": ("model: {type: transfer_function, num: [1.0, 0.0, 0.0], den: [1.0, 1.0]}\n",
                 ":1: model: improper transfer function"),
    "empty_sweep": ("model: {type: transfer_function, num: [1.0], den: [1.0, 1.0]}\n"
                    "sweep: {parameter: model.delay, values: []}\n", ":2: sweep.values: expected at least 1 items, got 0"),
    "long_delay": ("model: {type: transfer_function, num: [1.0], den: [1.0, 1.0], delay: 10.0}\n",
                   "model.delay: dead time of 10000 samples is not shorter than the record (4000 samples)"),
    "fractional_delay": ("model: {type: transfer_function, domain: discrete, num: [0.0, 0.5], den: [1.0, -0.5], "
                         "delay: 0.0005}\n", "it must be a whole number of samples"),  # fractional: continuous only
    "negative_friction": ("model:\n  type: mass_spring_damper\n  mass: 1.0\n  stiffness: 100.0\n"
                          "  nonlinearities:\n    - {type: coulomb, fc: -0.5}\n",
                          ":6: model.nonlinearities[0].fc: must be > 0"),
    "negative_mass": ("model: {type: mass_spring_damper, mass: -1.0}\n", "model.mass: must be > 0"),
    "unknown_mass": ("model:\n  type: mass_spring_damper\n  mass: 1.0\n  stiffness: 1.0\n"
                     "  nonlinearities:\n    - {type: coulomb, fc: 0.5, at: load}\n",
                     ":6: model.nonlinearities[0].at: expected one of mass, got 'load'"),
    "noise_without_seed": ("model: {type: transfer_function, num: [1.0], den: [1.0, 1.0]}\n"
                           "disturbances: {y_noise: 0.1}\n", "disturbances.seed: noise needs a seed"),
    "unstable_loop": ("model: {type: mass_spring_damper, mass: 1.0}\n"
                      "closed_loop:\n  controller: {type: pid, kp: -5.0}\n",
                      ":2: closed_loop: the linear closed loop is unstable"),
    "ragged_matrix": ("model: {type: state_space, A: [[0.0, 1.0], [-1.0]], B: [0.0, 1.0], C: [1.0, 0.0]}\n",
                      "model.A: expected a square matrix"),
    "derivative_without_filter": ("model: {type: mass_spring_damper, mass: 1.0}\n"
                                  "closed_loop:\n  controller: {type: pid, kp: 1.0, kd: 0.1}\n",
                                  ":3: closed_loop.controller: a derivative action (kd > 0) needs a filter"),
    "unknown_block": ("model:\n  type: wiener\n  linear: {type: transfer_function, num: [1.0], den: [1.0, 1.0]}\n"
                      "  nonlinear: {type: cubic, a: 1.0}\n", ":4: model.nonlinear"),
    "discrete_substeps": ("model: {type: transfer_function, domain: discrete, num: [1.0], den: [1.0, -0.5]}\n"
                          "simulation: {substeps: 4}\n", ":2: simulation.substeps: a discrete-time model runs one step"),
    "discrete_causality": ("model: {type: transfer_function, domain: discrete, num: [1.0], den: [0.0, 1.0]}\n",
                           "model.den: den[0] (the z^0 coefficient) must be nonzero"),
    "swept_value_bad": ("model: {type: mass_spring_damper, mass: 1.0, stiffness: 1.0}\n"
                        "sweep: {parameter: model.mass, values: [1.0, -2.0]}\n",
                        "sweep value -2: model.mass: must be > 0"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_model_configs_exit_2_with_one_line(run_cli, tmp_path, multisine_file, name):
    text, fragment = BAD[name]
    config = tmp_path / f"{name}.yaml"
    config.write_text(text)
    out = tmp_path / "out.h5"
    result = run_cli("simulate", config, "--excitation", multisine_file, "-o", out)
    assert result.exit_code == 2, (result.stderr, result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert f"{name}.yaml" in lines[0], lines[0]
    assert fragment in lines[0], lines[0]
    assert not out.exists()


def test_steady_state_flag_simulates_one_period_in_periodic_steady_state(run_cli, tmp_path):
    """``--steady-state``: a periodic run without transient periods (P = 1, as a realization with
    its lead-in cut off) comes out in periodic steady state. The reference is the frequency
    domain: for a periodic input the steady-state output of a stable discrete LTI model is
    exactly Y(k) = G(e^{j 2 pi k / N}) U(k) on every DFT line, independent of the simulator.
    Without the flag the run is simulated from rest: its start differs by the transient."""
    num, den = [0.0, 0.05, 0.03], [1.0, -1.6, 0.9]  # a resonance with |pole| = 0.95: 20+ samples to settle
    model = tmp_path / "model.yaml"
    model.write_text(f"model:\n  type: transfer_function\n  domain: discrete\n  num: {num}\n  den: {den}\n")
    N = 256
    run = multisine("ms", 1000.0, N, np.arange(1, 100, 2), 1, 0, seed=3)
    excitation = write_excitation(tmp_path / "one_period.h5", [run])
    z = np.exp(2j * np.pi * np.arange(N // 2 + 1) / N)
    response = np.polyval(num[::-1], 1 / z) / np.polyval(den[::-1], 1 / z)  # coefficients of z^-i
    expected = np.fft.irfft(response * np.fft.rfft(run.u), N)
    for flag, out in (("--steady-state", "steady.h5"), (None, "rest.h5")):
        args = ["simulate", model, "--excitation", excitation, "-o", tmp_path / out] + ([flag] if flag else [])
        result = run_cli(*args)
        assert result.exit_code == 0, result.stderr
    (steady,), (rest,) = read_runs(tmp_path / "steady.h5"), read_runs(tmp_path / "rest.h5")
    scale = float(np.sqrt(np.mean(expected**2)))
    assert np.max(np.abs(steady.y - expected)) < 1e-6 * scale  # lead periods settle to 1e-6 (engine.STEADY_TOLERANCE)
    assert np.max(np.abs(rest.y[:20] - expected[:20])) > 0.1 * scale
    assert steady.transient_periods == 0 and steady.period == N
