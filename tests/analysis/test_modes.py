"""Modes that move with the excitation level: the BLA of each level fitted mode by mode.

The structure: five modes in modal form, force in, acceleration out,
``y = sum_j r_j a_j`` with ``q_j'' + 2 zeta_j w_j q_j' + w_j^2 q_j = f`` and ``a_j = q_j''``. Four
modes are linear and stepped exactly (zero-order hold, scipy.signal.cont2discrete and lfilter);
the mode at 7.3 Hz carries a softening cubic spring ``+ K3 q^3`` (K3 < 0) on its modal coordinate,
stepped by RK4 with the force held over the sample (checked against half the step). Multisines of
four levels (rms force 1 : 2 : 4 : 8) drive it; the measured output carries white noise and a
50 Hz mains line, the measured force the mains line too, declared excited at the lowest level.

Truth of the moving mode, independently of any fit: for a random-phase multisine of many lines
the modal coordinate is nearly Gaussian, and the best linear approximation of the cubic force
``K3 q^3`` is ``3 K3 sigma_q^2 q`` (Bussgang; exact to first order in K3), so the BLA is the linear
structure with the mode's stiffness ``w^2 + 3 K3 sigma_q^2``: natural frequency
``f_eq = sqrt(w^2 + 3 K3 sigma_q^2) / (2 pi)``, damping ratio ``zeta w / sqrt(w^2 + 3 K3 sigma_q^2)``.
``sigma_q^2 = sum_k (A_k^2 / 2) |H_q(k)|^2`` over the lines of amplitude ``A_k`` with the sampled
(ZOH) receptance of the linearised mode, solved for ``sigma_q^2`` by fixed-point iteration
(statistical linearisation). Its error is of second order in the stiffness change (at most 4 %
here, so about 0.04 % of the frequency); the test allows it beside the fit's standard errors.
"""

from __future__ import annotations

import functools
import re

import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import multisine

from nlsid.analysis.levels import across_levels, analyse_runs
from nlsid.diagnose.bla_comparison import level_findings
from nlsid.io.bla_file import read_bla
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

FS, N, P, T, M = 128.0, 4096, 2, 1, 3
FREQ = np.array([3.1, 7.3, 11.8, 17.5, 24.0])
ZETA = np.array([0.03, 0.025, 0.02, 0.02, 0.015])
RESIDUE = np.array([1.0, 0.8, -0.6, 0.5, 0.4])
W = 2 * np.pi * FREQ
MOVING = 1
RMS = (0.5, 1.0, 2.0, 4.0)
BINS = np.arange(48, 961)  # 1.5 .. 30 Hz at 1/32 Hz
MAINS_BIN = 1600  # 50 Hz
NOISE_Y = 2e-3
SUBSTEPS = 2


def linear_mode_acceleration(j: int, f: np.ndarray) -> np.ndarray:
    """Acceleration of linear mode j under the sampled force, exact for a force held over each sample."""
    A = np.array([[0.0, 1.0], [-W[j] ** 2, -2 * ZETA[j] * W[j]]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[-W[j] ** 2, -2 * ZETA[j] * W[j]]])
    D = np.array([[1.0]])
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), 1 / FS, method="zoh")
    b, a = signal.ss2tf(Ad, Bd, Cd, Dd)
    return signal.lfilter(b[0], a, f)


def cubic_mode_acceleration(f: np.ndarray, k3: float, substeps: int = SUBSTEPS) -> np.ndarray:
    """RK4 of q'' = f - 2 zeta w q' - w^2 q - k3 q^3 with f held over each sample (rows: records),
    from rest; the acceleration at each sample instant."""
    w2, c = W[MOVING] ** 2, 2 * ZETA[MOVING] * W[MOVING]
    h = 1 / (FS * substeps)
    out = np.empty_like(f)
    for row, forces in enumerate(f):
        q = v = 0.0
        values = []
        for force in forces.tolist():
            values.append(force - c * v - w2 * q - k3 * q * q * q)
            for _ in range(substeps):
                a1 = force - c * v - w2 * q - k3 * q * q * q
                q2, v2 = q + h / 2 * v, v + h / 2 * a1
                a2 = force - c * v2 - w2 * q2 - k3 * q2 * q2 * q2
                q3, v3 = q + h / 2 * v2, v + h / 2 * a2
                a3 = force - c * v3 - w2 * q3 - k3 * q3 * q3 * q3
                q4, v4 = q + h * v3, v + h * a3
                a4 = force - c * v4 - w2 * q4 - k3 * q4 * q4 * q4
                q, v = q + h / 6 * (v + 2 * v2 + 2 * v3 + v4), v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        out[row] = values
    return out


