"""Excited lines of a measured force 6 dB above its noise, with mains hum (nlsid.signals.inference).

The generator is written here: a random-phase random-odd multisine (odd bins up to 801, one of
every three left out, rms 1) repeated over P = 16 periods of N samples at fs = 1000 Hz, plus
Gaussian noise of variance 1/4 (6 dB below the excitation's power: white, variance 0.15, and
low-pass coloured, variance 0.10, through a 2nd-order Butterworth filter at 150 Hz, settled over
20,000 samples before the record starts), a converter offset, and mains hum at 50 Hz (amplitude
0.2, 10 dB above a line of the multisine, amplitude 0.087) and 150 Hz (0.1). With N = 4000 the hum
sits on bins 200 and 600 (even: off the odd grid); with N = 4096 it is not periodic in the period
(50 Hz is bin 204.8).

The inference must find exactly the generator's lines, and no mains line.

Why a miss is negligible: at excited line k the one-period DFT X_p(k)/N has the line A/2 (A the
line amplitude) and noise of variance S(k)/N per period (S the noise's two-sided spectrum per
sample: white plus coloured, from the filter's exact response), so 2T, with T the test statistic
P |mean X|^2 / s^2, is non-central chi-square with 2 degrees of freedom and non-centrality
lambda_k = 2 P (A^2 / 4) N / S(k) (its variance s^2 estimated over 2 x 15 x 17 = 510 degrees of
freedom, within 25 % except with probability far below 1e-9). The weakest line has lambda > 500
here (510 at N = 4000, in the coloured noise's band), and a line with T above 100 (the 20 dB a
measured input's line needs, more than the F threshold of about 16) counts whatever its
neighbours: the probability that any of the ~270 lines falls below 1.25 x 100 is computed in
``miss_bound`` (3.5e-10) and asserted below 1e-6. Unexcited lines pass the F threshold with
family-wise probability 1e-3, and even then are off the odd grid of the 20 dB lines, so they do
not count.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, stats
from scipy.io import savemat

from nlsid.io.recording import read_runs
from nlsid.signals.inference import infer_excitation

FS = 1000.0
PERIODS = 16
TOP = 801
WHITE_VAR, COLOURED_VAR = 0.15, 0.10  # 0.25: 6 dB below the excitation's power 1
HUM = ((50.0, 0.2), (150.0, 0.1))
FILTER = signal.butter(2, 150.0 / (FS / 2))


def random_odd(top: int, rng: np.random.Generator) -> np.ndarray:
    odd = np.arange(1, top + 1, 2)
    dropped = [group[rng.integers(group.size)] for group in np.array_split(odd, math.ceil(odd.size / 3))]
    return np.setdiff1d(odd, dropped)


def impulse_energy(b: np.ndarray, a: np.ndarray) -> float:
    """sum h(n)^2 of the filter's impulse response (the pole radius is 0.5: 400 samples reach 1e-100)."""
    impulse = np.zeros(400)
    impulse[0] = 1.0
    return float(np.sum(signal.lfilter(b, a, impulse) ** 2))


def noisy_force(seed: int, period: int, bins: np.ndarray | None = None):
    """(u, the clean multisine, its bins, its line amplitude)."""
    rng = np.random.default_rng(seed)
    bins = random_odd(TOP, rng) if bins is None else bins
    amplitude = math.sqrt(2.0 / bins.size)
    n = np.arange(period)[:, None]
    one = amplitude * np.cos(2 * np.pi * bins[None, :] * n / period + rng.uniform(0, 2 * np.pi, bins.size)).sum(axis=1)
    clean = np.tile(one, PERIODS)
    b, a = FILTER
    coloured = signal.lfilter(b, a, rng.normal(size=clean.size + 20_000))[-clean.size:]
    coloured *= math.sqrt(COLOURED_VAR / impulse_energy(b, a))
    t = np.arange(clean.size) / FS
    hum = sum(level * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) for f, level in HUM)
    u = clean + rng.normal(0, math.sqrt(WHITE_VAR), clean.size) + coloured + hum + 0.3
    return u, clean, bins, amplitude


def noise_spectrum(bins: np.ndarray, period: int) -> np.ndarray:
    """Two-sided noise spectrum per sample S at the bins (white plus the filter's exact |H|^2)."""
    b, a = FILTER
    _, h = signal.freqz(b, a, worN=2 * np.pi * bins / period)
    return WHITE_VAR + COLOURED_VAR * np.abs(h) ** 2 / impulse_energy(b, a)


def miss_bound(bins: np.ndarray, amplitude: float, period: int) -> tuple[float, float]:
    """(smallest lambda_k, the probability that some line has T below 1.25 x 100)."""
    lam = 2 * PERIODS * amplitude**2 / 4 * period / noise_spectrum(bins, period)
    return float(lam.min()), float(np.sum(stats.ncx2.cdf(2 * 1.25 * 100, 2, lam)))


@pytest.mark.parametrize("period, on_grid", [(4000, True), (4096, False)], ids=["hum-on-bins", "hum-between-bins"])
@pytest.mark.parametrize("seed", [0, 1])
def test_a_force_6_db_above_noise_with_hum_excites_exactly_the_generator_lines(seed, period, on_grid):
    u, clean, bins, amplitude = noisy_force(seed, period)
    smallest, bound = miss_bound(bins, amplitude, period)
    assert smallest > 500 and bound < 1e-6  # the design of the test: a miss is negligible
    # the generator's SNR as defined: noise power a quarter of the excitation's
    assert float(np.var(clean)) == pytest.approx(1.0, rel=1e-9)
    inf = infer_excitation(u, FS, measured=True)
    assert (inf.kind, inf.period, inf.grid) == ("multisine", period, "random-odd"), inf.notes
    (real,) = inf.realizations
    assert (real.start, real.transient_periods, real.periods) == (0, 0, PERIODS)
    np.testing.assert_array_equal(real.excited_bins, bins)
    if on_grid:
        # hum on bins 200 and 600, stronger than the lines: named mains, not counted
        assert inf.measures["mains_bins"] == [200, 600]
        assert any("mains line(s)" in note and "50, 150 Hz" in note for note in inf.notes)
        # the period-to-period noise is the generator's 0.25 and the mean period holds the
        # multisine (1), the periodic hum (0.025) and noise / P: the estimate's spread over
        # 15 x 4000 degrees of freedom is 0.03 dB
        expected = 10 * math.log10((1 + 0.2**2 / 2 + 0.1**2 / 2 + 0.25 / PERIODS) / 0.25)
        assert inf.measures["input_snr_db"] == pytest.approx(expected, abs=0.2)


