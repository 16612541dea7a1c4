"""Test material: a foreign MCAP log as a logger writes it (JSON messages on two topics, one per sample)."""

from __future__ import annotations

import json

import numpy as np
from mcap.writer import Writer


def write_json_mcap(path, fs: float, u: np.ndarray, y: np.ndarray) -> None:
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start(profile="", library="test-logger")
        schema = writer.register_schema("Sample", "jsonschema", b'{"type": "object"}')
        cmd, joint = (writer.register_channel(t, "json", schema) for t in ("/cmd", "/joint"))
        for k in range(u.size):
            t = 1_000_000_000 + round(k * 1e9 / fs)
            writer.add_message(cmd, t, json.dumps({"effort": u[k]}).encode(), t)
            writer.add_message(joint, t, json.dumps({"state": {"position": y[k]}}).encode(), t)
        writer.finish()
