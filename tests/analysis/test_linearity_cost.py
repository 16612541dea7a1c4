"""Seed 003: linearity cost (Definitions 2-3, Eq. 7) and friction feed-forward tuning end to end."""

import numpy as np
import pytest

from nlsid.analysis.hosidf import HarmonicStats
from nlsid.analysis.linearity_cost import linearity_costs, sweep, time_error
from nlsid.errors import InputError
from nlsid.io.run import Run

FS, N, F0, GAMMA = 1000.0, 1000, 1.0, 0.01  # one 1 Hz sine of 10 mm per 1000-sample period
FC = 0.93  # true Coulomb friction [N]; not on the K_fc grid below
KFC = np.arange(0.0, 1.61, 0.04)  # the sweep, steps of 4.3 % of FC


def closed_loop(kfc, damping, periods=3, transient=2, mass=1.0, kp=1e4, kd=100.0, substeps=10, noise=0.0, seed=0):
    """Independent simulation of the seed 003 Fig. 1 loop, for all K_fc values at once (vectorised).

    Plant: m x'' = F - c x' - F_fric, with Coulomb friction in the Karnopp form: the mass sticks
    (v = 0) while |v| < 1e-5 m/s and the applied force |F - c v| <= F_c; otherwise
    F_fric = F_c sign(v) (sign(F) when starting to slip). Controller: PD on e = r - x (P alone
    leaves a loop without damping oscillating when c = 0) plus the feed-forward
    K_fc sign(dr/dt). Reference r = GAMMA sin(2 pi F0 t). Semi-implicit Euler with `substeps`
    steps per sample (1e-4 s; the loop's natural frequency is 100 rad/s). Output y = x sampled,
    plus white measurement noise of sd `noise`.
    """
    kfc = np.asarray(kfc, dtype=float)
    dt, w = 1.0 / FS / substeps, 2 * np.pi * F0
    total = (periods + transient) * N
    x, v = np.zeros(kfc.size), np.full(kfc.size, GAMMA * w)
    y = np.empty((kfc.size, total))
    for i in range(total):
        y[:, i] = x
        for j in range(substeps):
            t = (i * substeps + j) * dt
            force = kp * (GAMMA * np.sin(w * t) - x) + kd * (GAMMA * w * np.cos(w * t) - v)
            force = force + kfc * np.sign(np.cos(w * t)) - damping * v
            slipping = np.abs(v) >= 1e-5
            stick = ~slipping & (np.abs(force) <= FC)
            friction = FC * np.where(slipping, np.sign(v), np.sign(force))
            v = np.where(stick, 0.0, v + (force - friction) / mass * dt)
            x = x + v * dt
    y += noise * np.random.default_rng(seed).standard_normal(y.shape)
    r = GAMMA * np.sin(2 * np.pi * F0 * np.arange(total) / FS)
    return [Run(run_id=f"kfc_{i:02d}", fs=FS, kind="sine", u=r, r=r, y=y[i], period=N, transient_periods=transient,
                level=GAMMA, frequency=F0, params={"K_fc": float(k)}) for i, k in enumerate(kfc)]


def test_frequency_optimum_at_fc_and_time_optimum_above_with_damping():
    """Seed 003 Section IV-D ("apples and oranges"), with viscous damping c = 5 N s/m.

    Frequency domain: the harmonics vanish when K_fc sign(r') cancels F_c sign(x'), i.e. at
    K_fc = F_c; the grid point nearest F_c is 0.92 (1.1 % away) and the claim of the issue is
    within 5 %. Time domain: the fundamental of K_fc sign(r') is (4/pi) K_fc in phase with r',
    so it also cancels the damping force c r' (amplitude c GAMMA w) at
    K_fc = F_c + c GAMMA w pi/4 = 0.93 + 0.247 = 1.177; the harmonics it leaves pull the optimum
    back towards F_c, so the time optimum lies in (F_c, 1.177 + one grid step].
    """
    result = sweep(closed_loop(KFC, damping=5.0, noise=1e-7), "K_fc", harmonics=9, reference="r")
    assert abs(result.optimum - FC) <= 0.05 * FC
    upper = FC + 5.0 * GAMMA * 2 * np.pi * F0 * np.pi / 4
    assert FC * 1.05 < result.time_optimum <= upper + 0.04
    # noise of 1e-7 m: far from the optimum odd harmonics 3, 5, 7, 9 clear their bound (Eq. 6)
    assert result.points[0].used[[3, 5, 7, 9]].all()


def test_without_damping_both_optima_coincide():
    """c = 0: nothing but friction to cancel, so both measures are minimal at the same K_fc near F_c."""
    result = sweep(closed_loop(KFC, damping=0.0), "K_fc", harmonics=9, reference="r")
    assert result.optimum == result.time_optimum
    assert abs(result.optimum - FC) <= 0.05 * FC


