"""Level comparisons on the lines excited at every level, and "not compared" where there are none.

The system is the static cubic y = x + b x^3 measured with output noise, driven by random-phase
multisines of equal amplitudes at F odd lines. Its BLA is flat and known in closed form: of the
terms of x^3 at line k only the pairs (+l, -l, +k) keep the phase of line k, 6 (F - 1) + 3 ordered
triples of amplitude (A/2)^3 each, so with sigma^2 = F A^2 / 2

    G_BLA = 1 + 3 b sigma^2 (1 - 1/(2F)),

and the change of |G_BLA| from the lowest level is 20 log10 of the ratio at every line. The
remaining terms of x^3 are the stochastic distortion: for a nearly Gaussian x their variance per
realization is that of x^3 - 3 sigma^2 x, 6 sigma^6, spread over F lines, so var(G_S) = 6 b^2
sigma^4 per line and realization; the mean change over F lines and M realizations has standard
deviation 8.69 sqrt(6 b^2 sigma^4 / (M F)) / G_BLA dB (plus the output noise's, far smaller).

A mains line (50 Hz of fixed amplitude in the measured force and, with an amplitude that drifts
between the recordings, in the measured output) is declared excited at the lowest level only, or
at every level: either way it must not enter the comparison.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from generators.bla_cases import multisine

from nlsid.analysis.levels import INPUT_SHARE_SPREAD_DB, across_levels, analyse_runs, common_lines
from nlsid.diagnose.bla_comparison import level_findings
from nlsid.io.result_file import json_safe
from nlsid.io.run import Run

FS, N, P, M = 1000.0, 1000, 2, 4
B = 0.005  # cubic coefficient
SIGMAS = (0.25, 0.5, 1.0, 2.0)  # rms input per level (the largest 8 times the lowest: 18 dB)
MAINS_BIN, MAINS_U = 50, 0.05  # 50 Hz at 1 Hz spacing; amplitude in the measured force
MAINS_Y = (0.02, 0.04, 0.08, 0.16)  # its amplitude in the measured output, drifting between recordings
NOISE_Y = 1e-3
BINS = np.arange(3, 400, 2)  # odd lines 3 .. 399 Hz: 50 Hz is not a line of the multisine


def expected_bla(sigma: float) -> float:
    return 1 + 3 * B * sigma**2 * (1 - 1 / (2 * BINS.size))


def level_runs(index: int, sigma: float, rng, excited: np.ndarray, bins: np.ndarray = BINS) -> list[Run]:
    t = np.arange(N * P) / FS
    runs = []
    for m in range(M):
        x = np.tile(multisine(N, bins, sigma, rng), P)
        y = x + B * x**3
        u = x + MAINS_U * np.cos(2 * np.pi * 50 * t + 0.3)
        y = y + MAINS_Y[index] * np.cos(2 * np.pi * 50 * t + 1.1) + NOISE_Y * rng.standard_normal(x.size)
        runs.append(Run(run_id=f"l{index}m{m}", fs=FS, kind="multisine", u=u, y=y, period=N, transient_periods=0,
                        realization=m, level=sigma, excited_bins=excited))
    return runs


def analyse(runs):
    levels, _ = analyse_runs((run, run.run_id) for run in runs)
    return levels


@pytest.fixture(scope="module")
def mains_at_lowest_level():
    """The mains line declared excited at the lowest level only (the issue's case)."""
    rng = np.random.default_rng(3)
    with_mains = np.sort(np.append(BINS, MAINS_BIN))
    runs = []
    for i, sigma in enumerate(SIGMAS):
        runs += level_runs(i, sigma, rng, with_mains if i == 0 else BINS)
    return analyse(runs)


@pytest.fixture(scope="module")
def mains_at_every_level():
    rng = np.random.default_rng(4)
    with_mains = np.sort(np.append(BINS, MAINS_BIN))
    runs = []
    for i, sigma in enumerate(SIGMAS):
        runs += level_runs(i, sigma, rng, with_mains)
    return analyse(runs)


def check_against_theory(across: dict) -> None:
    rows = across["levels"]
    assert rows[0]["bla_change_max_db"] is None and rows[0]["bla_not_compared"] == "the reference level"
    for row, sigma in zip(rows[1:], SIGMAS[1:]):
        expected = 20 * np.log10(expected_bla(sigma) / expected_bla(SIGMAS[0]))
        sd = 20 / np.log(10) * np.sqrt(6 * B**2 * sigma**4 / (M * BINS.size)) / expected_bla(sigma)
        assert row["bla_compared_lines"] == BINS.size
        assert abs(row["bla_change_mean_db"] - expected) < 4 * sd + 0.002, (row, expected, sd)
        # the largest single-line change is the distortion's scatter, not the mains line's 6 to 18 dB
        assert abs(row["bla_change_max_db"]) < 1.0


def test_a_mains_line_excited_at_the_lowest_level_only_is_not_compared(mains_at_lowest_level):
    across = across_levels(mains_at_lowest_level)
    assert across["lines_compared"] == BINS.size and across["lines_excited_everywhere"] == BINS.size
    assert across["not_compared"] is None
    check_against_theory(across)


def test_a_mains_line_excited_at_every_level_is_left_out_by_its_input(mains_at_every_level):
    """At every level the mains line is declared excited; its share of the input power falls by
    20 log10 8 = 18 dB from the lowest level to the highest (its amplitude is fixed), more than
    INPUT_SHARE_SPREAD_DB, while the multisine lines keep theirs."""
    assert 20 * np.log10(SIGMAS[-1] / SIGMAS[0]) > INPUT_SHARE_SPREAD_DB
    common = common_lines(mains_at_every_level)
    assert common.excited_everywhere == BINS.size + 1
    np.testing.assert_allclose(common.input_outliers_hz, [50.0])
    assert 50.0 not in common.frequency_hz
    across = across_levels(mains_at_every_level)
    assert across["input_outliers_hz"] == [50.0]
    check_against_theory(across)


def test_the_diagnose_finding_names_the_change_of_the_highest_level(mains_at_lowest_level):
    across = across_levels(mains_at_lowest_level)
    rows = [dict(row, model_bla_change_max_db=0.0) for row in across["levels"]]
    header = {key: value for key, value in across.items() if key != "levels"}
    [finding] = level_findings(rows, header)
    top = rows[-1]["bla_change_max_db"]
    assert f"BLA changes by up to {top:+.1f} dB" in finding and f"over {BINS.size} lines" in finding
    assert "+0.0 dB over the levels" not in finding


def test_levels_without_common_lines_are_not_compared():
    """Odd lines at one level, even lines at the other: no line to compare; null, and said so."""
    rng = np.random.default_rng(5)
    even = BINS[:-1] + 1
    levels = analyse(level_runs(0, SIGMAS[0], rng, BINS) + level_runs(1, SIGMAS[1], rng, even, bins=even))
    across = across_levels(levels)
    assert across["lines_compared"] == 0 and "no line is excited" in across["not_compared"]
    for row in across["levels"]:
        assert row["bla_change_mean_db"] is None and row["bla_change_max_db"] is None
        assert row["bla_compared_lines"] == 0 and row["bla_not_compared"]
    stored = json.loads(json.dumps(json_safe(across)))
    assert stored["levels"][1]["bla_change_max_db"] is None
    rows = [dict(row, model_bla_change_max_db=None) for row in across["levels"]]
    [finding] = level_findings(rows, across)
    assert finding.startswith("BLA not compared over the levels: no line is excited") and "dB" not in finding


def test_a_level_on_another_grid_is_set_aside_and_the_others_compared():
    rng = np.random.default_rng(6)
    even = BINS[:-1] + 1
    runs = (level_runs(0, SIGMAS[0], rng, BINS) + level_runs(1, SIGMAS[1], rng, even, bins=even)
            + level_runs(2, SIGMAS[2], rng, BINS))
    across = across_levels(analyse(runs))
    middle, top = across["levels"][1:]
    assert middle["bla_change_max_db"] is None and "no excited line in common" in middle["bla_not_compared"]
    assert top["bla_compared_lines"] == BINS.size
    expected = 20 * np.log10(expected_bla(SIGMAS[2]) / expected_bla(SIGMAS[0]))
    assert abs(top["bla_change_mean_db"] - expected) < 0.05
    rows = [dict(row, model_bla_change_max_db=None) for row in across["levels"]]
    [finding] = level_findings(rows, across)
    assert "1 level(s) not compared (no excited line in common" in finding
