"""``nlsid fit bla.h5 --order auto --max-order N`` before and after the pole count by vector fitting,
in the same run; prints JSON.

Data: a structure of ``modes`` modes (natural frequencies log-spaced 10..800 Hz, damping 0.5-3 %,
modal superposition) sampled through the zero-order hold (scipy.signal.cont2discrete) at 4 kHz,
on ``lines`` lines k = 1.. of a 4,096-sample period, circular complex noise of std 1 % of the
mean |G|, the variances known (the generator of ``benchmarks/high_order_fit.py``, the mode
count a parameter).

* ``before``: ``--max-order N`` as it was, the polynomial scan alone: every nb <= na <= N
  (nlsid.fit.order.select_order at delay 0, ``--delay 0`` being the command's default);
* ``after``: ``--max-order N`` now (nlsid.fit.bla_fit.fit_level: the pole count by vector fits
  up to N poles, then the choice among them, or the closest fit where the cap is reached).

For each: wall seconds, the chosen order, the weighted cost V = sum |G_k - G(z_k)|^2 / sigma_k^2
recomputed from the model's response, its bound, stability, and whether the reason says that the
cap was reached. ``--before-limit SECONDS``: the polynomial scan is run in a child process and
stopped after that many seconds (reported as ``stopped``). One BLAS thread. ``load_average`` at
start and end.

Usage: ``python benchmarks/max_order_fit.py MODES MAX_ORDER [--lines L] [--before-limit S] [--no-before]``.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: every BLAS library one thread

import argparse
import json
import multiprocessing
import time

import numpy as np
from scipy import signal
from threadpoolctl import threadpool_limits

from nlsid.fit.bla_fit import fit_level
from nlsid.fit.bla_source import BLALevel
from nlsid.fit.frf_data import FRFData
from nlsid.fit.order import select_order


def structure(modes: int, lines: int, seed: int = 5) -> tuple[FRFData, np.ndarray]:
    """The FRF data of ``modes`` modes (module docstring) and their natural frequencies (Hz)."""
    rng = np.random.default_rng(seed)
    fs, period = 4000.0, 4096
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
    bins = np.arange(1, lines + 1)
    z = np.exp(2j * np.pi * bins / period)
    g = np.array([(Cd @ np.linalg.solve(x * np.eye(n) - Phi, Gamma))[0, 0] for x in z])
    sd = np.full(bins.size, 0.01 * np.mean(np.abs(g)))
    noisy = g + sd / np.sqrt(2) * (rng.standard_normal(g.size) + 1j * rng.standard_normal(g.size))
    return FRFData(bins, noisy, sd**2, fs, period), fn


def _entry(seconds: float, fit, data: FRFData, reason: str) -> dict:
    model = fit.model
    cost = float(np.sum(np.abs(data.G - model.response(data.bins, data.period)) ** 2 / data.variance))
    return {"seconds": round(seconds, 2), "order": f"{fit.nb}/{fit.na}", "fit": fit.how, "cost": cost,
            "bound": fit.cost_bound, "at_noise_floor": bool(cost <= fit.cost_bound), "stability": model.stability(),
            "cap_reached": "cap of" in reason and "was reached" in reason}


def _before(data: FRFData, max_order: int, queue) -> None:
    with threadpool_limits(1):
        start = time.perf_counter()
        selection = select_order(data, max_order, "z", 0)
        queue.put(_entry(time.perf_counter() - start, selection.fit, data, selection.reason))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("modes", type=int)
    parser.add_argument("max_order", type=int)
    parser.add_argument("--lines", type=int, default=1600)
    parser.add_argument("--before-limit", type=float, default=1800.0)
    parser.add_argument("--no-before", action="store_true")
    args = parser.parse_args()
    load_start = os.getloadavg()
    data, _ = structure(args.modes, args.lines)
    level = BLALevel(data, np.full(data.bins.size, np.nan), np.full(data.bins.size, np.nan), [], "robust")
    out = {"poles": 2 * args.modes, "lines": args.lines, "max_order": args.max_order}
    with threadpool_limits(1):
        start = time.perf_counter()
        result = fit_level(level, None, "z", 0, args.max_order)
        out["after"] = _entry(time.perf_counter() - start, result.fit, data, result.selection.reason)
    if not args.no_before:
        queue = multiprocessing.Queue()
        child = multiprocessing.Process(target=_before, args=(data, args.max_order, queue))
        start = time.perf_counter()
        child.start()
        child.join(args.before_limit)
        if child.is_alive():
            child.terminate()
            child.join()
            out["before"] = {"stopped": True, "seconds": round(time.perf_counter() - start, 1)}
        else:
            out["before"] = queue.get()
    out["load_average"] = {"start": load_start, "end": os.getloadavg()}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
