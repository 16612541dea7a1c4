"""Friction that differs by direction (fc_pos / fc_neg, fv_pos / fv_neg, fs_pos / fs_neg; LuGre's
sides of fc, fs, sigma2) against independent references.

The main reference is exact: a free mass m v' = F - F_f(v) under a force F held over each sample
(ZOH) with F_f = fc_pos + fv_pos v for v > 0 and -fc_neg + fv_neg v for v < 0 moves between
stick/slip events along v(t) = v_inf + (v0 - v_inf) e^{-t fv/m}, v_inf = (F -+ fc) / fv of the
side; the time it reaches v = 0 is a logarithm, and at rest it sticks while F lies in
[-fc_neg, fc_pos], else it slides off on the side of F. Closed forms only, no ODE solver: the
differences measured are the simulator's discretisation error (first order, nlsid.models.forces).
The other truths are the thresholds of the law itself and steady sliding states solved by brentq.
Models go through the config schema and nlsid.models.from_config, as `nlsid simulate` does.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from nlsid.io.model_config import SimulateConfig
from nlsid.io.run import Run
from nlsid.models import forces
from nlsid.models.from_config import closed_loop, model
from nlsid.simulate.runs import simulate_run

M = 1.0
FS = 100.0  # Hz: Ts = 10 ms
SIDES = {"fc_pos": 1.0, "fc_neg": 1.2, "fv_pos": 2.0, "fv_neg": 3.0}  # backward: 20 % more Coulomb, 50 % more viscous


def config(force: dict, output: str = "position", substeps: int = 10, mass: float = M, damping: float = 0.0) -> dict:
    return {"model": {"type": "mass_spring_damper", "mass": mass, "damping": damping, "output": output,
                      "nonlinearities": [force]},
            "simulation": {"substeps": substeps}}


def simulate(data: dict, u) -> np.ndarray:
    cfg = SimulateConfig.model_validate(data)
    run = Run("r", FS, "arbitrary", np.asarray(u, dtype=float))
    return simulate_run(model(cfg), closed_loop(cfg), run, cfg.simulation.substeps).y


def coulomb_reference(m: float, fc_pos: float, fc_neg: float, fv_pos: float, fv_neg: float, force, fs: float):
    """Sampled (x, v) at the start of each interval of m v' = F - F_f(v), F held per interval, from
    rest, by the piecewise exponential solution between events (module docstring); fv > 0."""
    x = v = 0.0
    xs, vs = np.empty(len(force)), np.empty(len(force))
    events = 0
    for i, F in enumerate(force):
        xs[i], vs[i] = x, v
        t, t_end = 0.0, 1.0 / fs
        while t < t_end:
            if v == 0.0:
                if -fc_neg <= F <= fc_pos:
                    break  # sticks for the rest of the interval: the force needed, F, is within the set
                s = 1.0 if F > 0 else -1.0
                events += 1
            else:
                s = 1.0 if v > 0 else -1.0
            fc, fv = (fc_pos, fv_pos) if s > 0 else (fc_neg, fv_neg)
            rate = fv / m
            v_inf = (F - s * fc) / fv
            dt, stops = t_end - t, False
            if v_inf * s < 0:  # decelerates through v = 0 at t0
                t0 = math.log((v - v_inf) / -v_inf) / rate
                if t0 < dt:
                    dt, stops = t0, True
            decay = math.exp(-rate * dt)
            x += v_inf * dt + (v - v_inf) * (1.0 - decay) / rate
            v = 0.0 if stops else v_inf + (v - v_inf) * decay
            events += stops
            t += dt
    return xs, vs, events


def _push(n: int = 300) -> np.ndarray:
    """2.5 N sine of 1 s plus 0.3 N: slides both ways, sticks at one turn (4 samples), reverses within
    an interval without sticking at the other."""
    return 0.3 + 2.5 * np.sin(2 * np.pi * np.arange(n) / FS)


def test_asymmetric_coulomb_viscous_mass_matches_the_exact_piecewise_solution():
    u = _push()
    x_ref, v_ref, events = coulomb_reference(M, *SIDES.values(), u, FS)
    # the reference sticks, slides forward and backward (so both sides of the law are exercised)
    assert np.sum(v_ref == 0.0) > 10 and v_ref.max() > 0.2 and v_ref.min() < -0.1 and events >= 6
    force = {"type": "coulomb", **SIDES}
    errors_x, errors_v = {}, {}
    for substeps in (10, 40, 160):
        h = 1.0 / (FS * substeps)
        x = simulate(config(force, "position", substeps), u)
        v = simulate(config(force, "velocity", substeps), u)
        errors_x[substeps] = np.max(np.abs(x - x_ref))
        errors_v[substeps] = np.max(np.abs(v - v_ref))
        # A-priori bound of a first-order step (Moreau's, which nlsid used before the reversal
        # was located; the present step is second order, so it meets it with a wide margin): (a) an event inside a
        # sub-step misplaces the jump of the friction force, at most fc_pos + fc_neg, for at most h:
        # velocity off by <= (fc_pos + fc_neg) h / m per event; (b) while sliding, the Moreau step
        # holds the viscous force at its end velocity (backward Euler in fv v): a velocity error of
        # at most (fv / m) |v'| h^2 / 2 per sub-step, |v'| <= (|F| + fc + fv |v|) / m, summed over
        # the sliding time T <= the record length. The bound leaves out that fv / m (2-3 /s) damps
        # both, and the position error is at most the record length times the velocity bound.
        T = len(u) / FS
        jump = (SIDES["fc_pos"] + SIDES["fc_neg"]) / M
        fv_max = max(SIDES["fv_pos"], SIDES["fv_neg"])
        accel = (np.max(np.abs(u)) + SIDES["fc_neg"] + fv_max * np.max(np.abs(v_ref))) / M
        bound_v = events * jump * h + (fv_max / M) * accel * h * T / 2
        assert errors_v[substeps] <= bound_v
        assert errors_x[substeps] <= bound_v * T
    # second order (nlsid.models.forces, coulomb: the force is the mean over the sub-step's velocity
    # path, reversals located): 4x finer sub-steps divide the error by about 16 (measured 12-17;
    # first order, Moreau's step, gave 3.5-4.0)
    for coarse, fine in ((10, 40), (40, 160)):
        assert 10.0 <= errors_x[coarse] / errors_x[fine] <= 24.0
        assert 10.0 <= errors_v[coarse] / errors_v[fine] <= 24.0
    # The a-priori bound is loose (the ratios above are the sharp check), but the match resolves
    # each side: the symmetric law at the mean levels, and a 2 % change of any one side's
    # parameter, are off by far more than the error at 160 sub-steps (measured 1.8e-9 m).
    mean = {"type": "coulomb", "fc": 1.1, "fv": 2.5}
    assert np.max(np.abs(simulate(config(mean, "position", 160), u) - x_ref)) > 1000 * errors_x[160]
    for key in SIDES:
        changed = {"type": "coulomb", **SIDES, key: 1.02 * SIDES[key]}
        assert np.max(np.abs(simulate(config(changed, "position", 160), u) - x_ref)) > 50 * errors_x[160], key


@pytest.mark.parametrize("symmetric, sided", [
    ({"type": "coulomb", "fc": 1.1, "fv": 0.4}, {"type": "coulomb", "fc_pos": 1.1, "fc_neg": 1.1, "fv_pos": 0.4, "fv_neg": 0.4}),
    ({"type": "coulomb", "fc": 1.1}, {"type": "coulomb", "fc_pos": 1.1, "fc_neg": 1.1, "fv": 0.0}),
    ({"type": "stribeck", "fc": 1.0, "fs": 1.5, "vs": 0.05, "fv": 0.3},
     {"type": "stribeck", "fc_pos": 1.0, "fc_neg": 1.0, "fs_pos": 1.5, "fs_neg": 1.5, "vs": 0.05,
      "fv_pos": 0.3, "fv_neg": 0.3}),
    ({"type": "lugre", "sigma0": 1e4, "sigma1": 50.0, "sigma2": 0.3, "fc": 1.0, "fs": 1.5, "vs": 0.05},
     {"type": "lugre", "sigma0": 1e4, "sigma1": 50.0, "sigma2_pos": 0.3, "sigma2_neg": 0.3, "fc_pos": 1.0,
      "fc_neg": 1.0, "fs_pos": 1.5, "fs_neg": 1.5, "vs": 0.05}),
])
def test_symmetric_config_runs_exactly_as_equal_sides(symmetric, sided):
    # One law in the kernel: the symmetric form is the case of equal sides, bit for bit.
    for form in (symmetric, sided):
        SimulateConfig.model_validate(config(form))  # both forms valid
    kind_a, params_a = forces.encode(SimulateConfig.model_validate(config(symmetric)).model.nonlinearities[0])
    kind_b, params_b = forces.encode(SimulateConfig.model_validate(config(sided)).model.nonlinearities[0])
    assert kind_a == kind_b
    np.testing.assert_array_equal(params_a, params_b)
    u = _push(200)
    np.testing.assert_array_equal(simulate(config(symmetric, "position", 4), u), simulate(config(sided, "position", 4), u))


def _coulomb_sides(fc_pos=1.0, fc_neg=1.2) -> dict:
    return {"type": "coulomb", "fc_pos": fc_pos, "fc_neg": fc_neg}


@pytest.mark.parametrize("law", ["coulomb", "stribeck"])
def test_sticking_set_is_minus_neg_to_pos(law):
    # At rest the mass holds any constant force within [-fc_neg, fc_pos] (Stribeck: [-fs_neg,
    # fs_pos]); the set's ends differ, so a force of 1.1 N moves it forward but not backward.
    pos, neg = 1.0, 1.2
    if law == "coulomb":
        force = _coulomb_sides(pos, neg)
    else:  # sliding levels well below the break-away ones: the thresholds are fs_pos, fs_neg
        force = {"type": "stribeck", "fc_pos": 0.5, "fc_neg": 0.6, "fs_pos": pos, "fs_neg": neg, "vs": 0.05}
    n = 200
    for F in (0.999 * pos, -0.999 * neg, -1.1, 0.5, -1.15):
        x = simulate(config(force, "position", 4), np.full(n, F))
        # stuck: the position moves by rounding only (the held force's effect cancels to ~eps F h^2 / m)
        assert np.max(np.abs(x)) < 1e-15, (law, F)
    for F, sign in ((1.001 * pos, 1.0), (1.1, 1.0), (-1.001 * neg, -1.0)):
        x = simulate(config(force, "position", 4), np.full(n, F))
        # moving off on the side of F: after the first interval the excess force (0.1 % of the
        # threshold, >= 1e-3 N) has moved the mass by (F - threshold) Ts^2 / 2m (Coulomb; Stribeck
        # more, its level falling below fs): at least half that
        assert x[1] * sign > 0.25 * abs(abs(F) - (pos if sign > 0 else neg)) * (1 / FS) ** 2 / M, (law, F)
        assert np.all(np.diff(x[1:]) * sign > 0), (law, F)


def test_stribeck_breaks_away_at_each_directions_static_level():
    # A held force ramp of 0.002 N per sample from 0.0005 N, forward and backward: the mass stays
    # at rest until the force exceeds fs_pos = 1.5 N (forward) or fs_neg = 1.7 N (backward), first
    # on the interval k = 750 and k = 850; the velocity, read at the start of an interval, is first
    # nonzero one sample later.
    k = np.arange(1500)
    force = {"type": "stribeck", "fc_pos": 1.0, "fc_neg": 1.1, "fs_pos": 1.5, "fs_neg": 1.7, "vs": 1e-3}
    for sign, first in ((1.0, 751), (-1.0, 851)):
        v = simulate(config(force, "velocity", 8), sign * (0.002 * k + 0.0005))
        moving = np.flatnonzero(np.abs(v) > 1e-15)
        assert moving[0] == first
        assert np.all(v[moving[0]:] * sign > 0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_stribeck_steady_sliding_per_direction(sign):
    # A constant push F against Stribeck friction with per-direction levels and viscous terms:
    # the steady speed w solves |F| = fv_side w + fc_side + (fs_side - fc_side) e^{-(w/vs)^2}
    # (brentq; the only root, slope ~ fv > 0), which the implicit step holds exactly.
    from scipy.optimize import brentq

    side = {1.0: (1.0, 1.5, 200.0), -1.0: (1.2, 1.8, 150.0)}  # fc, fs, fv of each direction
    force = {"type": "stribeck", "fc_pos": 1.0, "fc_neg": 1.2, "fs_pos": 1.5, "fs_neg": 1.8, "vs": 1e-3,
             "fv_pos": 200.0, "fv_neg": 150.0}
    fc, fs, fv = side[sign]
    F = 1.9
    vs = 1e-3
    w = brentq(lambda w: fv * w + fc + (fs - fc) * math.exp(-((w / vs) ** 2)) - F, 1e-9, 1.0, xtol=1e-15)
    v = simulate(config(force, "velocity", 8), np.full(2000, sign * F))
    assert v[-1] == pytest.approx(sign * w, rel=1e-9)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_lugre_steady_sliding_per_direction(sign):
    # Steady LuGre sliding: z' = 0, so z = s(v) / sigma0 and F_f = s(v) + sigma2 v with the side's
    # fc, fs (in s) and sigma2; against a push F and the plant's damping c the steady speed w
    # solves |F| = c w + sigma2_side w + s_side(w) (brentq). The step holds that fixed point to the
    # solver's tolerance.
    from scipy.optimize import brentq

    c, F, vs = 200.0, 1.9, 1e-3
    side = {1.0: (1.0, 1.5, 10.0), -1.0: (1.2, 1.8, 40.0)}  # fc, fs, sigma2
    force = {"type": "lugre", "sigma0": 1e5, "sigma1": 300.0, "fc_pos": 1.0, "fc_neg": 1.2, "fs_pos": 1.5,
             "fs_neg": 1.8, "sigma2_pos": 10.0, "sigma2_neg": 40.0, "vs": vs}
    fc, fs, sigma2 = side[sign]
    w = brentq(lambda w: (c + sigma2) * w + fc + (fs - fc) * math.exp(-((w / vs) ** 2)) - F, 1e-9, 1.0, xtol=1e-15)
    v = simulate(config(force, "velocity", 8, damping=c), np.full(2000, sign * F))
    assert v[-1] == pytest.approx(sign * w, rel=1e-8)


def test_lugre_presliding_turns_around_both_sides():
    # Under a sine the LuGre mass reverses many times, through both sides' Newton solves: finite,
    # bounded, and the backward excursions (higher levels backward) are the smaller ones.
    force = {"type": "lugre", "sigma0": 1e4, "sigma1": 100.0, "fc_pos": 1.0, "fc_neg": 1.2, "fs_pos": 1.5,
             "fs_neg": 1.8, "vs": 0.01}
    v = simulate(config(force, "velocity", 4, damping=1.0), 2.5 * np.sin(2 * np.pi * np.arange(400) / FS))
    assert np.all(np.isfinite(v)) and v.max() > 0.1 and v.min() < -0.05
    assert v.max() > -v.min()


def test_cli_simulate_runs_an_asymmetric_config(run_cli, tmp_path):
    # `nlsid simulate` end to end: the recording's y is the library's output for the same config.
    from nlsid.io.recording import read_runs, write_recording

    u = _push(200)
    excitation = tmp_path / "exc.h5"
    write_recording(excitation, [Run("a", FS, "arbitrary", u)], {"tool": "test"})
    data = config({"type": "coulomb", **SIDES}, "position", 10)
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(data))
    result = run_cli("simulate", path, "--excitation", excitation, "-o", tmp_path / "rec.h5")
    assert result.exit_code == 0, result.stderr
    (run,) = read_runs(tmp_path / "rec.h5")
    np.testing.assert_array_equal(run.y, simulate(data, u))
    x_ref = coulomb_reference(M, *SIDES.values(), u, FS)[0]
    assert np.max(np.abs(run.y - x_ref)) < 1e-3


def test_force_regression_estimates_each_side():
    # `nlsid fit --model --start-estimate`: the regression of the residual force on [v > 0] and
    # -[v < 0] (nlsid.fit.start) gives both sides. Its systematic errors (the hold, the harmonics cut
    # off, sticking left out; tests/fit/test_fit_extension.py) are alike on both sides, so each side is
    # within the 25 % required there and their ratio, the asymmetry, within 5 % (measured 22 % low,
    # ratio 1.23 for 1.2).
    import sys
    from pathlib import Path

    from nlsid.fit.start import force_regression
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.simulate.batch import simulate_all
    from nlsid.simulate.sweep import SweepPoint

    from generators.bla_cases import multisine

    fs, n, periods = 1000.0, 1024, 3
    rng = np.random.default_rng(1)
    bins = np.arange(1, 60)
    excitation = [Run(f"ms{m}", fs, "multisine", np.tile(multisine(n, bins, 3.0, rng), periods + 1), period=n,
                      transient_periods=1, realization=m, excited_bins=bins) for m in range(4)]
    true = {"model": {"type": "mass_spring_damper", "mass": 1.0, "damping": 20.0, "stiffness": 4000.0,
                      "nonlinearities": [{"type": "coulomb", "fc_pos": 0.5, "fc_neg": 0.6}]}}
    runs = simulate_all([SweepPoint({}, validate_simulate_config(true, "true", {}))], excitation)
    paths = [f"model.nonlinearities[0].{key}" for key in ("fc_pos", "fc_neg")]
    pos, neg = (force_regression(true, runs, paths)[path] for path in paths)
    assert pos == pytest.approx(0.5, rel=0.25) and neg == pytest.approx(0.6, rel=0.25)
    assert neg / pos == pytest.approx(1.2, rel=0.05)


@pytest.mark.parametrize("force, message", [
    ({"type": "coulomb", "fc": 1.0, "fc_pos": 1.0, "fc_neg": 1.2}, "give fc or fc_pos and fc_neg, not both"),
    ({"type": "coulomb", "fc": 1.0, "fv": 0.1, "fv_neg": 0.2}, "give fv or fv_pos and fv_neg, not both"),
    ({"type": "coulomb", "fc_pos": 1.0}, "fc_pos without fc_neg: give both, or fc alone"),
    ({"type": "coulomb", "fc": 1.0, "fv_neg": 0.2}, "fv_neg without fv_pos: give both, or fv alone"),
    ({"type": "coulomb", "fv": 0.2}, "give fc, or fc_pos and fc_neg"),
    ({"type": "coulomb", "fc_pos": 1.0, "fc_neg": -1.2}, "nonlinearities[0].fc_neg: must be > 0"),
    ({"type": "coulomb", "fc": 1.0, "fv_pos": -0.1, "fv_neg": 0.1}, "nonlinearities[0].fv_pos: must be >= 0"),
    ({"type": "stribeck", "fc": 1.0, "fs_pos": 1.5, "vs": 0.01}, "fs_pos without fs_neg: give both, or fs alone"),
    ({"type": "stribeck", "fc": 1.0, "fs": 1.5, "fs_neg": 1.5, "vs": 0.01}, "give fs or fs_pos and fs_neg, not both"),
    ({"type": "stribeck", "fc_pos": 1.0, "fc_neg": 0.0, "fs": 1.5, "vs": 0.01}, "fc_neg: must be > 0"),
    ({"type": "lugre", "sigma0": 1e4, "fc": 1.0, "fs": 1.5, "vs": 0.01, "sigma2": 1.0, "sigma2_pos": 1.0,
      "sigma2_neg": 2.0}, "give sigma2 or sigma2_pos and sigma2_neg, not both"),
    ({"type": "lugre", "sigma0": 1e4, "fc_neg": 1.0, "fs": 1.5, "vs": 0.01}, "fc_neg without fc_pos: give both, or fc alone"),
])
def test_config_errors_are_one_line(run_cli, tmp_path, force, message):
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(config(force)))
    result = run_cli("simulate", path, "--excitation", tmp_path / "missing.h5", "-o", tmp_path / "out.h5")
    result.assert_one_line_error(str(path), "model.nonlinearities[0]", message)
