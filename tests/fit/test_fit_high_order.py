"""``nlsid fit --order auto`` on a structure of many lightly damped modes (nlsid.fit.order_poles,
nlsid.fit.tf_vector, nlsid.fit.modal_model).

The measured FRF is generated here with numpy alone: a discrete-time modal sum
G0(z) = sum_n r_n / (z - p_n) + r_n* / (z - p_n*) of twelve modes (24 poles; p_n = e^{s_n / fs},
the zero-order-hold poles of modes of damping 1-3 % spread over 15-350 Hz), evaluated exactly at
the lines z_k = e^{j 2 pi k / N}, plus circular complex Gaussian noise of known variance sigma^2 on
each line. The file ``bla.h5`` holds it as the fast method's BLA of one realization, whose
variance the fit takes as exact: the cost check is then the chi-square one.

At the minimum of a correct model of n_theta parameters, V = sum |G_k - G(z_k)|^2 / sigma^2 is
(1/2) chi^2(2F - n_theta) (Schoukens, Pintelon and Rolain 2012, 4.7 L). The selection takes the
fewest poles whose cost lies below the 0.99865 quantile and then a nested order only where the
likelihood ratio says so, so the chosen model's cost lies inside the two-sided 0.999 band of that
distribution unless a 1-in-1000 event happened (the seed is fixed; a model missing a mode lies
many times above: 23 poles leave a cost of about 18 times the bound here). The true number of
poles, 24, must be found within +-2: a pole fewer misses a mode's pair, two more are allowed
by the likelihood-ratio step fitting what noise cannot explain at probability 0.99865 each.
"""

from __future__ import annotations

import time

import numpy as np
import yaml
from scipy import signal, stats

MODES, FS, PERIOD, SIGMA = 12, 1000.0, 4096, 0.01
BINS = np.arange(4, 1600)


DESIGN = f"""fs: {FS}
seed: 3
multisine:
  period: {PERIOD}
  band: [1.0, 390.0]
  lines: full
  realizations: 1
  periods: 1
  transient_periods: 4
  rms_levels: [1.0]
"""


def _structure(seed: int, modes: int = MODES) -> tuple[np.ndarray, np.ndarray]:
    """Poles (Im > 0 member of each pair) and the noisy FRF at BINS."""
    rng = np.random.default_rng(seed)
    fn = np.geomspace(15.0, 350.0, modes)
    zeta = rng.uniform(0.01, 0.03, modes)
    wn = 2 * np.pi * fn
    poles = np.exp((-zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)) / FS)
    height = rng.uniform(0.5, 2.0, modes)  # |G| of each mode at its peak, 50-200 noise std
    residues = height * (1 - np.abs(poles)) * np.exp(1j * rng.uniform(-np.pi, np.pi, modes))
    z = np.exp(2j * np.pi * BINS / PERIOD)
    G0 = sum(r / (z - p) + np.conj(r) / (z - np.conj(p)) for p, r in zip(poles, residues))
    noise = SIGMA / np.sqrt(2) * (rng.standard_normal(BINS.size) + 1j * rng.standard_normal(BINS.size))
    return poles, G0 + noise


def _write_bla(path, G: np.ndarray, bins: np.ndarray = BINS, variance: np.ndarray | None = None,
               fs: float = FS, period: int = PERIOD) -> None:
    """A bla.h5 of one level in the layout nlsid.io.bla_file.read_bla reads: one realization of two
    periods (no robust variance), the fast method's G and var_total (default sigma^2) at every line."""
    from nlsid.io.bla_file import FORMAT, FORMAT_VERSION
    from nlsid.io.result_file import create_result, put

    with create_result(path, FORMAT, FORMAT_VERSION, {"generator": "tests/fit/test_fit_high_order.py"}) as handle:
        handle.attrs["units"] = "{}"
        level = handle.create_group("levels").create_group("level_00")
        level.attrs.update({"fs": fs, "period": period, "n_periods": 2, "n_realizations": 1})
        put(level, "excited_bins", bins.astype(np.int64))
        put(level, "frequency", bins * fs / period)
        put(level.create_group("robust"), "G", G)
        fast = level.create_group("fast")
        put(fast, "G", G)
        put(fast, "var_total", np.full(bins.size, SIGMA**2) if variance is None else variance)
        level.create_group("lines")


def _response(model: dict, z: np.ndarray) -> np.ndarray:
    """The written model's response at z, from the YAML alone: C (zI - A)^-1 B + D of a discrete
    state space, or B(z^-1)/A(z^-1) of a discrete transfer function."""
    assert model["domain"] == "discrete" and model.get("delay", 0) == 0
    if model["type"] == "state_space":
        A, B, C = np.array(model["A"]), np.array(model["B"]), np.array(model["C"])
        return np.array([C @ np.linalg.solve(x * np.eye(len(B)) - A, B) for x in z]) + model["D"]
    return np.polyval(model["num"][::-1], 1 / z) / np.polyval(model["den"][::-1], 1 / z)