def test_costs_by_hand():
    """Definitions 2 and 3 on hand-made statistics: |Y| = [0.5, 2, 0.2, 0.1, 0.05], bound 0.08.

    Definition 2: (0.2 + 0.1 + 0.05) / 3 / 2 = 0.058333; Definition 3 uses k = 2, 3 only
    (0.05 < 0.08): (0.2 + 0.1) / 2 / 2 = 0.075.
    """
    mean = np.array([0.5, 2j, -0.2, 0.1j, 0.05])
    stats = HarmonicStats(mean, np.zeros(5), 0.0, 0.0, np.full(5, 0.08))
    cost, cost_all, used = linearity_costs(stats)
    assert cost == pytest.approx(0.075)
    assert cost_all == pytest.approx(0.35 / 6)
    np.testing.assert_array_equal(used, [False, False, True, True, False])
    quiet = HarmonicStats(mean * np.array([1, 1, 0.1, 0.1, 0.1]), np.zeros(5), 0.0, 0.0, np.full(5, 0.08))
    assert linearity_costs(quiet)[0] == 0.0  # no harmonic above the noise: linear within the noise


def test_time_error_is_the_worst_period_rms():
    """Eq. 7: periods with errors 0, a constant 3, and a square wave of amplitude 1 -> max rms 3."""
    r = np.zeros(12)
    y = np.concatenate([np.zeros(4), np.full(4, -3.0), np.array([1.0, -1.0, 1.0, -1.0])])
    run = Run(run_id="t", fs=4.0, kind="sine", u=r, r=r, y=y, period=4, transient_periods=0, level=1.0, frequency=1.0)
    assert time_error(run, "r") == pytest.approx(3.0)


def test_bad_sweeps_are_reported():
    runs = closed_loop([0.0, 0.5], damping=0.0, periods=2, transient=0, substeps=1)
    runs[1].params = {"other": 1.0}
    with pytest.raises(InputError, match=r"rec.h5:/runs/kfc_01.params: sweep parameter 'K_fc' is missing"):
        sweep(runs, "K_fc", harmonics=5, reference="r", source="rec.h5")
    runs[1].params = {"K_fc": 0.5}
    runs[1].level = 2 * GAMMA
    with pytest.raises(InputError, match="one sine"):
        sweep(runs, "K_fc", harmonics=5, reference="r", source="rec.h5")


@pytest.mark.parametrize("damping", [5.0, 0.0])
def test_pipeline_with_project_simulator(run_cli, tmp_path, damping):
    """design -> simulate (the project's closed loop, K_fc swept) -> hosidf --sweep: seed 003's claim.

    Same loop and grid as above (F_c = 0.93, PD 1e4/100 with a 0.5 ms derivative filter, sine of
    10 mm at 1 Hz). Frequency optimum within 5 % of F_c; with damping the time optimum lies in
    (1.05 F_c, F_c + c GAMMA w pi/4 + one step] (see the first test), without it the two coincide.
    """
    (tmp_path / "design.yaml").write_text(
        f"fs: {FS}\nseed: 1\nsines:\n  period: {N}\n  frequencies: [{F0}]\n  amplitudes: [{GAMMA}]\n"
        "  repeats: 1\n  periods: 3\n  transient_periods: 2\n")
    (tmp_path / "stage.yaml").write_text(
        f"model:\n  type: mass_spring_damper\n  mass: 1.0\n  damping: {damping}\n"
        f"  nonlinearities:\n    - {{type: coulomb, fc: {FC}}}\n"
        "closed_loop:\n  controller: {type: pid, kp: 10000.0, kd: 100.0, tau: 0.0005}\n"
        "disturbances: {y_noise: 1.0e-7, seed: 3}\n"
        "sweep:\n  parameter: closed_loop.feedforward.coulomb\n  name: K_fc\n"
        f"  linspace: {{start: 0.0, stop: 1.6, num: {KFC.size}}}\n")
    for args in (("design", tmp_path / "design.yaml", "-o", tmp_path / "exc.h5"),
                 ("simulate", tmp_path / "stage.yaml", "--excitation", tmp_path / "exc.h5", "-o", tmp_path / "rec.h5",
                  "--workers", 1)):
        assert run_cli(*args).exit_code == 0
    result = run_cli("hosidf", tmp_path / "rec.h5", "-o", tmp_path / "s.h5", "--sweep", "K_fc", "--harmonics", 9, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()["sweep"]
    assert abs(summary["optimum"] - FC) <= 0.05 * FC
    if damping:
        assert FC * 1.05 < summary["time_optimum"] <= FC + damping * GAMMA * 2 * np.pi * F0 * np.pi / 4 + 0.04
    else:
        assert summary["time_optimum"] == summary["optimum"]
