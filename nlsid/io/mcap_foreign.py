"""Read a foreign MCAP file (JSON topics, ROS 2 topics) as one arbitrary run.

A mapping names where each signal lives: ``{"u": "/cmd:effort", "y": "/joint:state.position"}``,
and each further measured channel (key ``channels.NAME``, e.g. ``{"channels.d": "/rig:force"}``),
a topic and a dotted path into each decoded message (a JSON object or a ROS 2 message,
:mod:`nlsid.io.mcap_messages`); a path element that is a whole number indexes a list
(``/joint_states:position.0``, joint 0). A message holds one sample (a number) or several (a list
of numbers) taken at its log time, then at the sample interval. The
timestamps must be uniformly sampled (:func:`nlsid.io.timestamps.uniform_sampling`), the rate
``fs`` comes from them, and all signals must be sampled at the same instants. Nothing is known of
the excitation, so the run is of kind ``"arbitrary"`` (no period, no excited lines).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.reader import SeekingReader

from nlsid.errors import InputError
from nlsid.io.mcap_file import channels_and_schemas, checked
from nlsid.io.mcap_messages import READABLE, decoder_for, message_fields, shown, unreadable
from nlsid.io.run import CHANNEL_KEY, SIGNALS, Run, check_channel_name, make_run
from nlsid.io.timestamps import check_aligned, uniform_sampling


def parse_source(signal: str, source: str) -> tuple[str, list[str]]:
    """Split ``/topic:field.sub`` into the topic and the field path ``["field", "sub"]``."""
    topic, sep, field = source.rpartition(":")
    path = field.split(".")
    if not sep or not topic or not all(path):
        raise InputError(f"--map {signal}", f"expected /topic:field (field may be a dotted path a.b, with list indices a.0), got {source!r}")
    return topic, path


def _lookup(obj: Any, path: list[str], where: str) -> Any:
    """Follow a dotted field path into a decoded message; name the fields (or list length) if absent."""
    for depth, key in enumerate(path):
        inside = ".".join(path[:depth])
        if isinstance(obj, (list, bytes)):  # ROS 2 uint8[] and byte[] arrays decode to bytes
            if not (key.isascii() and key.isdigit() and int(key) < len(obj)):
                prefix = f"{inside}." if inside else ""
                span = f"indexed {prefix}0 to {prefix}{len(obj) - 1}" if obj else "empty"
                raise InputError(where, f"field {'.'.join(path)!r} not found: {inside or 'the message'} is a list of {len(obj)} ({span})")
            obj = obj[int(key)]
            continue
        fields = message_fields(obj)
        if fields is None:
            raise InputError(where, f"field {'.'.join(path)!r} not found: {inside or 'the message'} is a {type(obj).__name__}, not an object")
        if key not in fields:
            at = f"in {inside}" if depth else "at the top level"
            raise InputError(where, f"field {'.'.join(path)!r} not found: fields {at} are {', '.join(sorted(fields)) or '(none)'}")
        obj = fields[key]
    return obj


def _samples(value: Any, where: str) -> list[float]:
    """One number, or a non-empty list of numbers (ROS 2 ``uint8[]`` arrays come as bytes), as a list of samples."""
    items = list(value) if isinstance(value, (list, bytes)) else [value]
    if not items or not all(type(v) in (int, float) for v in items):
        raise InputError(where, f"expected a number or a non-empty list of numbers, got {shown(value)}")
    return items


class _Collected:
    """The samples of one mapped signal: message log times, samples per message, values."""

    def __init__(self) -> None:
        self.times: list[int] = []
        self.counts: list[int] = []
        self.values: list[float] = []

    def add(self, log_time: int, samples: list[float]) -> None:
        self.times.append(log_time)
        self.counts.append(len(samples))
        self.values.extend(samples)

    def in_time_order(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times, counts and samples with the messages stably sorted by log time.

        Messages are read in file order (the reader's own log-time ordering costs half the read
        time of one-sample messages); loggers mostly write in time order, so this rarely moves any.
        """
        times, counts = np.array(self.times, dtype=np.int64), np.array(self.counts, dtype=np.int64)
        values = np.asarray(self.values, dtype=np.float64)
        if np.all(np.diff(times) >= 0):
            return times, counts, values
        order = np.argsort(times, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        message_of_sample = np.repeat(np.arange(times.size), counts)
        return times[order], counts[order], values[np.lexsort((np.arange(values.size), rank[message_of_sample]))]


def unmapped_output() -> InputError:
    """The error of reading a foreign file without y where a measured output is required."""
    return InputError("--map", "map the measured output too: --map y=/topic:field")


def read_foreign_run(
    path: Path, handle: BinaryIO, reader: SeekingReader, mapping: dict[str, str], require_y: bool
) -> tuple[Run, dict]:
    """Read the mapped signals and channels of a foreign MCAP file into one ``"arbitrary"`` run.

    Returns the run (named after the file) and a provenance record naming the source and mapping.
    """
    unknown = sorted(k for k in mapping if k not in SIGNALS and not k.startswith(CHANNEL_KEY))
    if unknown:
        raise InputError("--map", f"signals are u, y and r, got {', '.join(unknown)} "
                                  f"(map a further measured channel NAME as {CHANNEL_KEY}NAME)")
    for key in mapping:
        if key.startswith(CHANNEL_KEY):
            check_channel_name(key[len(CHANNEL_KEY):], f"--map {key}")
    if "u" not in mapping:
        raise InputError("--map", "map the input too: --map u=/topic:field")
    if require_y and "y" not in mapping:
        raise unmapped_output()
    sources = {name: parse_source(name, source) for name, source in mapping.items()}
    channels, schemas = channels_and_schemas(handle, reader, str(path))
    for name, (topic, _) in sources.items():
        channel = channels.get(topic)
        if channel is None:
            raise InputError(f"{path}: --map {name}", f"no topic {topic!r}; topics in the file: {', '.join(sorted(channels)) or '(none)'}")
        reason = unreadable(channel, schemas)
        if reason is not None:
            readable = sorted(t for t, c in channels.items() if unreadable(c, schemas) is None)
            raise InputError(f"{path}:{topic}", f"{reason}; --map reads {READABLE} (readable topics here: {', '.join(readable) or 'none'})")
    collected = {name: _Collected() for name in sources}
    topics = sorted({topic for topic, _ in sources.values()})
    decoders = {topic: decoder_for(channels[topic], schemas, f"{path}:{topic}") for topic in topics}
    for _, channel, message in checked(reader.iter_messages(topics=topics, log_time_order=False), str(path)):
        where = f"{path}:{channel.topic} message at log_time {message.log_time} ns"
        obj = decoders[channel.topic](message.data, where)
        for name, (topic, field) in sources.items():
            if topic == channel.topic:
                collected[name].add(message.log_time, _samples(_lookup(obj, field, where), f"{where}: {'.'.join(field)}"))
    sampling, signals = {}, {}
    for name, data in collected.items():
        where = f"{path}:{mapping[name]}"
        if not data.times:
            raise InputError(where, "topic holds no messages")
        times, counts, signals[name] = data.in_time_order()
        sampling[name] = uniform_sampling(times, counts, where)
    for name in sampling:
        if name != "u":
            check_aligned(sampling["u"], sampling[name], ("u", name), f"{path}: --map {mapping['u']} and {mapping[name]}")
    measured = {name[len(CHANNEL_KEY):]: signals.pop(name) for name in list(signals) if name.startswith(CHANNEL_KEY)}
    run = make_run(path.stem, {"fs": sampling["u"].fs, "kind": "arbitrary"}, signals, str(path), require_y,
                   channels=measured)
    header = reader.get_header()
    provenance = {
        "source": str(path),
        "mapping": dict(mapping),
        "start_time_ns": sampling["u"].t0_ns,
        "mcap_library": header.library,
        "mcap_profile": header.profile,
    }
    return run, provenance