def test_order_auto_finds_the_modes_of_a_lightly_damped_structure(run_cli, tmp_path):
    poles, G = _structure(seed=3)
    _write_bla(tmp_path / "bla.h5", G)
    start = time.perf_counter()
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "auto", "-o", tmp_path / "m.yaml", "--json")
    seconds = time.perf_counter() - start
    assert result.exit_code == 0, (result.stdout, result.stderr)
    out = result.json()
    nb, na = map(int, out["order"].split("/"))
    assert abs(na - 2 * MODES) <= 2 and nb == na, out["order_reason"]
    assert out["stable"] and out["stability"] == "stable"
    n_theta = 2 * na + 1
    dof = 2 * BINS.size - n_theta
    low, high = stats.chi2.ppf([0.0005, 0.9995], dof) / 2
    assert low <= out["cost"] <= high, (out["cost"], low, high)
    # the written model, read back from the YAML, reproduces that cost and is stable
    model = yaml.safe_load((tmp_path / "m.yaml").read_text())["model"]
    z = np.exp(2j * np.pi * BINS / PERIOD)
    cost = float(np.sum(np.abs(G - _response(model, z)) ** 2) / SIGMA**2)
    assert abs(cost - out["cost"]) <= 1e-6 * out["cost"]
    if model["type"] == "state_space":
        assert np.max(np.abs(np.linalg.eigvals(np.array(model["A"])))) < 1
    # every true pole is found within 5 standard deviations (the report's, per real and imaginary
    # part) by a fitted one: a Gaussian estimate leaves that band with probability 6e-7, the 48
    # parts together with 3e-5 (the ML estimate's bias is of order sigma^2, negligible at peaks
    # 50-200 noise std high)
    assert model["type"] == "state_space"  # 24 lightly damped poles: the polynomial form cannot hold them
    parameters = out["parameters"]
    fitted = [(complex(parameters[f"p{i}.re"]["value"], parameters[f"p{i}.im"]["value"]),
               parameters[f"p{i}.re"]["std"], parameters[f"p{i}.im"]["std"])
              for i in range(1, na + 1) if f"p{i}.im" in parameters]
    for p in poles:
        q, sd_re, sd_im = min(fitted, key=lambda f: abs(f[0] - p))
        assert abs(q.real - p.real) <= 5 * sd_re and abs(q.imag - p.imag) <= 5 * sd_im, (p, q, sd_re, sd_im)
    assert "vector fitting" in out["order_reason"] and "24/24" in out["order_reason"]
    assert seconds < 60  # about 7 s on one idle core; the bound leaves room for a shared machine
    # nlsid simulate runs the written model unchanged: its steady-state FRF (numpy FFT of the last
    # period) is the model's response at the excited lines, up to the transient left after four
    # periods, at most max |p|^(4 N) of the slowest pole (asserted below 1e-6 of the response)
    (tmp_path / "design.yaml").write_text(DESIGN)
    design = run_cli("design", tmp_path / "design.yaml", "-o", tmp_path / "exc.h5")
    assert design.exit_code == 0, design.stderr
    sim = run_cli("simulate", tmp_path / "m.yaml", "--excitation", tmp_path / "exc.h5", "-o", tmp_path / "sim.h5")
    assert sim.exit_code == 0, sim.stderr
    from nlsid.io.recording import read_runs

    run = read_runs(tmp_path / "sim.h5")[0]
    lines = run.excited_bins
    simulated = np.fft.fft(run.periods("y")[-1])[lines] / np.fft.fft(run.periods("u")[-1])[lines]
    written = _response(model, np.exp(2j * np.pi * lines / PERIOD))
    assert np.max(np.abs(poles)) ** (4 * PERIOD) < 1e-7
    assert np.max(np.abs(simulated - written) / np.abs(written)) < 1e-6


def test_a_given_high_order_is_fitted_stable(run_cli, tmp_path):
    """--order 24/24 on the same data: a stable model at the noise floor (the chi-square band of
    the true order's n_theta = 49), where the polynomial fit of that order does not reach it."""
    _, G = _structure(seed=3)
    _write_bla(tmp_path / "bla.h5", G)
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "24/24", "-o", tmp_path / "m.yaml", "--json")
    assert result.exit_code == 0, (result.stdout, result.stderr)
    out = result.json()
    assert out["order"] == "24/24" and out["stable"]
    low, high = stats.chi2.ppf([0.0005, 0.9995], 2 * BINS.size - 49) / 2
    assert low <= out["cost"] <= high, (out["cost"], low, high)
    assert out["order_reason"] == "given with --order" and "vector fitting" in out["fit_note"]


