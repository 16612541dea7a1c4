"""The recording format in MCAP (``docs/formats.md``): the runs of an HDF5 recording, losslessly.

Layout (every message JSON-encoded, every channel with a JSON schema, zstd-compressed chunks)::

    metadata "nlsid"   nlsid_format ("recording"/"excitation"), nlsid_format_version ("2"), provenance (JSON)
    /nlsid/run         one message per run: the HDF5 run attributes (fs, kind, period, ...,
                       excited_bins as integers, params as an object) plus run, n_samples, signals,
                       channels (version 2; absent if none), units
    /nlsid/u, /y, /r   sample blocks {"run", "start", "data"}: up to BLOCK_SAMPLES samples from
                       sample index ``start``, ``data`` = base64 of little-endian IEEE 754 float64
    /nlsid/channel/<name>  sample blocks of a further measured channel (version 2)

The run message's ``inputs`` and ``outputs`` (version 3) name the inputs and outputs of a run with
several, as the HDF5 run attributes do; a file is version 3 only when some run has them.
Version 1 files (no channels) are read as before: a ``channels`` field of their run messages is
ignored, as are ``inputs`` and ``outputs`` before version 3. The run schema stored in the file is
that of version 2, whose properties are not exclusive: its text (and so a file of runs with one
input and one output) is unchanged by version 3.

Time line: log times are nanoseconds on a synthetic clock; they do not say when the data were
measured (the recording format does not carry that). The first run starts at ``t0 = 0``; each
further run starts at the first whole second at least 1 s after the previous run ends, so runs
occupy disjoint time windows. A block's log time is ``t0 + round(start * 1e9 / fs)``, the time of
its first sample; the run message has log time ``t0``. A reader loads one run by reading only the
chunks of its time window, and checks the ``run`` field of every block.

A truncated or damaged file is refused (InputError), never read in part: the writer is atomic, so
a cut file means a damaged copy, and a run read in part would pass for a shorter experiment.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np
from mcap.writer import CompressionType, Writer

from nlsid import __version__
from nlsid.errors import InputError
from nlsid.io.atomic import atomic_path
from nlsid.io.mcap_file import channels_by_topic, checked, open_mcap
from nlsid.io.mcap_foreign import read_foreign_run, unmapped_output
from nlsid.io.reader import RecordingReader
from nlsid.io.run import SIGNALS, VERSION_3_ATTRS, Run, check_channel_name, make_run

FORMAT_VERSION = 2
MIMO_FORMAT_VERSION = 3  # written when some run has several inputs or outputs
READ_VERSIONS = ("1", "2", "3")  # version 2 added channels, version 3 the run fields inputs, outputs
FORMATS = ("recording", "excitation")
METADATA_NAME = "nlsid"
RUN_TOPIC = "/nlsid/run"
SIGNAL_TOPICS = {name: f"/nlsid/{name}" for name in SIGNALS}
CHANNEL_TOPIC = "/nlsid/channel/"  # + channel name
BLOCK_SAMPLES = 4096  # 32 KiB of float64 per message: about 0.07 s per 1e6 samples to write or read
SECOND_NS = 1_000_000_000
SAMPLE_DTYPE = np.dtype("<f8")

RUN_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "nlsid.Run",
    "description": "One run of an nlsid recording: the attributes of /runs/<run> in the HDF5 form (docs/formats.md).",
    "type": "object",
    "required": ["run", "fs", "kind", "transient_periods", "n_samples", "signals"],
    "properties": {
        "run": {"type": "string", "description": "run id; sample blocks name it"},
        "fs": {"type": "number", "exclusiveMinimum": 0, "description": "sample rate, Hz"},
        "kind": {"enum": ["multisine", "sine", "arbitrary"]},
        "period": {"type": "integer", "minimum": 2, "description": "samples per period N (not for arbitrary)"},
        "transient_periods": {"type": "integer", "minimum": 0},
        "realization": {"type": "integer"},
        "level": {"type": "number"},
        "frequency": {"type": "number", "description": "sine frequency, Hz"},
        "excited_bins": {"type": "array", "items": {"type": "integer", "minimum": 1},
                         "description": "excited DFT bins k of one period (frequency k fs / N)"},
        "params": {"type": "object", "description": "experiment parameters, e.g. {\"K_fc\": 0.12}"},
        "n_samples": {"type": "integer", "minimum": 1},
        "signals": {"type": "array", "items": {"enum": ["u", "y", "r"]}, "description": "signals with sample blocks"},
        "channels": {"type": "array", "items": {"type": "string", "pattern": "^[A-Za-z_][A-Za-z0-9_]*$"},
                     "description": "further measured channels, with sample blocks on /nlsid/channel/<name>"},
        "units": {"type": "object", "additionalProperties": {"type": "string"}},
    },
}
BLOCK_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "nlsid.SampleBlock",
    "description": "Consecutive samples of one signal of one run; log time = time of the first sample.",
    "type": "object",
    "required": ["run", "start", "data"],
    "properties": {
        "run": {"type": "string"},
        "start": {"type": "integer", "minimum": 0, "description": "index of the first sample in the run"},
        "data": {"type": "string", "contentEncoding": "base64", "description": "little-endian IEEE 754 float64 samples"},
    },
}
_OWN_KEYS = ("run", "n_samples", "signals", "channels", "units")


def _excitation_error(path: Path) -> InputError:
    return InputError(str(path), "is an excitation file without measured output y; run `nlsid simulate` or measure first")


class MCAPRecording(RecordingReader):
    """An open MCAP recording whose runs are read one at a time (same interface as HDF5Recording).

    Without ``mapping`` the file must be in the nlsid layout above. With ``mapping`` (signal name
    to ``/topic:field``) it is a foreign file read as one arbitrary run
    (:func:`nlsid.io.mcap_foreign.read_foreign_run`). Use as a context manager.
    """

    def __init__(self, path: str | os.PathLike, require_y: bool = True, mapping: dict[str, str] | None = None):
        self.path = Path(path)
        self.require_y = require_y
        self._handle, self._reader = open_mcap(self.path)
        try:
            if mapping:
                run, self.provenance = read_foreign_run(self.path, self._handle, self._reader, mapping, require_y)
                self.format = "recording" if run.y is not None else "excitation"
                self._foreign = {run.run_id: run}
                self.run_ids = [run.run_id]
            else:
                self._foreign = {}
                self.format, self.version, self.provenance = self._check_metadata()
                self._runs = self._list_runs()
                self.run_ids = sorted(self._runs)
        except BaseException:
            self._handle.close()
            raise

    def _check_metadata(self) -> tuple[str, int, dict]:
        records = [m for m in checked(self._reader.iter_metadata(), str(self.path)) if m.name == METADATA_NAME]
        if len(records) != 1:
            topics = ", ".join(sorted(channels_by_topic(self._handle, self._reader, str(self.path)))) or "(none)"
            raise InputError(
                str(self.path),
                f"not an nlsid recording ({len(records)} '{METADATA_NAME}' metadata records, expected 1); "
                f"read a foreign MCAP file with --map u=/topic:field --map y=/topic:field (topics: {topics})",
            )
        meta = records[0].metadata
        where = f"{self.path}:metadata {METADATA_NAME}"
        fmt = meta.get("nlsid_format")
        if fmt not in FORMATS:
            raise InputError(where, f"nlsid_format must be 'recording' or 'excitation', got {fmt!r}")
        version = meta.get("nlsid_format_version")
        if version not in READ_VERSIONS:
            expected = " or ".join(f"'{v}'" for v in READ_VERSIONS)
            raise InputError(where, f"nlsid_format_version must be {expected}, got {version!r} (a file of a newer nlsid?)")
        if self.require_y and fmt == "excitation":
            raise _excitation_error(self.path)
        return fmt, int(version), _json_object(meta.get("provenance", "{}"), f"{where}.provenance")

    def _list_runs(self) -> dict[str, tuple[dict, int, int | None]]:
        """Each run's message and time window ``[start, end)`` (``end`` None for the last run)."""
        topics = channels_by_topic(self._handle, self._reader, str(self.path))
        if RUN_TOPIC not in topics:
            raise InputError(str(self.path), f"missing topic {RUN_TOPIC}; topics in the file: {', '.join(sorted(topics)) or '(none)'}")
        found: list[tuple[int, dict]] = []
        for _, _, message in checked(self._reader.iter_messages(topics=[RUN_TOPIC]), str(self.path)):
            where = f"{self.path}:{RUN_TOPIC} message at log_time {message.log_time} ns"
            meta = _json_object(message.data, where)
            run_id = meta.get("run")
            if not isinstance(run_id, str) or not run_id:
                raise InputError(where, f"field 'run' must be a non-empty string, got {run_id!r}")
            found.append((message.log_time, meta))
        if not found:
            raise InputError(f"{self.path}:{RUN_TOPIC}", "holds no runs")
        runs: dict[str, tuple[dict, int, int | None]] = {}
        for i, (start, meta) in enumerate(found):
            if meta["run"] in runs:
                raise InputError(f"{self.path}:{RUN_TOPIC}", f"run {meta['run']!r} is described twice")
            end = found[i + 1][0] if i + 1 < len(found) else None
            runs[meta["run"]] = (meta, start, end)
        return runs

    def output_error(self) -> InputError | None:
        if self.format != "excitation":
            return None
        return unmapped_output() if self._foreign else _excitation_error(self.path)

    def run_where(self, run_id: str) -> str:
        return str(self.path) if self._foreign else f"{self.path}:{RUN_TOPIC}[{run_id}]"

    def load(self, run_id: str) -> Run:
        """Read and validate one run."""
        if self._foreign:
            return self._foreign[run_id]
        meta, start, end = self._runs[run_id]
        where = self.run_where(run_id)
        n_samples, names, channel_names, units = _own_fields(meta, where, self.version)
        topics = {name: SIGNAL_TOPICS[name] for name in names} | {name: CHANNEL_TOPIC + name for name in channel_names}
        samples = self._read_signals(run_id, topics, n_samples, start, end)
        attrs = {k: v for k, v in meta.items() if k not in _OWN_KEYS}
        if self.version < MIMO_FORMAT_VERSION:
            attrs = {k: v for k, v in attrs.items() if k not in VERSION_3_ATTRS}
        if "params" in attrs and not isinstance(attrs["params"], str):
            attrs["params"] = json.dumps(attrs["params"])
        signals = {name: samples[name] for name in names}
        channels = {name: samples[name] for name in channel_names}
        return make_run(run_id, attrs, signals, where, self.require_y, units, channels)

    def _read_signals(self, run_id: str, topics: dict[str, str], n_samples: int, start: int, end: int | None) -> dict[str, np.ndarray]:
        """The samples of each signal or channel (name -> its topic) of one run."""
        blocks: dict[str, list[tuple[int, bytes]]] = {name: [] for name in topics}
        topic_names = {topic: name for name, topic in topics.items()}
        messages = self._reader.iter_messages(
            topics=sorted(topic_names), starting_at=start, ending_before=end, log_time_order=False)
        for _, channel, message in checked(messages, str(self.path)):
            where = f"{self.path}:{channel.topic} message at log_time {message.log_time} ns"
            block = _json_object(message.data, where)
            if block.get("run") != run_id:
                continue
            first = block.get("start")
            if isinstance(first, bool) or not isinstance(first, int) or first < 0:
                raise InputError(where, f"field 'start' must be an integer >= 0, got {first!r}")
            blocks[topic_names[channel.topic]].append((first, _decode_samples(block.get("data"), where)))
        return {name: _assemble(parts, n_samples, f"{self.path}:{topics[name]}[{run_id}]") for name, parts in blocks.items()}

    def close(self) -> None:
        self._handle.close()


