"""CSV import speed: nlsid's reader of a table of numbers against numpy.loadtxt on the same file.

Usage: ``python benchmarks/csv_import.py [ROWS] [--repeats R]`` (default 1,000,000 rows, 3 repeats).
Writes a CSV ``t,u,y`` (time in seconds, two noise signals, numbers as Python's shortest round-trip
text) and prints JSON: the best of R wall-clock and CPU seconds of

- ``nlsid``: :func:`nlsid.importers.convert.read_source`, what ``nlsid import`` reads a file
  with (the table found, the columns chosen, the time vector scaled), its fast reading;
- ``loadtxt``: ``numpy.loadtxt(path, delimiter=",", skiprows=1)``;
- ``careful``: nlsid's cell-by-cell reading of the same file (the fast one made to decline), run once;

the ratios nlsid/loadtxt and careful/nlsid, and whether nlsid's u, y and time are identical, bit
for bit, to loadtxt's columns and to Python's ``float`` of the text written.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from nlsid.importers import csv_file
from nlsid.importers.convert import ImportOptions, read_source


def _timed(action, repeats: int) -> tuple[float, float, object]:
    """Best wall and CPU seconds of ``repeats`` calls, and the last result."""
    walls, cpus, result = [], [], None
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = action()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus), result


def write_table(path: Path, rows: int) -> np.ndarray:
    """The CSV of ``rows`` rows t, u, y; returns the numbers as float() reads the text written."""
    rng = np.random.default_rng(0)
    t = np.arange(rows) / 1000.0
    u, y = rng.standard_normal(rows), rng.standard_normal(rows) * 1e-3
    lines = [f"{a!r},{b!r},{c!r}" for a, b, c in zip(t.tolist(), u.tolist(), y.tolist())]
    path.write_text("t,u,y\n" + "\n".join(lines) + "\n")
    return np.array([t, u, y]).T  # repr round-trips: float(repr(x)) == x


def main(rows: int, repeats: int) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "table.csv"
        truth = write_table(path, rows)
        size_mb = path.stat().st_size / 1e6
        options = ImportOptions(names={})
        nlsid_s, nlsid_cpu, source = _timed(lambda: read_source(path, options), repeats)
        loadtxt_s, loadtxt_cpu, matrix = _timed(lambda: np.loadtxt(path, delimiter=",", skiprows=1), repeats)
        original = csv_file._numeric_table
        csv_file._numeric_table = lambda *args: None
        try:
            careful_s, careful_cpu, careful = _timed(lambda: read_source(path, options), 1)
        finally:
            csv_file._numeric_table = original
    got = np.column_stack([source.time, source.arrays["u"], source.arrays["y"]])
    return {
        "rows": rows, "columns": 3, "file_MB": round(size_mb, 1),
        "repeats": repeats,
        "nlsid_s": round(nlsid_s, 3), "nlsid_cpu_s": round(nlsid_cpu, 3),
        "loadtxt_s": round(loadtxt_s, 3), "loadtxt_cpu_s": round(loadtxt_cpu, 3),
        "careful_s": round(careful_s, 3), "careful_cpu_s": round(careful_cpu, 3),
        "nlsid_over_loadtxt": round(nlsid_s / loadtxt_s, 2),
        "nlsid_over_loadtxt_cpu": round(nlsid_cpu / loadtxt_cpu, 2),
        "careful_over_nlsid": round(careful_s / nlsid_s, 1),
        "identical_to_loadtxt": bool(np.array_equal(got, matrix)),
        "identical_to_float_of_text": bool(np.array_equal(got, truth)),
        "careful_identical": bool(np.array_equal(careful.arrays["u"], source.arrays["u"])
                                  and np.array_equal(careful.arrays["y"], source.arrays["y"])
                                  and np.array_equal(careful.time, source.time)),
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rows", nargs="?", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(json.dumps(main(args.rows, args.repeats), indent=2))
