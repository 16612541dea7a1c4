"""Vector fitting in pole-residue form (nlsid.fit.vector_fitting).

References are independent of the code under test: the structures are modal superpositions
G(s) = d + sum_k r_k/(s - p_k) + r_k*/(s - p_k*) evaluated with numpy in this file; the discrete
structure is the exact zero-order-hold discretisation of the modal state space by
scipy.signal.cont2discrete, its response C (zI - Phi)^{-1} Gamma + D solved with numpy. The noise is
circular complex Gaussian of known variance per line, so at the minimum of a correct model the
weighted cost is V ~ (1/2) chi^2(2K - n_theta) (book 4.7 L) and the estimated natural frequencies
and dampings scatter around the truth by the Cramér-Rao standard deviations (asymptotically normal).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal, stats

from nlsid.errors import InputError
from nlsid.fit.vector_fitting import vector_fit


def _structure(modes: int, seed: int, f_low: float = 5.0, f_high: float = 400.0):
    """Modes log-spaced over f_low..f_high with damping ratios 0.5-3 % and random residues
    (mass-normalised-like, scaled by the natural frequency so every peak matters)."""
    rng = np.random.default_rng(seed)
    fn = np.geomspace(f_low, f_high, modes)
    zeta = rng.uniform(0.005, 0.03, modes)
    wn = 2 * np.pi * fn
    poles = -zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)
    residues = (rng.normal(size=modes) + 0.3j * rng.normal(size=modes)) * wn
    return fn, zeta, poles, residues


def _modal_response(s: np.ndarray, poles: np.ndarray, residues: np.ndarray, direct: float) -> np.ndarray:
    g = np.full(s.shape, complex(direct))
    for p, r in zip(poles, residues):
        g += r / (s - p) + np.conj(r) / (s - np.conj(p))
    return g


def _relative_pole_error(estimated: np.ndarray, true: np.ndarray) -> float:
    """Largest distance of a true pole (upper half) to its nearest estimate, relative to |pole|."""
    upper = estimated[estimated.imag > 0]
    return float(max(np.min(np.abs(upper - p)) / abs(p) for p in true))


def test_noise_free_continuous_structure_recovered():
    """15 modes (30 poles) in s, no noise: poles and response to ~1e-8 relative, stable."""
    fn, zeta, poles, residues = _structure(15, seed=3)
    f = np.linspace(1.0, 500.0, 1500)
    s = 2j * np.pi * f
    G = _modal_response(s, poles, residues, 0.1)
    fit = vector_fit(f, G, None, 30, domain="s")
    assert fit.order == 30 and fit.stable()
    assert _relative_pole_error(fit.all_poles(), poles) < 1e-8
    scale = np.max(np.abs(G))
    assert np.max(np.abs(fit.response(s) - G)) < 1e-8 * scale
    # the modal state space realises the same response (independent evaluation: C (sI - A)^-1 B + D)
    ss = fit.state_space()
    assert not ss.discrete and ss.order == 30
    h = np.array([ss.C @ np.linalg.solve(x * np.eye(30) - ss.A, ss.B) + ss.D for x in s[::50]])
    assert np.max(np.abs(h - G[::50])) < 1e-8 * scale
    modes = fit.modes()
    assert np.allclose([m["frequency"] for m in modes], fn, rtol=1e-8)
    assert np.allclose([m["damping"] for m in modes], zeta, rtol=1e-6)


def _sampled_structure(modes: int, seed: int, fs: float = 4000.0, period: int = 4096, lines: int = 1600):
    """The structure of :func:`_structure` (10..800 Hz) sampled through the zero-order hold: its real
    modal realisation discretised by scipy.signal.cont2discrete, the response C (zI - Phi)^-1 Gamma
    at lines 1..``lines`` of a period of ``period`` samples. Returns the truth and (f, z, G)."""
    fn, zeta, poles, residues = _structure(modes, seed=seed, f_low=10.0, f_high=800.0)
    n = 2 * poles.size
    A = np.zeros((n, n))
    B = np.zeros(n)
    C = np.zeros(n)
    for i, (p, r) in enumerate(zip(poles, residues)):
        A[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[p.real, p.imag], [-p.imag, p.real]]
        B[2 * i] = 2.0
        C[2 * i:2 * i + 2] = [r.real, r.imag]
    Phi, Gamma, Cd, Dd, _ = signal.cont2discrete((A, B[:, None], C[None, :], np.zeros((1, 1))), 1 / fs, "zoh")
    f = np.arange(1, lines + 1) * fs / period
    z = np.exp(2j * np.pi * f / fs)
    G = np.array([(Cd @ np.linalg.solve(x * np.eye(n) - Phi, Gamma))[0, 0] for x in z]) + Dd[0, 0]
    return (fn, zeta, poles, residues), (f, z, G)


def test_noise_free_discrete_forty_poles_exact_zoh():
    """20 modes (40 poles) of a continuous structure sampled through the zero-order hold
    (scipy.signal.cont2discrete): the discrete poles e^{p Ts} to ~1e-8 relative, stable, and the
    discrete modal state space reproduces the response."""
    fs = 4000.0
    (fn, zeta, poles, residues), (f, z, G) = _sampled_structure(20, seed=5, fs=fs)
    n = 2 * poles.size
    fit = vector_fit(f, G, None, n, domain="z", fs=fs)
    assert fit.stable()
    assert _relative_pole_error(fit.all_poles(), np.exp(poles / fs)) < 1e-8
    assert np.max(np.abs(fit.response(z) - G)) < 1e-8 * np.max(np.abs(G))
    ss = fit.state_space()
    assert ss.discrete and ss.order == n
    assert np.max(np.abs(ss.frequency_response(z) - G)) < 1e-8 * np.max(np.abs(G))
    assert np.allclose([m["frequency"] for m in fit.modes()], fn, rtol=1e-8)
    # back through the hold: the continuous structure itself, poles and response at s = j 2 pi f
    continuous = fit.continuous_state_space()
    assert not continuous.discrete
    found = np.linalg.eigvals(continuous.A)
    assert _relative_pole_error(found, poles) < 1e-8
    s = 2j * np.pi * f[::40]
    truth = _modal_response(s, poles, residues, 0.0)
    assert np.max(np.abs(continuous.frequency_response(s) - truth)) < 1e-7 * np.max(np.abs(truth))


def test_noisy_structure_modes_within_standard_errors_and_cost_chi_square():
    """12 modes, complex Gaussian noise of known variance per line (1 % of the mean |G|).

    Each natural frequency and damping ratio lies within 4 standard errors of the truth (24
    comparisons: a false failure has probability ~24 x 6e-5); the sum of the 24 squared
    standardised errors lies within the 0.1 % and 99.9 % quantiles of chi^2(24), which fails if
    the reported standard errors are too large as well as too small; the weighted cost lies
    within the 0.1 % and 99.9 % quantiles of (1/2) chi^2(2K - n_theta)."""
    fn, zeta, poles, residues = _structure(12, seed=11)
    f = np.linspace(1.0, 500.0, 2000)
    s = 2j * np.pi * f
    G0 = _modal_response(s, poles, residues, 0.1)
    rng = np.random.default_rng(7)
    sd = 0.01 * np.mean(np.abs(G0)) * (1 + 0.5 * np.sin(f / 40))      # a variance that varies over lines
    G = G0 + sd / np.sqrt(2) * (rng.normal(size=f.size) + 1j * rng.normal(size=f.size))
    fit = vector_fit(f, G, sd**2, 24, domain="s")
    assert fit.stable() and fit.covariance is not None
    modes = fit.modes()
    z_freq = np.array([(m["frequency"] - t) / m["frequency_std"] for m, t in zip(modes, fn)])
    z_damp = np.array([(m["damping"] - t) / m["damping_std"] for m, t in zip(modes, zeta)])
    assert np.all(np.abs(z_freq) < 4) and np.all(np.abs(z_damp) < 4), (z_freq, z_damp)
    total = np.sum(z_freq**2) + np.sum(z_damp**2)
    assert stats.chi2.ppf(0.001, 24) < total < stats.chi2.ppf(0.999, 24), total
    dof = 2 * f.size - fit.n_parameters
    assert fit.n_parameters == 49
    assert stats.chi2.ppf(0.001, dof) / 2 < fit.cost < stats.chi2.ppf(0.999, dof) / 2, fit.cost
    # the cost is the weighted cost of the returned model (recomputed here)
    assert fit.cost == pytest.approx(np.sum(np.abs(G - fit.response(s)) ** 2 / sd**2), rel=1e-9)


@pytest.mark.parametrize("domain", ["s", "z"])
def test_unstable_poles_reflected_when_stability_asked(domain):
    """A response with an unstable pair: without the constraint the pair is recovered outside the
    stable region; with it every pole is stable, the relocation's pair mirrored (s: -Re p; z: 1/p*)."""
    fs = 1000.0
    f = np.linspace(1.0, 400.0, 400)
    p_s = np.array([20.0 + 2j * np.pi * 50, -30 + 2j * np.pi * 150])
    r = np.array([100.0 + 20j, 300.0 - 50j])
    if domain == "s":
        x, p = 2j * np.pi * f, p_s
    else:
        x, p = np.exp(2j * np.pi * f / fs), np.exp(p_s / fs)
        r = r / fs
    G = _modal_response(x, p, r, 0.0)
    free = vector_fit(f, G, None, 4, domain=domain, fs=fs, stable=False)
    assert not free.stable()
    assert _relative_pole_error(free.all_poles(), p) < 1e-8
    relocated = vector_fit(f, G, None, 4, domain=domain, fs=fs, stable=True, refine=False)
    assert relocated.stable()
    mirrored = -p[0].conjugate() if domain == "s" else 1 / p[0].conjugate()
    upper = relocated.poles[relocated.poles.imag > 0]
    # the relocation settles on the unstable pole mirrored (within a few % of its distance to it)
    assert np.min(np.abs(upper - mirrored)) < 0.05 * abs(p[0] - mirrored)
    # the refinement keeps the poles stable and can only lower the cost
    refined = vector_fit(f, G, None, 4, domain=domain, fs=fs, stable=True)
    assert refined.stable() and refined.cost <= relocated.cost


