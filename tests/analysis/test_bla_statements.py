"""What ``bla``, its report and ``fit`` say on valid data, against what the data are known to hold.

Each test builds its data here with a known truth (a linear system: no distortion; a static cubic:
harmonics beyond the band; a delay put in by an exact FFT phase shift; a noise-free linear model) and
checks the sentence the user reads, with numbers computed here independently of the code under test.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import signal

from generators.bla_cases import multisine, odd_random_bins, simulate  # noqa: E402

from nlsid.analysis.arbitrary import analyse_level  # noqa: E402
from nlsid.analysis.bla import cross_spectrum_delay, nonlinear_variance_missing  # noqa: E402
from nlsid.analysis.levels import analyse_runs  # noqa: E402
from nlsid.analysis.lines import EVEN, ODD  # noqa: E402
from nlsid.io.run import Run  # noqa: E402
from nlsid.report.render_bla import distortion_verdict  # noqa: E402


def analyse(runs, method="auto"):
    return analyse_runs(((run, run.run_id) for run in runs), method)[0]


def verdict(level) -> str:
    """The report's headline for one level, with the detection lines judged as render_bla does."""
    lines = level.lines
    detection = bool(np.any(((lines.kind == ODD) | (lines.kind == EVEN)) & lines.in_band))
    return distortion_verdict(level.summary(), detection)[0]


# 1. The M/P requirement of the nonlinear variance --------------------------------------------------

def _closed_loop_linear(seed: int, M: int = 10, P: int = 2):
    """u = r - y around y = G u + v (process noise v), every line of the band excited: a linear
    system, so its BLA has no nonlinear variance (the book's closed-loop example, Section 6.1.1)."""
    rng = np.random.default_rng(seed)
    b, a = np.array([0.0, 0.6]), np.array([1.0, -0.7])
    N, sv = 512, 0.05
    bins = np.arange(1, 121)
    runs = []
    for m in range(M):
        r_period = multisine(N, bins, 1.0, rng)
        r = np.tile(r_period, P + 1)
        v = sv * rng.standard_normal(r.size)
        y = signal.lfilter(b, a + b, r) + signal.lfilter(a, a + b, v)
        run = simulate(f"r{m}", r_period, lambda x: x, P, rng, realization=m, bins=bins, reference=True)
        run.u, run.y = r - y, y
        runs.append(run)
    return runs


@pytest.mark.parametrize("seed", [1, 2])
def test_reference_method_with_ten_realizations_and_two_periods_is_never_called_unmeasurable(seed):
    # M = 10 and P = 2 give the reference method both variances (book (6-39)). On a linear loop
    # the nonlinear variance estimate M (var_total - var_noise) is zero on average and falls below
    # zero about half the time (seeds 1 and 2 do): that is "no distortion", not "not measurable".
    level = analyse(_closed_loop_linear(seed))[0]
    assert level.robust.method == "reference" and level.n_realizations == 10 and level.n_periods == 2
    assert np.mean(level.robust.var_nl) < 0  # the case that used to be called unmeasurable
    text = verdict(level)
    assert "not measurable" not in text and "needs" not in text, text
    assert text.startswith("No nonlinear distortion detected"), text


def test_the_requirement_names_only_what_is_missing():
    assert nonlinear_variance_missing(10, 2) == ""
    one_m = nonlinear_variance_missing(1, 4)
    assert "M >= 2" in one_m and "P >= 2" not in one_m and "noise variance only" in one_m
    one_p = nonlinear_variance_missing(10, 1)
    assert "P >= 2" in one_p and "M >= 2" not in one_p and "total variance only" in one_p
    assert "M >= 2" in nonlinear_variance_missing(1, 1) and "P >= 2" in nonlinear_variance_missing(1, 1)


def test_one_realization_with_periods_says_it_lacks_realizations_not_periods():
    rng = np.random.default_rng(4)
    bins = np.arange(1, 101)
    run = simulate("r0", multisine(256, bins, 1.0, rng), lambda u: u + 0.2 * u**3, 4, rng, noise_y=0.01,
                   realization=0, bins=bins)
    text = verdict(analyse([run], "frf")[0])
    assert "not measurable" in text and "M >= 2" in text and "P >= 2" not in text, text


