"""Benchmark of the ``bla`` stage: throughput against the read + FFT limit, and peak memory.

Writes a recording of ``--samples`` time instants (u and y, float64) in ``--runs`` runs of one
level (a random-phase odd multisine through a Wiener system with noise), then measures

- ``limit``: reading the u and y datasets of every run with plain h5py and taking the FFT of their
  (P, N) periods, the least any BLA analysis must do;
- ``bla``: :func:`nlsid.analysis.levels.analyse_recording` on the same file (validation, spectra,
  robust and fast methods, output spectrum);

each after a warm-up pass, so both read from the page cache. Peak memory (ru_maxrss) is measured
in fresh subprocesses that analyse the first quarter of the runs and all of them: run-by-run
processing keeps the two equal. Prints one JSON document.

Usage: python benchmarks/bla.py [--samples 1e8] [--runs 20] [--dir /tmp]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from itertools import islice
from pathlib import Path

import h5py
import numpy as np


def make_recording(path: Path, samples: int, runs: int, period: int) -> None:
    from scipy import signal

    from nlsid.io.hdf5_recording import write_hdf5_recording
    from nlsid.io.run import Run

    rng = np.random.default_rng(0)
    periods = -(-samples // (runs * period))
    excited = np.arange(1, period // 8, 2)
    b, a = signal.butter(2, 0.2)

    def run(m: int) -> Run:
        spectrum = np.zeros(period // 2 + 1, complex)
        spectrum[excited] = np.exp(2j * np.pi * rng.random(excited.size))
        u0 = np.tile(np.fft.irfft(spectrum, n=period), periods)
        u0 /= np.std(u0)
        x = signal.lfilter(b, a, u0)
        y = x + 0.1 * x**3 + 1e-3 * rng.standard_normal(u0.size)
        return Run(f"ms_{m:03d}", 1000.0, "multisine", u0 + 1e-3 * rng.standard_normal(u0.size), y,
                   period=period, realization=m, level=1.0, excited_bins=excited)

    write_hdf5_recording(path, (run(m) for m in range(runs)))


def read_and_fft(path: Path) -> int:
    """The limit: read u and y of every run with h5py and FFT their periods; returns samples."""
    total = 0
    with h5py.File(path, "r") as handle:
        for group in handle["runs"].values():
            period = int(group.attrs["period"])
            for name in ("u", "y"):
                x = group[name][()]
                np.fft.rfft(x.reshape(-1, period), axis=1)
            total += x.size
    return total


def analyse(path: Path, runs: int | None = None) -> None:
    from nlsid.analysis.levels import analyse_runs, recording_runs
    from nlsid.io.recording import open_recording

    with open_recording(path) as recording:
        pairs = recording_runs(recording, str(path))
        analyse_runs(pairs if runs is None else islice(pairs, runs))


def timed(function, *args) -> float:
    start = time.perf_counter()
    function(*args)
    return time.perf_counter() - start


def peak_memory_mb(path: Path, runs: int) -> float:
    """ru_maxrss of a fresh interpreter that analyses the first ``runs`` runs."""
    code = (f"import resource, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bla; "
            f"bla.analyse(__import__('pathlib').Path({str(path)!r}), {runs}); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=float, default=1e8)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--period", type=int, default=8192)
    parser.add_argument("--dir", default=tempfile.gettempdir())
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.dir) as folder:
        path = Path(folder) / "bench.h5"
        start = time.perf_counter()
        make_recording(path, int(args.samples), args.runs, args.period)
        write_s = time.perf_counter() - start
        samples = read_and_fft(path)  # warm-up: the file is now in the page cache
        analyse(path)
        limit_s = min(timed(read_and_fft, path) for _ in range(2))
        bla_s = min(timed(analyse, path) for _ in range(2))
        quarter = max(args.runs // 4, 1)
        result = {
            "samples": samples,
            "runs": args.runs,
            "period": args.period,
            "file_mb": round(os.path.getsize(path) / 2**20, 1),
            "write_s": round(write_s, 2),
            "limit_read_fft_s": round(limit_s, 3),
            "bla_s": round(bla_s, 3),
            "limit_samples_per_s": round(samples / limit_s),
            "bla_samples_per_s": round(samples / bla_s),
            "bla_fraction_of_limit": round(limit_s / bla_s, 3),
            f"peak_rss_mb_{quarter}_runs": round(peak_memory_mb(path, quarter), 1),
            f"peak_rss_mb_{args.runs}_runs": round(peak_memory_mb(path, args.runs), 1),
            "this_process_peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