def test_delay_corrected_in_z():
    """A known dead time of 3 samples: the data times z^3 are fitted, the response includes z^-3."""
    fs = 100.0
    f = np.linspace(0.5, 45.0, 300)
    z = np.exp(2j * np.pi * f / fs)
    p = np.array([0.9 * np.exp(0.6j)])
    r = np.array([0.2 + 0.1j])
    G = _modal_response(z, p, r, 0.5) * z**-3
    fit = vector_fit(f, G, None, 2, domain="z", fs=fs, delay=3)
    assert np.max(np.abs(fit.frequency_response(f) - G)) < 1e-10
    assert fit.state_space().delay == pytest.approx(0.03)


@pytest.mark.parametrize("kwargs, fragment", [
    ({"order": 0}, "order"),
    ({"order": 400}, "order"),
    ({"domain": "w"}, "domain"),
    ({"variance": -1.0}, "variance"),
    ({"fs": 10.0}, "frequency"),
    ({"domain": "s", "delay": 2}, "delay"),
])
def test_bad_input_named(kwargs, fragment):
    f = np.linspace(1.0, 40.0, 100)
    args = {"frequency": f, "G": 1 / (1 + 1j * f), "variance": np.ones(f.size), "order": 2, "domain": "z",
            "fs": 100.0}
    args.update(kwargs)
    if np.isscalar(args["variance"]):
        args["variance"] = np.full(f.size, args["variance"])
    with pytest.raises(InputError) as error:
        vector_fit(**args)
    assert str(error.value).startswith(fragment)