def structure(f: np.ndarray, k3: float, substeps: int = SUBSTEPS) -> np.ndarray:
    """Acceleration output of the five modes for forces f (rows: records)."""
    y = RESIDUE[MOVING] * cubic_mode_acceleration(f, k3, substeps)
    for j in range(FREQ.size):
        if j != MOVING:
            y += RESIDUE[j] * linear_mode_acceleration(j, f)
    return y


def line_amplitude(rms: float) -> float:
    return rms * np.sqrt(2 / BINS.size)


def modal_variance(rms: float, stiffness: float) -> float:
    """sigma_q^2 of the moving mode with modal stiffness ``stiffness`` (sampled ZOH receptance)."""
    A = np.array([[0.0, 1.0], [-stiffness, -2 * ZETA[MOVING] * W[MOVING]]])
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]),
                                              np.array([[0.0]])), 1 / FS, method="zoh")
    b, a = signal.ss2tf(Ad, Bd, Cd, Dd)
    _, H = signal.freqz(b[0], a, worN=2 * np.pi * BINS / N)
    return float(np.sum(line_amplitude(rms) ** 2 / 2 * np.abs(H) ** 2))


def equivalent_stiffness(rms: float, k3: float) -> float:
    stiffness = W[MOVING] ** 2
    for _ in range(50):
        stiffness = W[MOVING] ** 2 + 3 * k3 * modal_variance(rms, stiffness)
    return stiffness


# the cubic: the top level's equivalent stiffness 2.6 % below the linear one (frequency about -1.3 %)
STIFFNESS_CHANGE = 0.026
K3 = -STIFFNESS_CHANGE * W[MOVING] ** 2 / (3 * modal_variance(RMS[-1], W[MOVING] ** 2 * (1 - STIFFNESS_CHANGE)))


def truth(rms: float) -> tuple[float, float]:
    """Equivalent-linear natural frequency (Hz) and damping ratio of the moving mode at a level.

    The stiffness is ``w^2 + 3 K3 sigma_q^2`` less the finite-line term: of the 6 (F - 1) + 3
    phase-keeping triples of q^3 at line k the 3 with l = k count half, so the cubic's BLA at line k
    is ``3 K3 (sigma_q^2 - a_k^2 / 4)`` with ``a_k`` the amplitude of q there; at the resonance
    (phase -90 degrees, ``w_eq^2`` = the stiffness) ``a_k = A / (c w_eq)``, c = 2 zeta w.
    """
    stiffness = equivalent_stiffness(rms, K3)
    c = 2 * ZETA[MOVING] * W[MOVING]
    w2 = stiffness
    for _ in range(20):
        w2 = stiffness - 0.75 * K3 * line_amplitude(rms) ** 2 / (c * c * w2)
    return np.sqrt(w2) / (2 * np.pi), c / (2 * np.sqrt(w2))


