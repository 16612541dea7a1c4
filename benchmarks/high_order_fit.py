"""``nlsid fit --order auto`` (and a given high order) before and after vector fitting, in the same
run; prints JSON.

* ``wiener_hammerstein_18000_lines``: the BLA of a Wiener-Hammerstein-like system, G1 G2 with
  G1 = cheby1(3, 0.5 dB, 0.17) and G2 = cheby2(3, 40 dB, 0.2) (the structure of the
  Wiener-Hammerstein benchmark's filters; 6 poles, z domain), on 18,000 excited lines k = 1..18000
  of a period of 65,536 samples, with circular complex noise of standard deviation 1 % of |G| plus
  1e-4 of the peak (the stochastic nonlinear distortion and noise of a BLA), the variances known.
  ``polynomial_auto``: the polynomial order scan alone (nlsid.fit.order.select_order, orders up to
  4/4, then up to 10/10 while none reaches its cost bound: ``--order auto`` before vector fitting);
  ``auto``: ``nlsid fit bla.h5 --order auto`` now (nlsid.fit.bla_fit.fit_level: the pole count by
  vector fitting, then the choice among the vector fits, nlsid.fit.order_poles).
* ``structure_40_poles``: 20 modes (natural frequencies log-spaced 10..800 Hz, damping 0.5-3 %)
  sampled through the zero-order hold (scipy.signal.cont2discrete) at 4 kHz, 1,600 lines of a
  4,096-sample period, noise 1 % of the mean |G|. ``polynomial_40_40``: the polynomial fit of
  40/40 (nlsid.fit.tf_fit.fit_transfer_function, ``--order 40/40`` before); ``given_40_40``:
  ``--order 40/40`` now (vector fitting); ``polynomial_auto`` and ``auto`` as above.

For each: wall seconds, the weighted cost V = sum |G_k - G(z_k)|^2 / sigma_k^2 recomputed here from
the response of the model as written (transfer function or modal state space), its expected value
F - n_theta/2 and bound, whether it lies within the bound (the noise floor), the stability and, for
the structure, the largest error of the natural frequencies found. ``speedup``: seconds before over
seconds now where both reach the noise floor (matched accuracy), else null with ``note`` saying
which does not. One BLAS thread (as ``nlsid`` runs). ``load_average`` (1, 5, 15 min) at start and
end: the machine may be shared. ``--quick``: 2,000 lines and no polynomial 40/40 fit.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: every BLAS library one thread

import json
import sys
import time

import numpy as np
from scipy import signal
from threadpoolctl import threadpool_limits

from nlsid.fit.bla_fit import fit_level
from nlsid.fit.bla_source import BLALevel
from nlsid.fit.frf_data import FRFData
from nlsid.fit.order import select_order
from nlsid.fit.tf_fit import fit_transfer_function

QUICK = "--quick" in sys.argv          # a smoke run: fewer lines, no 40/40 polynomial fit


def _noisy(g: np.ndarray, sd: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return g + sd / np.sqrt(2) * (rng.standard_normal(g.size) + 1j * rng.standard_normal(g.size))


def _timed(call):
    start = time.perf_counter()
    out = call()
    return time.perf_counter() - start, out


def _entry(seconds: float, fit, data: FRFData, true_frequencies: np.ndarray | None = None) -> dict:
    """The numbers of one fit: its model's cost recomputed from the model's own response."""
    model = fit.model
    cost = float(np.sum(np.abs(data.G - model.response(data.bins, data.period)) ** 2 / data.variance))
    out = {"seconds": round(seconds, 3), "order": f"{fit.nb}/{fit.na}", "n_theta": fit.n_theta,
           "model": model.config()["type"], "fit": fit.how, "cost": cost, "expected_cost": fit.expected_cost,
           "bound": fit.cost_bound, "at_noise_floor": bool(cost <= fit.cost_bound), "stability": model.stability()}
    if true_frequencies is not None:
        poles = model.poles()
        s = np.log(poles[poles.imag > 0].astype(complex)) * data.fs if model.domain == "z" else poles[poles.imag > 0]
        found = np.sort(np.abs(s) / (2 * np.pi))
        out["largest_frequency_error_relative"] = (float(np.max(np.abs(found - true_frequencies) / true_frequencies))
                                                   if found.size == true_frequencies.size else None)
    return out


def _speedup(before: dict, now: dict) -> dict:
    if before["at_noise_floor"] and now["at_noise_floor"]:
        return {"speedup": round(before["seconds"] / now["seconds"], 1)}
    missing = [name for name, entry in (("before", before), ("now", now)) if not entry["at_noise_floor"]]
    return {"speedup": None, "note": f"not at the noise floor: {', '.join(missing)} (cost above its bound)",
            "time_ratio": round(before["seconds"] / now["seconds"], 1)}


def _level(data: FRFData) -> BLALevel:
    return BLALevel(data, np.full(data.bins.size, np.nan), np.full(data.bins.size, np.nan), [], "robust")


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
    t_poly, poly = _timed(lambda: select_order(data, 4, "z", 0, extend_to=10))
    t_now, now = _timed(lambda: fit_level(_level(data), None, "z", 0, None))
    before, after = _entry(t_poly, poly.fit, data), _entry(t_now, now.fit, data)
    return {"lines": lines, "polynomial_auto": before, "auto": after, **_speedup(before, after)}


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
    t_given, given = _timed(lambda: fit_level(_level(data), (n, n), "z", 0, None))
    out["given_40_40"] = _entry(t_given, given.fit, data, fn)
    t_auto, auto = _timed(lambda: fit_level(_level(data), None, "z", 0, None))
    out["auto"] = _entry(t_auto, auto.fit, data, fn)
    t_poly_auto, poly_auto = _timed(lambda: select_order(data, 4, "z", 0, extend_to=10))
    out["polynomial_auto"] = _entry(t_poly_auto, poly_auto.fit, data, fn)
    out["auto_against_before"] = _speedup(out["polynomial_auto"], out["auto"])
    if polynomial:
        t_poly, poly = _timed(lambda: fit_transfer_function(data, n, n, "z", 0))
        out["polynomial_40_40"] = _entry(t_poly, poly, data, fn)
        out["given_against_before"] = _speedup(out["polynomial_40_40"], out["given_40_40"])
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