# 2. LPM band statistics over excited lines ---------------------------------------------------------

def test_lpm_band_means_are_over_the_excited_lines_only():
    # Input power at lines 200..800 only (an FFT-built band-limited noise); the LPM band, found on
    # the window-smoothed power, reaches unexcited lines beside it, where G is extrapolated.
    rng = np.random.default_rng(1)
    N, M, sigma, scale = 4096, 2, 1e-4, 30.0
    b, a = [0.5, 0.2], [1.0, -0.5]
    lo, hi = 200, 800
    runs, U2 = [], []
    for m in range(M):
        X = np.zeros(N // 2 + 1, complex)
        X[lo:hi + 1] = np.exp(2j * np.pi * rng.uniform(size=hi - lo + 1))
        u = np.fft.irfft(X, n=N) * scale
        U2.append(np.abs(np.fft.rfft(u)[lo:hi + 1] / N) ** 2)
        y = signal.lfilter(b, a, u) + sigma * rng.standard_normal(N)
        runs.append(Run(run_id=f"a{m}", fs=1.0, kind="arbitrary", u=u, y=y))
    summary = analyse_level(runs, "test", 0.95).summary()
    assert summary["excited_lines"] == hi - lo + 1
    _, G = signal.freqz(b, a, worN=2 * np.pi * np.arange(lo, hi + 1) / N)
    G2 = np.mean(np.abs(G) ** 2)
    # |G| of a 4000-sample record of this smooth G is within 1e-3 of the truth (transient removed
    # by the local polynomial; noise 70 dB below): 0.05 dB is about 10 of its standard deviations
    assert summary["bla_db"] == pytest.approx(10 * np.log10(G2), abs=0.05)
    # var G is the line's noise variance sigma^2/N over |U|^2, times [A^-1]_00 |U|^2, which lies
    # between 1/(M (2n+1)) and 1 for a window of 2n+1 = 7 lines with the transient projected out
    noise_to_signal = 10 * np.log10(np.mean(sigma**2 / N / np.mean(U2, axis=0)) / G2)
    assert noise_to_signal - 10 * np.log10(M * 7) - 3 < summary["total_var_db"] < noise_to_signal + 3


# 3. Noise-free and P = 1 data: the non-excited lines are read -------------------------------------

def _noise_free_full_grid(system, N=256, top=60, P=2):
    rng = np.random.default_rng(7)
    bins = np.arange(1, top + 1)
    u = multisine(N, bins, 1.0, rng)
    return simulate("r0", u, system, P, rng, realization=0, bins=bins), u


def test_noise_free_full_grid_reports_the_harmonics_beyond_the_band():
    # One realization (no robust nonlinear variance), every in-band line excited (no detection
    # lines): a static cubic puts its harmonics at lines 61..180, beyond the band.
    cubic = lambda x: x + 0.3 * x**3  # noqa: E731
    run, u = _noise_free_full_grid(cubic)
    level = analyse([run])[0]
    assert level.noise_floor == "zero"
    Y2 = np.abs(np.fft.rfft(cubic(u)) / u.size) ** 2
    k = np.arange(Y2.size)
    out = (k > 60) & (k < u.size // 2)
    strongest = max(np.mean(Y2[out & (k % 2 == 1)]), np.mean(Y2[out & (k % 2 == 0)]))
    gap = 10 * np.log10(np.mean(Y2[1:61]) / strongest)
    text = verdict(level)
    assert not text.startswith("No nonlinear distortion"), text
    assert f"beyond the excited band, {gap:.0f} dB below the output" in text, (text, gap)


def test_noise_free_linear_full_grid_claims_no_distortion_only_at_the_lines_it_read():
    run, _ = _noise_free_full_grid(lambda x: np.convolve(x, [0.5, 0.25])[:x.size])
    text = verdict(analyse([run])[0])
    assert text.startswith("No nonlinear distortion beyond numerical precision at the non-excited harmonic lines")
    assert "not measured (M = 1)" in text


def test_one_period_per_realization_classifies_the_distortion_from_the_detection_lines():
    # An even nonlinearity on an odd random grid puts its distortion at the even lines only (book
    # Section 5.1): with P = 1 (noise unknown) the page still says so, from the line classes.
    rng = np.random.default_rng(3)
    N, M = 512, 4
    bins = odd_random_bins(1, 101, 4, rng)
    runs = [simulate(f"r{m}", multisine(N, bins, 1.0, rng), lambda x: x + 0.3 * x**2, 1, rng, noise_y=0.003,
                     realization=m, bins=bins) for m in range(M)]
    level = analyse(runs)[0]
    summary = level.summary()
    text, findings = distortion_verdict(summary, True)
    assert text.startswith("Noise level unknown (one period per realization, P = 1)")
    assert "even detection lines are" in text and "even nonlinear distortion dominant" in text, text
    assert any("detection lines (noise plus distortion" in f for f in findings), findings


# 4. r-to-u delay between realizations is not a nonlinear actuator ----------------------------------

def _delayed(x: np.ndarray, delay: float) -> np.ndarray:
    """One period of a periodic signal delayed by ``delay`` samples exactly (a phase shift of its DFT)."""
    N = x.size
    X = np.fft.rfft(x)
    k = np.arange(X.size)
    X = X * np.exp(-2j * np.pi * k * delay / N)
    if N % 2 == 0:
        X[-1] = X[-1].real  # the Nyquist line of a real signal (the multisine leaves it empty)
    return np.fft.irfft(X, n=N)


def _reference_runs(delay: float, input_noise: float, actuator=lambda r: r, M=6, P=3, seed=3):
    """Open loop with the reference r recorded: u = actuator(r), realization 2 delayed from r by
    ``delay`` samples; y = an FIR filter of u plus output noise."""
    rng = np.random.default_rng(seed)
    N = 256
    bins = np.arange(1, 80)
    runs = []
    for m in range(M):
        r = multisine(N, bins, 1.0, rng)
        u = actuator(_delayed(r, delay) if m == 2 else r)
        u_all = np.tile(u, P + 1)
        y = np.convolve(u_all, [0.5, 0.3, 0.1])[:u_all.size] + 1e-3 * rng.standard_normal(u_all.size)
        u_measured = u_all + input_noise * rng.standard_normal(u_all.size)
        runs.append(Run(run_id=f"m{m}", fs=1.0, kind="multisine", u=u_measured, y=y, r=np.tile(r, P + 1),
                        period=N, transient_periods=1, realization=m, excited_bins=bins))
    return runs


@pytest.mark.parametrize("delay, input_noise", [(1.0, 0.0), (0.37, 0.0), (1.0, 1e-3), (2.5, 1e-3)])
def test_a_delay_between_realizations_is_named_instead_of_a_nonlinear_actuator(delay, input_noise):
    warnings = " ".join(analyse(_reference_runs(delay, input_noise))[0].warnings)
    assert "reaches the plant input" not in warnings, warnings
    assert f"r-to-u delay varies by {delay:.3g} samples between realizations" in warnings, warnings


def test_a_nonlinear_actuator_is_still_called_one():
    # A static cubic between r and u: U_R varies over realizations by its stochastic distortion,
    # which no delay explains.
    warnings = " ".join(analyse(_reference_runs(0.0, 1e-3, actuator=lambda r: r + 0.3 * r**3))[0].warnings)
    assert "reaches the plant input" in warnings and "delay varies" not in warnings, warnings


@pytest.mark.parametrize("delay", [0.0, 0.37, 1.0, -2.6, 17.25])
def test_cross_spectrum_delay_recovers_an_exact_phase_slope(delay):
    N = 512
    bins = np.arange(3, 200, 2)
    amplitude = 1 + np.random.default_rng(0).uniform(size=bins.size)
    cross = amplitude * np.exp(-2j * np.pi * bins * delay / N)
    assert cross_spectrum_delay(cross, bins, N) == pytest.approx(delay, abs=1e-9)


# 5. fit accepts a noise-free BLA -------------------------------------------------------------------

NOISE_FREE_DESIGN = """fs: 100.0
seed: 2
multisine:
  period: 400
  band: [0.5, 20.0]
  lines: random-odd
  realizations: {M}
  periods: 2
  transient_periods: 3
  rms_levels: [1.0]
"""

SECOND_ORDER = """model:
  type: transfer_function
  domain: discrete
  num: [0.0, 0.2, 0.1]
  den: [1.0, -1.2, 0.5]
"""


@pytest.mark.parametrize("M", [1, 3])
def test_fit_of_a_noise_free_bla_is_unweighted_and_says_so(run_cli, tmp_path, M):
    # A noise-free linear model: the BLA is its FRF up to rounding (the transient of poles of
    # radius 0.71 after 3 periods of 400 samples is below 1e-180), its variances zero within
    # numerical precision. An unweighted 2/2 fit must return the model's coefficients.
    (tmp_path / "design.yaml").write_text(NOISE_FREE_DESIGN.format(M=M))
    (tmp_path / "true.yaml").write_text(SECOND_ORDER)
    for args in (("design", tmp_path / "design.yaml", "-o", tmp_path / "e.h5"),
                 ("simulate", tmp_path / "true.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "r.h5"),
                 ("bla", tmp_path / "r.h5", "-o", tmp_path / "bla.h5")):
        result = run_cli(*args)
        assert result.exit_code == 0, result.stderr
    model = tmp_path / "m.yaml"
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "2/2", "--domain", "z", "-o", model, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["weighted"] is False and summary["weights"].startswith("none: a noise-free BLA")
    assert "P >= 2" not in result.stderr
    fitted = yaml.safe_load(model.read_text())["model"]
    assert np.allclose(fitted["num"], [0.0, 0.2, 0.1], atol=1e-7)
    assert np.allclose(fitted["den"], [1.0, -1.2, 0.5], atol=1e-7)
    report = json.loads((tmp_path / "m.fit.json").read_text())
    assert report["weighted"] is False and report["provenance"]["unweighted"] is True
    assert "unweighted least squares" in model.read_text()  # the model file's header says it too
    plain = run_cli("fit", tmp_path / "bla.h5", "--order", "2/2", "-o", tmp_path / "p.yaml")
    assert plain.exit_code == 0 and "unweighted least squares" in plain.stderr
    assert "misses it by more than numerical precision" not in plain.stderr
    # one pole short of the system: no 1/1 model equals a 2/2 FRF, so the fit says it misses it
    short = run_cli("fit", tmp_path / "bla.h5", "--order", "1/1", "-o", tmp_path / "s.yaml", "--json")
    assert short.exit_code == 0, short.stderr
    assert any("misses it by more than numerical precision" in w for w in short.json()["warnings"])


def test_fit_of_a_noisy_bla_stays_weighted(run_cli, tmp_path):
    (tmp_path / "design.yaml").write_text(NOISE_FREE_DESIGN.format(M=3))
    (tmp_path / "true.yaml").write_text(SECOND_ORDER + "disturbances: {y_noise: 0.01, seed: 4}\n")
    for args in (("design", tmp_path / "design.yaml", "-o", tmp_path / "e.h5"),
                 ("simulate", tmp_path / "true.yaml", "--excitation", tmp_path / "e.h5", "-o", tmp_path / "r.h5"),
                 ("bla", tmp_path / "r.h5", "-o", tmp_path / "bla.h5")):
        assert run_cli(*args).exit_code == 0
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "2/2", "-o", tmp_path / "m.yaml", "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert summary["weighted"] is True and summary["weights"].startswith("var_total of the robust method")
    assert "unweighted" not in json.loads((tmp_path / "m.fit.json").read_text())["provenance"]
