"""Write and read throughput of MCAP recordings: nlsid sample blocks vs one JSON message per sample.

Usage: ``python benchmarks/mcap_io.py [N_SAMPLES]`` (default 1e6). Prints JSON: seconds, MB/s of
float64 payload and file size for each layout, and the block/per-sample speed ratios. The
per-sample file is what a generic logger writes (``{"u": x}`` per message); it is read through
the foreign-file path (``--map u=/u:u``), so both reads go through nlsid's validation.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from nlsid.io.mcap_recording import BLOCK_SAMPLES
from nlsid.io.recording import read_runs, write_recording
from nlsid.io.run import make_run


def _timed(action) -> float:
    start = time.perf_counter()
    action()
    return time.perf_counter() - start


def _write_per_sample(path: Path, u: np.ndarray, fs: float) -> None:
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        channel = writer.register_channel("/u", "json", 0)
        for k, value in enumerate(u.tolist()):
            log_time = round(k * 1e9 / fs)
            writer.add_message(channel, log_time, json.dumps({"u": value}).encode(), log_time)
        writer.finish()


def main(n: int) -> dict:
    fs = 10_000.0
    u = np.random.default_rng(0).standard_normal(n)
    run = make_run("bench", {"fs": fs, "kind": "arbitrary"}, {"u": u}, "benchmark", require_y=False)
    payload_mb = u.nbytes / 1e6
    out: dict = {"samples": n, "block_samples": BLOCK_SAMPLES}
    with tempfile.TemporaryDirectory() as folder:
        blocks, single = Path(folder) / "blocks.mcap", Path(folder) / "per_sample.mcap"
        layouts = {
            "blocks": (lambda: write_recording(blocks, [run]), lambda: read_runs(blocks, require_y=False), blocks),
            "per_sample": (lambda: _write_per_sample(single, u, fs),
                           lambda: read_runs(single, require_y=False, mapping={"u": "/u:u"}), single),
        }
        for name, (write, read, path) in layouts.items():
            t_write, t_read = _timed(write), _timed(read)
            out[name] = {"write_s": round(t_write, 3), "read_s": round(t_read, 3),
                         "write_MB_per_s": round(payload_mb / t_write, 1), "read_MB_per_s": round(payload_mb / t_read, 1),
                         "file_MB": round(path.stat().st_size / 1e6, 2)}
    out["write_speedup"] = round(out["per_sample"]["write_s"] / out["blocks"]["write_s"], 1)
    out["read_speedup"] = round(out["per_sample"]["read_s"] / out["blocks"]["read_s"], 1)
    return out


if __name__ == "__main__":
    print(json.dumps(main(int(float(sys.argv[1])) if len(sys.argv) > 1 else 1_000_000), indent=2))