def test_noisy_forty_poles_in_z_within_standard_errors():
    """The 40-pole sampled structure with complex Gaussian noise of 1 % of the mean |G| on 1,600
    lines (the lowest modes have a half-power bandwidth below the line spacing): the z fit is
    stable, each of the 20 frequencies and dampings (from s = fs ln z, delta method) within 4
    standard errors (40 comparisons: a false failure ~40 x 6e-5), their squared standardised errors
    summing within the 0.1 % and 99.9 % quantiles of chi^2(40), and the cost within those of
    (1/2) chi^2(2F - 81). (Over 12 noise seeds: sum 41.8 on average, cost 1549.9 against 1559.5.)"""
    fs = 4000.0
    (fn, zeta, _, _), (f, _, G0) = _sampled_structure(20, seed=5, fs=fs)
    rng = np.random.default_rng(100)
    sd = np.full(f.size, 0.01 * np.mean(np.abs(G0)))
    G = G0 + sd / np.sqrt(2) * (rng.normal(size=f.size) + 1j * rng.normal(size=f.size))
    fit = vector_fit(f, G, sd**2, 40, domain="z", fs=fs)
    assert fit.stable() and fit.order == 40 and fit.n_parameters == 81
    modes = fit.modes()
    z_freq = np.array([(m["frequency"] - t) / m["frequency_std"] for m, t in zip(modes, fn)])
    z_damp = np.array([(m["damping"] - t) / m["damping_std"] for m, t in zip(modes, zeta)])
    assert np.all(np.abs(z_freq) < 4) and np.all(np.abs(z_damp) < 4), (z_freq, z_damp)
    assert stats.chi2.ppf(0.001, 40) < np.sum(z_freq**2) + np.sum(z_damp**2) < stats.chi2.ppf(0.999, 40)
    dof = 2 * f.size - fit.n_parameters
    assert stats.chi2.ppf(0.001, dof) / 2 < fit.cost < stats.chi2.ppf(0.999, dof) / 2, fit.cost
