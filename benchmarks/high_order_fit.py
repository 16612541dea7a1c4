"""Vector fitting (:mod:`nlsid.fit.vector_fitting`) against the polynomial transfer-function fit of
``nlsid fit``, side by side in the same run; prints JSON.

* ``wiener_hammerstein_18000_lines``: the BLA of a Wiener-Hammerstein-like system, G1 G2 with
  G1 = cheby1(3, 0.5 dB, 0.17) and G2 = cheby2(3, 40 dB, 0.2) (the structure of the
  Wiener-Hammerstein benchmark's filters; 6 poles, z domain), on 18,000 excited lines k = 1..18000
  of a period of 65,536 samples, with circular complex noise of standard deviation 1 % of |G| plus
  1e-4 of the peak (the stochastic nonlinear distortion and noise of a BLA), the variances known.
  ``polynomial_auto``: the path of ``nlsid fit bla.h5 --order auto`` (nlsid.fit.bla_fit.fit_level:
  orders up to 4/4, then up to 10/10 while none reaches its cost bound). ``vf_auto``: vector
  fitting at N = 1, 2, ... poles until the weighted cost lies within the same bound
  (nlsid.fit.pole_count.select_poles: nlsid.fit.cost_statistics.cost_bound, n_theta = 2N + 1), stable.
* ``structure_40_poles``: 20 modes (natural frequencies log-spaced 10..800 Hz, damping 0.5-3 %)
  sampled through the zero-order hold (scipy.signal.cont2discrete) at 4 kHz, 1,600 lines of a
  4,096-sample period, noise 1 % of the mean |G|. ``polynomial_40_40``: ``nlsid fit --order 40/40``
  (nlsid.fit.tf_fit.fit_transfer_function, z); ``polynomial_auto``: ``--order auto`` (up to 10/10); ``vf_40``: vector fitting with 40 poles;
  ``vf_auto``: the scan of 1, 2, ... poles (up to 44) to the cost bound.

For each: wall seconds, the weighted cost V = sum |G_k - G(z_k)|^2 / sigma_k^2 recomputed here from
the model's response, its expected value F - n_theta/2 and bound, the stability and, for the
structure, the largest error of the natural frequencies. One BLAS thread (as ``nlsid`` runs).
``load_average`` (1, 5, 15 min) at start and end: the machine is shared.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
from scipy import signal
from threadpoolctl import threadpool_limits

from nlsid.fit.bla_fit import fit_level
from nlsid.fit.bla_source import BLALevel
from nlsid.fit.cost_statistics import cost_bound
from nlsid.fit.frf_data import FRFData
from nlsid.fit.tf_fit import fit_transfer_function
from nlsid.fit.pole_count import select_poles
from nlsid.fit.vector_fitting import vector_fit

QUICK = "--quick" in sys.argv          # a smoke run: fewer lines, no 40/40 polynomial fit


def _noisy(g: np.ndarray, sd: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return g + sd / np.sqrt(2) * (rng.standard_normal(g.size) + 1j * rng.standard_normal(g.size))


def _cost(G: np.ndarray, model: np.ndarray, variance: np.ndarray) -> float:
    return float(np.sum(np.abs(G - model) ** 2 / variance))


def _timed(call):
    start = time.perf_counter()
    out = call()
    return time.perf_counter() - start, out


def _polynomial_entry(seconds: float, fit, data: FRFData) -> dict:
    model = fit.model
    n_theta = len(model.num) + len(model.den) - 1
    return {"seconds": round(seconds, 3), "order": f"{len(model.num) - 1}/{len(model.den) - 1}",
            "n_theta": n_theta, "cost": _cost(data.G, model.response(data.bins, data.period), data.variance),
            "expected_cost": data.bins.size - n_theta / 2, "bound": cost_bound(data.bins.size, n_theta, None),
            "stability": model.stability()}


def _vf_entry(seconds: float, fit, data: FRFData) -> dict:
    return {"seconds": round(seconds, 3), "poles": fit.order, "n_theta": fit.n_parameters,
            "cost": _cost(data.G, fit.frequency_response(data.frequency), data.variance),
            "expected_cost": data.bins.size - fit.n_parameters / 2,
            "bound": cost_bound(data.bins.size, fit.n_parameters, None), "stable": fit.stable(),
            "relocation_steps": fit.iterations, "refined": fit.refined}


def wiener_hammerstein(lines: int) -> dict:
    rng = np.random.default_rng(1)
    b1, a1 = signal.cheby1(3, 0.5, 0.17)
    b2, a2 = signal.cheby2(3, 40, 0.2)
    period = 65536
    bins = np.arange(1, lines + 1)
    z = np.exp(2j * np.pi * bins / period)
    g = (np.polyval(b1[::-1], 1 / z) / np.polyval(a1[::-1], 1 / z)
         * np.polyval(b2[::-1], 1 / z) / np.polyval(a2[::-1], 1 / z))
    sd = 0.01 * np.abs(g) + 1e-4 * np.abs(g).max()
    data = FRFData(bins, _noisy(g, sd, rng), sd**2, 1.0, period)
    level = BLALevel(data, np.full(lines, np.nan), np.full(lines, np.nan), [], "robust")
    t_poly, poly = _timed(lambda: fit_level(level, None, "z", 0, None))
    t_vf, vf = _timed(lambda: select_poles(data, 40, "z").fit)
    return {"lines": lines, "polynomial_auto": _polynomial_entry(t_poly, poly.fit, data),
            "vf_auto": _vf_entry(t_vf, vf, data), "speedup": round(t_poly / t_vf, 1)}


def structure_40_poles(polynomial: bool) -> dict:
    rng = np.random.default_rng(5)
    modes, fs, period = 20, 4000.0, 4096
    fn = np.geomspace(10.0, 800.0, modes)
    zeta = rng.uniform(0.005, 0.03, modes)
    wn = 2 * np.pi * fn
    poles = -zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)
    residues = (rng.normal(size=modes) + 0.3j * rng.normal(size=modes)) * wn
    n = 2 * modes
    A, B, C = np.zeros((n, n)), np.zeros((n, 1)), np.zeros((1, n))
    for i, (p, r) in enumerate(zip(poles, residues)):
        A[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[p.real, p.imag], [-p.imag, p.real]]
        B[2 * i, 0] = 2.0
        C[0, 2 * i:2 * i + 2] = [r.real, r.imag]
    Phi, Gamma, Cd, _, _ = signal.cont2discrete((A, B, C, np.zeros((1, 1))), 1 / fs, "zoh")
    bins = np.arange(1, 1601)
    z = np.exp(2j * np.pi * bins / period)
    g = np.array([(Cd @ np.linalg.solve(x * np.eye(n) - Phi, Gamma))[0, 0] for x in z])
    sd = np.full(bins.size, 0.01 * np.mean(np.abs(g)))
    data = FRFData(bins, _noisy(g, sd, rng), sd**2, fs, period)
    out = {"lines": int(bins.size), "poles": n}
    t_vf, vf = _timed(lambda: vector_fit(data.frequency, data.G, data.variance, n, "z", fs))
    found = np.array([m["frequency"] for m in vf.modes()])
    out["vf_40"] = _vf_entry(t_vf, vf, data)
    out["vf_40"]["largest_frequency_error_relative"] = (float(np.max(np.abs(found - fn) / fn))
                                                        if found.size == fn.size else None)
    t_auto, selection = _timed(lambda: select_poles(data, 44, "z"))
    out["vf_auto"] = _vf_entry(t_auto, selection.fit, data)
    out["vf_auto"]["accepted"] = selection.accepted
    if polynomial:
        t_poly, poly = _timed(lambda: fit_transfer_function(data, n, n, "z", 0))
        out["polynomial_40_40"] = _polynomial_entry(t_poly, poly, data)
        level = BLALevel(data, np.full(bins.size, np.nan), np.full(bins.size, np.nan), [], "robust")
        t_auto, chosen = _timed(lambda: fit_level(level, None, "z", 0, None))
        out["polynomial_auto"] = _polynomial_entry(t_auto, chosen.fit, data)
        out["polynomial_auto"]["accepted"] = bool(chosen.fit.accepted)
    return out


def main() -> None:
    load_start = os.getloadavg()
    with threadpool_limits(1):
        result = {"wiener_hammerstein_18000_lines": wiener_hammerstein(2000 if QUICK else 18000),
                  "structure_40_poles": structure_40_poles(not QUICK)}
    result["load_average"] = {"start": load_start, "end": os.getloadavg()}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