def _json_object(data: bytes | str, where: str) -> dict:
    try:
        obj = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(where, f"not JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise InputError(where, f"expected a JSON object, got {type(obj).__name__}")
    return obj


def _own_fields(meta: dict, where: str, version: int) -> tuple[int, list[str], list[str], dict[str, str]]:
    """The run message's fields beyond the HDF5 attributes: n_samples, signals, channels (from
    version 2 on; [] before), units."""
    n_samples = meta.get("n_samples")
    if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < 1:
        raise InputError(f"{where}.n_samples", f"expected an integer >= 1, got {n_samples!r}")
    names = meta.get("signals")
    if not isinstance(names, list) or "u" not in names or not set(names) <= set(SIGNALS) or len(set(names)) != len(names):
        raise InputError(f"{where}.signals", f"expected a list of distinct names from u, y, r including u, got {names!r}")
    channels = meta.get("channels", []) if version >= 2 else []
    if not isinstance(channels, list) or len(set(map(str, channels))) != len(channels):
        raise InputError(f"{where}.channels", f"expected a list of distinct channel names, got {channels!r}")
    for name in channels:
        check_channel_name(name, f"{where}/channels/{name}")
    units = meta.get("units", {})
    if not isinstance(units, dict) or not all(isinstance(v, str) for v in units.values()):
        raise InputError(f"{where}.units", f"expected an object of unit strings, got {units!r}")
    return n_samples, names, channels, units


def _decode_samples(data: Any, where: str) -> bytes:
    if not isinstance(data, str):
        raise InputError(where, "field 'data' must be a base64 string")
    try:
        raw = base64.b64decode(data, validate=True)
    except binascii.Error as exc:
        raise InputError(where, f"field 'data' is not base64 ({exc})") from None
    if len(raw) % SAMPLE_DTYPE.itemsize:
        raise InputError(where, f"field 'data' holds {len(raw)} bytes, not a whole number of float64 samples")
    return raw


def _assemble(parts: list[tuple[int, bytes]], n_samples: int, where: str) -> np.ndarray:
    """Join blocks into one array; they must cover samples 0..n_samples-1 once each, in order."""
    parts.sort(key=lambda part: part[0])
    expected = 0
    for first, raw in parts:
        if first != expected:
            problem = "a gap" if first > expected else "an overlap"
            raise InputError(where, f"blocks leave {problem} at sample {expected} (next block starts at {first})")
        expected += len(raw) // SAMPLE_DTYPE.itemsize
    if expected != n_samples:
        raise InputError(where, f"blocks hold {expected} samples, the run message says n_samples = {n_samples}")
    return np.frombuffer(b"".join(raw for _, raw in parts), dtype=SAMPLE_DTYPE).astype(np.float64)


def write_mcap_recording(
    path: str | os.PathLike,
    runs: Iterable[Run],
    provenance: dict | None = None,
    force: bool = False,
) -> Path:
    """Write runs in the MCAP layout above, atomically, one run at a time (runs may be a generator).

    The file is an ``"excitation"`` when some run lacks ``y`` and a ``"recording"`` otherwise,
    of format version 3 when some run has several inputs or outputs and version 2 otherwise.
    """
    with atomic_path(path, force) as tmp, open(tmp, "wb") as handle:
        writer = Writer(handle, compression=CompressionType.ZSTD)
        writer.start(profile="", library=f"nlsid {__version__}")
        channels = _Channels(writer)
        t0, complete, mimo, seen = 0, True, False, set()
        for run in runs:
            if run.run_id in seen:
                raise InputError(str(path), f"run id {run.run_id!r} given twice")
            seen.add(run.run_id)
            _write_run(writer, channels, run, t0)
            complete = complete and run.y is not None
            mimo = mimo or run.needs_version_3
            t0 = _next_start(t0, run)
        version = MIMO_FORMAT_VERSION if mimo else FORMAT_VERSION
        meta = {"nlsid_format": "recording" if complete else "excitation", "nlsid_format_version": str(version)}
        if provenance is not None:
            meta["provenance"] = json.dumps(provenance, sort_keys=True)
        writer.add_metadata(METADATA_NAME, meta)
        writer.finish()
    return Path(path)


class _Channels:
    """Channel ids of the nlsid topics, registered on first use (a file without r has no /nlsid/r)."""

    def __init__(self, writer: Writer):
        self._writer = writer
        self._schemas: dict[str, int] = {}
        self._ids: dict[str, int] = {}

    def __getitem__(self, topic: str) -> int:
        if topic not in self._ids:
            schema = RUN_SCHEMA if topic == RUN_TOPIC else BLOCK_SCHEMA
            if schema["title"] not in self._schemas:
                self._schemas[schema["title"]] = self._writer.register_schema(
                    schema["title"], "jsonschema", json.dumps(schema).encode())
            self._ids[topic] = self._writer.register_channel(topic, "json", self._schemas[schema["title"]])
        return self._ids[topic]


def run_message(run: Run) -> dict[str, Any]:
    """The /nlsid/run message of a run: its HDF5 attributes as JSON values, plus the MCAP fields."""
    meta: dict[str, Any] = {"run": run.run_id, **run.attrs()}
    if run.excited_bins is not None:
        meta["excited_bins"] = [int(k) for k in run.excited_bins]
    if run.params:
        meta["params"] = run.params
    meta["n_samples"] = run.n_samples
    meta["signals"] = [name for name in SIGNALS if getattr(run, name) is not None]
    if run.channels:
        meta["channels"] = list(run.channels)
    if run.units:
        meta["units"] = dict(run.units)
    return meta


def _write_run(writer: Writer, channels: _Channels, run: Run, t0: int) -> None:
    writer.add_message(channels[RUN_TOPIC], t0, json.dumps(run_message(run)).encode(), t0)
    signals = {SIGNAL_TOPICS[name]: np.asarray(getattr(run, name), dtype=SAMPLE_DTYPE)
               for name in SIGNALS if getattr(run, name) is not None}
    signals |= {CHANNEL_TOPIC + name: np.asarray(x, dtype=SAMPLE_DTYPE) for name, x in run.channels.items()}
    for first in range(0, run.n_samples, BLOCK_SAMPLES):
        log_time = t0 + round(first * SECOND_NS / run.fs)
        for topic, samples in signals.items():
            data = base64.b64encode(samples[first:first + BLOCK_SAMPLES].tobytes()).decode("ascii")
            block = json.dumps({"run": run.run_id, "start": first, "data": data}).encode()
            writer.add_message(channels[topic], log_time, block, log_time)


def _next_start(t0: int, run: Run) -> int:
    """Start of the next run: the first whole second at least 1 s after this run's last sample time."""
    end = t0 + math.ceil(run.n_samples * SECOND_NS / run.fs)
    return -(-(end + SECOND_NS) // SECOND_NS) * SECOND_NS