@functools.lru_cache(maxsize=1)
def simulated(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Forces (one row per run: M realizations of each level) and the structure's noise-free response."""
    rng = np.random.default_rng(seed)
    forces = np.array([np.tile(multisine(N, BINS, rms, rng), P + T) for rms in RMS for _ in range(M)])
    return forces, structure(forces, K3)


def recording(seed: int, noise: float = NOISE_Y) -> list[Run]:
    """The runs as measured: mains in force and output (declared excited at the lowest level), and
    white output noise of standard deviation ``noise``."""
    forces, y = simulated(seed)
    rng = np.random.default_rng(seed + 1000)
    t = np.arange(N * (P + T)) / FS
    with_mains = np.sort(np.append(BINS, MAINS_BIN))
    runs = []
    for row, (force, response) in enumerate(zip(forces, y)):
        i = row // M
        mains = np.cos(2 * np.pi * 50 * t + rng.uniform(0, 2 * np.pi))
        runs.append(Run(run_id=f"l{i}m{row % M}", fs=FS, kind="multisine", u=force + 0.05 * mains,
                        y=response + 0.02 * (i + 1) * mains + noise * rng.standard_normal(t.size),
                        period=N, transient_periods=T, realization=row % M, level=RMS[i],
                        excited_bins=with_mains if i == 0 else BINS))
    return runs


@pytest.fixture(scope="module")
def runs():
    return recording(1)


@pytest.fixture(scope="module")
def across(runs):
    levels, _ = analyse_runs((run, run.run_id) for run in runs)
    return across_levels(levels)


def test_rk4_step_halved_changes_the_response_by_far_less_than_the_cubic():
    rng = np.random.default_rng(7)
    f = np.tile(multisine(N, BINS, RMS[-1], rng), 2)[None, :]
    base = cubic_mode_acceleration(f, K3, SUBSTEPS)
    halved = cubic_mode_acceleration(f, K3, 2 * SUBSTEPS)
    linear = cubic_mode_acceleration(f, 0.0, SUBSTEPS)
    assert np.std(base - halved) < 1e-3 * np.std(base - linear)


def test_the_moving_mode_is_found_and_its_shift_matches_the_truth(across):
    """All five resonances found; the one with the cubic moves by the truth's shift within three of
    its standard errors plus the statistical linearisation's second-order error, bounded by
    (stiffness change)^2 in relative frequency (on a noise-free simulation of 10 realizations per
    level the BLA's shift differed from this truth by 0.014 % at this 2.6 % stiffness change, against
    a bound of 0.068 %; by 0.10 % at 4 %, against 0.16 %, with windows of 2 bandwidths)."""
    modes = across["modes"]
    found = np.array([mode["frequency_hz"] for mode in modes])
    assert found.size == FREQ.size
    np.testing.assert_allclose(found, FREQ, rtol=2e-3)
    moving = modes[MOVING]
    assert moving["frequency_significant"] and moving["significant"]
    assert moving["from_level"] == RMS[0] and moving["to_level"] == RMS[-1]
    expected = truth(RMS[-1])[0] / truth(RMS[0])[0] - 1
    assert expected < -0.012  # a softening joint: the frequency falls by 1.2 % or more
    assert abs(moving["frequency_change"] - expected) < 3 * moving["frequency_change_se"] + STIFFNESS_CHANGE**2
    assert moving["frequency_change_se"] < 0.1 * abs(expected)  # measured, not merely undecided
    levels = [row["frequency_hz"] for row in moving["levels"]]
    assert levels == sorted(levels, reverse=True)  # softening at every step up


def test_the_modes_without_the_cubic_are_not_flagged(across):
    for j, mode in enumerate(across["modes"]):
        if j != MOVING:
            assert not mode["significant"], mode
            assert abs(mode["frequency_change"]) < 3 * mode["frequency_change_se"] + 1e-12


def test_the_diagnose_finding_names_the_moving_mode(across):
    rows = [dict(row, model_bla_change_max_db=None) for row in across["levels"]]
    findings = level_findings(rows, across)
    moving = [text for text in findings if text.startswith("mode near 7.3 Hz: frequency -1.")]
    assert len(moving) == 1 and moving[0].endswith("significant (3 standard errors)"), findings
    assert any(text.startswith("modes near 3.1, 11.8, 17.5, 24 Hz: no significant change") for text in findings)
    assert across["input_outliers_hz"] == [] and across["lines_compared"] == BINS.size  # the mains line left out


def test_no_common_lines_no_modes():
    """Two levels on disjoint grids: nothing is compared, so no mode is either."""
    rng = np.random.default_rng(9)
    odd, even = BINS[BINS % 2 == 1], BINS[BINS % 2 == 0]
    forces = np.array([np.tile(multisine(N, bins, 1.0, rng), P + T) for bins in (odd, odd, even, even)])
    y = structure(forces, 0.0) + NOISE_Y * rng.standard_normal(forces.shape)
    runs = [Run(run_id=f"r{n}", fs=FS, kind="multisine", u=f, y=out, period=N, transient_periods=T,
                realization=n % 2, level=1.0 + n // 2, excited_bins=odd if n < 2 else even)
            for n, (f, out) in enumerate(zip(forces, y))]
    levels, _ = analyse_runs((run, run.run_id) for run in runs)
    across = across_levels(levels)
    assert across["modes"] == [] and across["not_compared"]
    assert across["levels"][1]["bla_change_max_db"] is None


@pytest.fixture(scope="module")
def recording_file(tmp_path_factory, runs):
    path = tmp_path_factory.mktemp("modes") / "rec.h5"
    write_recording(path, runs, provenance={"tool": "test"})
    return path


def test_bla_writes_the_modes_to_json_and_to_the_file(recording_file, across, tmp_path, run_cli):
    out = tmp_path / "bla.h5"
    result = run_cli("bla", recording_file, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    modes = result.json()["across_levels"]["modes"]
    assert [mode["significant"] for mode in modes] == [j == MOVING for j in range(FREQ.size)]
    assert modes[MOVING]["frequency_change"] == pytest.approx(across["modes"][MOVING]["frequency_change"], rel=1e-9)
    stored = read_bla(out)["attrs"]["across_levels"]
    assert stored["modes"][MOVING]["frequency_change_se"] == modes[MOVING]["frequency_change_se"]
    table = run_cli("bla", recording_file, "-o", tmp_path / "again.h5")
    # the console writes to stderr; box characters and widths depend on the console's settings
    shown = " ".join(re.sub("[│┃|]", " ", table.stdout + table.stderr).split())
    assert table.exit_code == 0 and "dzeta" in shown and re.search(r"7\.29\d \S+ 7\.2\d* \S+ -1\.\d+ .*? yes", shown)


def test_peaks_of_noise_are_not_taken_for_modes():
    """At 500 times the noise (1.0 rms on the acceleration) the BLA shows peaks of noise between the
    modes; they fit as pole pairs narrower than a line or with a damping the data do not fix, and
    are not reported: the five modes are, and the moving one is still found."""
    levels, _ = analyse_runs((run, run.run_id) for run in recording(1, noise=1.0))
    modes = across_levels(levels)["modes"]
    np.testing.assert_allclose([mode["frequency_hz"] for mode in modes], FREQ, rtol=2e-3)
    assert [mode["significant"] for mode in modes] == [j == MOVING for j in range(FREQ.size)]


def test_diagnose_names_the_moving_mode_against_the_linear_structure(runs):
    """diagnose's evidence with the linear five-mode structure as the model: the measured modes and
    the finding on the moving one, the level comparison on the lines excited at every level."""
    from nlsid.diagnose.evidence import gather
    from nlsid.diagnose.simulation import ModelRunner
    from nlsid.diagnose.split import split_runs

    A = np.zeros((2 * FREQ.size, 2 * FREQ.size))
    for j in range(FREQ.size):
        A[2 * j, 2 * j + 1] = 1.0
        A[2 * j + 1, 2 * j: 2 * j + 2] = [-W[j] ** 2, -2 * ZETA[j] * W[j]]
    C = np.ravel([[-r * w * w, -2 * r * z * w] for r, w, z in zip(RESIDUE, W, ZETA)])
    model = {"model": {"type": "state_space", "A": A.tolist(), "B": [0.0, 1.0] * FREQ.size, "C": C.tolist(),
                       "D": float(np.sum(RESIDUE))}}
    evidence, _ = gather(ModelRunner.from_data(model, "structure.yaml"), runs, split_runs(runs, "rec"))
    summary = evidence.summary()["across_levels"]
    assert [mode["significant"] for mode in summary["modes"]] == [j == MOVING for j in range(FREQ.size)]
    findings = evidence.findings()
    assert any(text.startswith("mode near 7.3 Hz: frequency -1.") for text in findings), findings
    [change] = [text for text in findings if text.startswith("BLA changes by up to")]
    assert f"over {BINS.size} lines excited at every level" in change


def test_one_realization_of_one_period_still_compares_the_modes(runs):
    """M = 1, P = 1: no variance of the BLA at all; the fits are unweighted and their standard
    errors come from the residuals' scatter (the Birge ratio): the moving mode is still named."""
    import dataclasses

    one = [dataclasses.replace(run, u=run.u[:(T + 1) * N], y=run.y[:(T + 1) * N]) for run in runs
           if run.realization == 0]
    levels, _ = analyse_runs((run, run.run_id) for run in one)
    modes = across_levels(levels)["modes"]
    assert [mode["significant"] for mode in modes] == [j == MOVING for j in range(FREQ.size)]
    expected = truth(RMS[-1])[0] / truth(RMS[0])[0] - 1
    tolerance = 3 * modes[MOVING]["frequency_change_se"] + STIFFNESS_CHANGE**2
    assert abs(modes[MOVING]["frequency_change"] - expected) < tolerance
