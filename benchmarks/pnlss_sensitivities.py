"""Exact PNLSS sensitivities (the forward recursion of nlsid.simulate.pnlss_kernels) against central
finite differences of the same simulation; prints JSON.

Two cases: the Duffing size of the yardstick (2 states, degrees 2 and 3 in the states and the input,
7 x 8192 samples as one record) and the Wiener-Hammerstein size (6 states, same degrees, 80,000
samples), and the yardstick's LFR form at that size (7 states, monomials of degrees 2 and 3 of 2
combinations z = Cz x + Dz u, whose columns are included); a random stable model with small
nonlinear coefficients, an arbitrary record (the initial state's columns included). For each:

* ``max_relative_difference``: the largest over the columns of ||J_exact - J_fd|| / ||J_fd||
  (central differences, step 1e-5 relative: truncation and rounding both near 1e-10), on the first
  ``fd_samples`` samples (the finite differences cost 2 simulations per column);
* ``exact_seconds``: the exact Jacobian over all samples (kernel only, compiled beforehand), the
  faster of two runs; ``rate``: samples x columns per second;
* ``fd_seconds``: the finite-difference Jacobian over all samples, extrapolated from its time on
  ``fd_samples`` (it is linear in the samples), and ``speed_ratio`` = fd_seconds / exact_seconds;
* ``normal_matrix_seconds``: J'J of all rows (BLAS dsyrk, one thread as the suite and the CLI run),
  timed on whole multiples of the kept rows and scaled to all samples.

``load_average`` at start and end: the machine is shared, other jobs only add time.
"""

from __future__ import annotations

import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.linalg.blas import dsyrk  # noqa: E402

from nlsid.fit.pnlss import global_vector, with_vector  # noqa: E402
from nlsid.simulate.pnlss_runs import Record, jacobian_blocks, simulate_record  # noqa: E402
from nlsid.models.pnlss import Pnlss, exponents  # noqa: E402


def _model(n: int, rng, lfr_inputs: int = 0) -> Pnlss:
    A = np.diag(np.linspace(0.9, 0.3, n)) + 0.02 * rng.standard_normal((n, n))
    if lfr_inputs:
        nz = exponents(lfr_inputs, (2, 3), False).shape[0]
        Cz, Dz = rng.standard_normal((lfr_inputs, n)) / np.sqrt(n), rng.standard_normal(lfr_inputs)
        return Pnlss(A, rng.standard_normal(n), rng.standard_normal(n), 0.1, 1e-2 * rng.standard_normal((n, nz)),
                     1e-2 * rng.standard_normal(nz), 1.0, (2, 3), (2, 3), Cz=Cz, Dz=Dz)
    nz = exponents(n, (2, 3)).shape[0]
    return Pnlss(A, rng.standard_normal(n), rng.standard_normal(n), 0.1, 1e-3 * rng.standard_normal((n, nz)),
                 1e-3 * rng.standard_normal(nz), 1.0, (2, 3), (2, 3))


def _exact(model, record, x0, keep: int):
    """The Jacobian's first ``keep`` rows and its column count; every row is formed (in chunks, as
    the fit forms them), the rest not stored."""
    kept, columns = [], 0
    for _, J in jacobian_blocks(model, record, x0, 1e9):
        columns = J.shape[1]
        if sum(k.shape[0] for k in kept) < keep:
            kept.append(J.copy())
    return np.vstack(kept)[:keep], columns


def _finite_differences(model, record, x0, relative=1e-5):
    n = model.order
    theta = np.concatenate([x0, global_vector(model)])
    columns = []
    for p in range(theta.size):
        h = relative * max(1.0, abs(theta[p]))
        up, down = theta.copy(), theta.copy()
        up[p] += h
        down[p] -= h
        plus = simulate_record(with_vector(model, up[n:]), record, up[:n], 1e9)
        minus = simulate_record(with_vector(model, down[n:]), record, down[:n], 1e9)
        columns.append((plus - minus) / (2 * h))
    return np.column_stack(columns)


def case(name: str, n: int, samples: int, fd_samples: int, lfr_inputs: int = 0) -> dict:
    rng = np.random.default_rng(0)
    model = _model(n, rng, lfr_inputs)
    u = 0.5 * rng.standard_normal(samples)
    record = Record(name, u, np.zeros(samples), None)
    x0 = 0.1 * rng.standard_normal(n)
    short = Record(name, u[:fd_samples], np.zeros(fd_samples), None)
    _exact(model, short, x0, 1)  # compile
    times = []
    for _ in range(2):
        clock = time.perf_counter()
        exact_short, width = _exact(model, record, x0, fd_samples)
        times.append(time.perf_counter() - clock)
    rows = np.tile(exact_short, (samples // fd_samples, 1))
    clock = time.perf_counter()
    dsyrk(1.0, rows.T, trans=0)
    normal = (time.perf_counter() - clock) * samples / rows.shape[0]
    clock = time.perf_counter()
    fd = _finite_differences(model, short, x0)
    fd_seconds = (time.perf_counter() - clock) * samples / fd_samples
    relative = np.linalg.norm(exact_short - fd, axis=0) / np.linalg.norm(fd, axis=0)
    exact_seconds = min(times)
    return {"case": name, "states": n, "lfr_inputs": lfr_inputs, "samples": samples, "columns": int(width),
            "fd_samples": fd_samples, "max_relative_difference": float(relative.max()),
            "exact_seconds": exact_seconds, "rate": samples * width / exact_seconds,
            "fd_seconds": fd_seconds, "speed_ratio": fd_seconds / exact_seconds,
            "normal_matrix_seconds": normal}


def main() -> None:
    start = os.getloadavg()
    results = [case("duffing_size", 2, 7 * 8192, 8192), case("wiener_hammerstein_size", 6, 80000, 2000),
               case("wiener_hammerstein_size_lfr", 7, 80000, 2000, lfr_inputs=2)]
    print(json.dumps({"cases": results, "load_average": {"start": start, "end": os.getloadavg()}}, indent=2))


if __name__ == "__main__":
    main()