def test_a_recorded_reference_counts_a_designed_line_at_50_hz():
    # a full multisine on bins 1..400 of N = 4000 (0.25 Hz apart): bin 200 is 50 Hz; recorded as r,
    # the design is what was excited, hum or not
    period = 4000
    bins = np.arange(1, 401)
    u, clean, _, _ = noisy_force(5, period, bins)
    assert infer_excitation(clean, FS).realizations[0].excited_bins.tolist() == bins.tolist()
    # measured alone, the hum (0.2) on the designed line 200 (0.071) makes it more than twice its
    # neighbours, and 150 Hz (bin 600) lies beyond the design's band: the input cannot tell the
    # line at 50 Hz from hum, so neither is counted, and the note says so
    inf = infer_excitation(u, FS, measured=True)
    assert inf.measures["mains_bins"] == [200, 600]
    assert any("mains line(s)" in note and "record the reference r" in note for note in inf.notes)
    np.testing.assert_array_equal(inf.realizations[0].excited_bins, np.setdiff1d(bins, [200]))


def test_noise_too_coloured_to_tell_from_a_change_is_not_periodic():
    # a multisine 6 dB above noise low-passed at 2 Hz (a slow wander): over a period of 500 samples
    # the period-to-period noise has a handful of degrees of freedom, so a change of content cannot
    # be told from it at 6 standard deviations; it is not taken as periodic, and the note says why
    rng = np.random.default_rng(7)
    period, periods = 500, 6
    bins = np.arange(1, 100, 2)
    n = np.arange(period)[:, None]
    one = math.sqrt(2 / bins.size) * np.cos(2 * np.pi * bins[None, :] * n / period
                                            + rng.uniform(0, 2 * np.pi, bins.size)).sum(axis=1)
    b, a = signal.butter(2, 2.0 / (FS / 2))
    wander = signal.lfilter(b, a, rng.normal(size=period * periods + 20_000))[-period * periods:]
    u = np.tile(one, periods) + 0.5 * wander / wander.std()
    inf = infer_excitation(u, FS, measured=True)
    assert inf.kind == "arbitrary"
    assert any("white enough to be told from a change of content" in note
               and "degrees of freedom over a period, fewer than the" in note for note in inf.notes), inf.notes


def test_the_import_writes_the_lines_and_bla_accepts_it(run_cli, tmp_path):
    u, _, bins, _ = noisy_force(2, 4000)
    y = signal.lfilter([0.2, 0.1], [1.0, -0.9, 0.3], u)  # a measured output: u through a stable filter
    source = tmp_path / "force.mat"
    savemat(source, {"u": u, "y": y, "fs": FS})
    out = tmp_path / "rec.h5"
    result = run_cli("import", source, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    (record,) = result.json()["records"]
    assert record["inferred_from"] == "u" and record["inference"]["measures"]["mains_bins"] == [200, 600]
    (run,) = read_runs(out)
    assert (run.kind, run.period) == ("multisine", 4000)
    np.testing.assert_array_equal(run.excited_bins, bins)
    bla = run_cli("bla", out, "-o", tmp_path / "bla.h5", "--json")
    assert bla.exit_code == 0, bla.stderr


@pytest.mark.parametrize("seed", [0, 1])
def test_realizations_back_to_back_6_db_above_white_noise(seed):
    # 137 samples of other content, then M = 4 realizations (new phases) of 6 periods of N = 2000,
    # white noise of variance 1/4 (6 dB). Each line: lambda = 2 x 6 x (A^2 / 4) x 2000 / 0.25 with
    # A^2 = 2 / 134, so 360 (2T has mean 362 against 200 for 20 dB; the realizations' lines also pass
    # the weaker on-grid rule). Where the slots start is found to one sample: shifting by one
    # trades one noise sample for one changed sample at each of the 4 boundaries, wrong with
    # probability about (0.64 / sqrt(5))^4 = 0.7 % (step 2), so the starts are asserted within a sample.
    rng = np.random.default_rng(seed)
    period, periods, count, lead = 2000, 6, 4, 137
    bins = random_odd(401, rng)
    n = np.arange(period)[:, None]
    amplitude = math.sqrt(2 / bins.size)
    parts = [np.tile(amplitude * np.cos(2 * np.pi * bins[None, :] * n / period
                                        + rng.uniform(0, 2 * np.pi, bins.size)).sum(axis=1), periods)
             for _ in range(count)]
    x = np.concatenate([rng.normal(0, 1, lead), *parts])
    u = x + rng.normal(0, 0.5, x.size)
    inf = infer_excitation(u, FS, measured=True)
    assert (inf.kind, inf.period, len(inf.realizations)) == ("multisine", period, count), inf.notes
    for m, real in enumerate(inf.realizations):
        assert abs(real.start - (lead + m * periods * period)) <= 1
        assert real.periods + real.transient_periods == periods
        np.testing.assert_array_equal(real.excited_bins, bins)