def test_a_continuous_model_of_many_poles_is_the_zero_order_hold_equivalent_of_the_fit(tmp_path):
    """--domain s, 24/24 through the face: the written continuous state space, discretised here by
    scipy.signal.cont2discrete (zero-order hold at fs), has at the lines the cost the report gives
    (to 1e-6: the matrix logarithm and exponential round-trip in double precision), within the
    chi-square band, and every pole in the left half plane."""
    import nlsid

    _, G = _structure(seed=3)
    _write_bla(tmp_path / "bla.h5", G)
    tf = nlsid.fit_tf(str(tmp_path / "bla.h5"), order=(24, 24), domain="s")
    tf.write(tmp_path / "s.yaml")
    model = yaml.safe_load((tmp_path / "s.yaml").read_text())["model"]
    assert model["type"] == "state_space" and model["domain"] == "continuous"
    A, B, C = np.array(model["A"]), np.array(model["B"])[:, None], np.array(model["C"])[None, :]
    assert np.max(np.linalg.eigvals(A).real) < 0
    Phi, Gamma, Cd, Dd, _ = signal.cont2discrete((A, B, C, np.array([[model["D"]]])), 1 / FS, "zoh")
    z = np.exp(2j * np.pi * BINS / PERIOD)
    response = np.array([(Cd @ np.linalg.solve(x * np.eye(A.shape[0]) - Phi, Gamma))[0, 0] for x in z]) + Dd[0, 0]
    cost = float(np.sum(np.abs(G - response) ** 2) / SIGMA**2)
    assert abs(cost - tf.cost) <= 1e-6 * tf.cost
    low, high = stats.chi2.ppf([0.0005, 0.9995], 2 * BINS.size - 49) / 2
    assert low <= cost <= high


def test_a_vector_fit_written_as_a_transfer_function_has_the_polynomial_fits_uncertainty():
    """Three modes (6 poles), where the polynomial fit 6/6 reaches the same minimum: the vector
    fit's coefficients, carried over from poles and residues, agree with the polynomial fit's
    as far as their costs do: near the minimum V - V_min = (1/2) d^T cov^-1 d, so a cost higher by
    D puts the parameters at most sqrt(2 D) std from the minimum in every component (10 % margin
    for the quadratic approximation), and their std (delta method from the pole-residue covariance)
    with the polynomial fit's own Cramer-Rao std (1/2 (J^T J)^-1 in the coefficients) within 5 %:
    the Gauss-Newton bound is invariant under a change of parameters at the same point, and the
    two minima differ by far less than the noise moves them."""
    from nlsid.fit.frf_data import FRFData
    from nlsid.fit.tf_fit import fit_order
    from nlsid.fit.tf_vector import fit_vector

    _, G = _structure(seed=3, modes=3)
    data = FRFData(BINS, G, np.full(BINS.size, SIGMA**2), FS, PERIOD)
    polynomial, vector = fit_order(data, 6, 6, "z"), fit_vector(data, 6, "z")
    assert vector.names == polynomial.names and vector.cost <= polynomial.cost + 1e-6
    distance = np.sqrt(2 * (polynomial.cost - vector.cost)) * 1.1 + 0.01
    assert np.all(np.abs(vector.values - polynomial.values) <= distance * polynomial.std)
    assert np.allclose(vector.std, polynomial.std, rtol=0.05)
    assert np.allclose(vector.response_std, polynomial.response_std, rtol=0.05)


def test_order_and_delay_auto_find_the_dead_time_the_data_hold(run_cli, tmp_path):
    """A second-order Chebyshev I low-pass behind 3 samples of dead time (2000 lines of a period of
    8192, noise 1 % of |G0| + 1e-4, variances exact), --order auto --delay auto: models with 1 or 2
    samples hold the truth too (the numerator starting later), so their costs differ from the
    3-sample one's by noise, while 4 samples cannot fit it; the longest delay within the
    likelihood-ratio bound of the lowest cost is 3, and the polynomial scan then takes 2/2 with
    its cost within the chi-square band."""
    b, a = signal.cheby1(2, 3, 2 * 0.08)
    period, bins = 8192, np.arange(1, 2001)
    z = np.exp(2j * np.pi * bins / period)
    G0 = np.polyval(b[::-1], 1 / z) / np.polyval(a[::-1], 1 / z) * z**-3
    sigma = 0.01 * np.abs(G0) + 1e-4
    rng = np.random.default_rng(6)
    G = G0 + sigma / np.sqrt(2) * (rng.standard_normal(bins.size) + 1j * rng.standard_normal(bins.size))
    _write_bla(tmp_path / "bla.h5", G, bins, sigma**2, 1.0, period)
    result = run_cli("fit", tmp_path / "bla.h5", "--order", "auto", "--delay", "auto", "-o", tmp_path / "m.yaml",
                     "--json")
    assert result.exit_code == 0, (result.stdout, result.stderr)
    out = result.json()
    assert out["delay_samples"] == 3 and out["order"] == "2/2", out["order_reason"]
    low, high = stats.chi2.ppf([0.0005, 0.9995], 2 * bins.size - 5) / 2
    assert low <= out["cost"] <= high
    assert "dead time 3 samples" in out["order_reason"]
