"""MCAP container: lossless round trip with HDF5, the documented layout, foreign JSON topics, bad files.

Every expected number is either the input the test wrote itself (round trips must return it bit
for bit), a time computed by hand from the documented layout, or a bound derived in a comment.
"""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import IndexType, Writer

from nlsid.errors import InputError
from nlsid.io.mcap_recording import BLOCK_SAMPLES, RUN_SCHEMA, run_message
from nlsid.io.recording import open_recording, read_runs, write_recording
from nlsid.io.run import make_run
from nlsid.io.timestamps import uniform_sampling

FS = 1000.0
PERIOD = 256


def _special_floats() -> np.ndarray:
    """Values a decimal text format would lose or alter: -0.0, subnormals, extremes, pi's last bit."""
    return np.array([-0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, np.pi, np.nextafter(np.pi, 4)])


def _runs(with_y: bool = True) -> list:
    """Three runs covering every attribute: multisine (bins, params, units, r), sine, arbitrary."""
    rng = np.random.default_rng(7)
    n_ms = PERIOD * 3
    # 2 blocks + 17 samples: a partial last block.
    n_arb = 2 * BLOCK_SAMPLES + 17
    u_arb = rng.standard_normal(n_arb)
    u_arb[:6] = _special_floats()

    def signals(n, r=False):
        out = {"u": rng.standard_normal(n)}
        if with_y:
            out["y"] = rng.standard_normal(n)
        if r:
            out["r"] = rng.standard_normal(n)
        return out

    return [
        make_run("ms_00", {"fs": FS, "kind": "multisine", "period": PERIOD, "transient_periods": 1,
                           "excited_bins": np.array([1, 3, 7, 9, 13]), "realization": 4, "level": 0.25,
                           "params": json.dumps({"K_fc": 0.12, "note": "Ω", "nested": {"a": [1, 2.5]}})},
                 signals(n_ms, r=True), "test", with_y, {"u": "N", "y": "m"}),
        # fs = 10 kHz / 3 needs all 17 significant digits: a text format rounding it would show.
        make_run("sine_03", {"fs": 10_000 / 3, "kind": "sine", "period": 100, "frequency": 30.0, "level": 1e-3},
                 signals(400), "test", with_y),
        make_run("zz_arbitrary", {"fs": 3000.0, "kind": "arbitrary"},
                 {**signals(n_arb), "u": u_arb}, "test", with_y),
    ]


def _assert_same_run(a, b) -> None:
    assert a.run_id == b.run_id
    for name in ("u", "y", "r"):
        x, z = getattr(a, name), getattr(b, name)
        assert (x is None) == (z is None), name
        if x is not None:
            # Bit-exact: compare the IEEE 754 bytes, which also tells -0.0 from 0.0.
            assert x.dtype == z.dtype == np.float64
            assert x.tobytes() == z.tobytes(), name
    attrs_a, attrs_b = a.attrs(), b.attrs()
    assert attrs_a.keys() == attrs_b.keys()
    for key in attrs_a:
        if key == "excited_bins":
            assert attrs_b[key].dtype == np.int64 and np.array_equal(attrs_a[key], attrs_b[key])
        else:
            assert attrs_a[key] == attrs_b[key] and type(attrs_a[key]) is type(attrs_b[key]), key
    assert a.params == b.params and a.units == b.units


def test_round_trip_hdf5_mcap_hdf5_is_lossless(tmp_path):
    runs = _runs()
    prov = {"tool": "nlsid", "command": "test", "inputs": {"a.yaml": "00ff"}}
    write_recording(tmp_path / "a.h5", runs, provenance=prov)
    from_h5 = read_runs(tmp_path / "a.h5")
    write_recording(tmp_path / "b.mcap", from_h5, provenance=prov)
    from_mcap = read_runs(tmp_path / "b.mcap")
    write_recording(tmp_path / "c.h5", from_mcap, provenance=prov)
    back = read_runs(tmp_path / "c.h5")
    assert [r.run_id for r in back] == ["ms_00", "sine_03", "zz_arbitrary"]
    for original, mcap_run, final in zip(runs, from_mcap, back):
        _assert_same_run(original, mcap_run)
        _assert_same_run(original, final)
    with open_recording(tmp_path / "b.mcap") as rec:
        assert rec.format == "recording" and rec.provenance == prov


def test_excitation_round_trip_and_require_y(tmp_path):
    runs = _runs(with_y=False)
    write_recording(tmp_path / "e.mcap", runs)
    with open_recording(tmp_path / "e.mcap", require_y=False) as rec:
        assert rec.format == "excitation" and rec.provenance == {}
        for original, loaded in zip(runs, rec):
            _assert_same_run(original, loaded)
    with pytest.raises(InputError, match="excitation file without measured output y"):
        read_runs(tmp_path / "e.mcap")


def test_layout_read_with_the_mcap_package_alone(tmp_path):
    """The documented layout, checked with the mcap reader only (no nlsid code on the read side)."""
    runs = _runs()
    write_recording(tmp_path / "r.mcap", runs)
    with open(tmp_path / "r.mcap", "rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        assert {c.topic for c in summary.channels.values()} == {"/nlsid/run", "/nlsid/u", "/nlsid/y", "/nlsid/r"}
        assert {c.message_encoding for c in summary.channels.values()} == {"json"}
        assert {s.encoding for s in summary.schemas.values()} == {"jsonschema"}
        assert {s.name for s in summary.schemas.values()} == {"nlsid.Run", "nlsid.SampleBlock"}
        (meta,) = list(reader.iter_metadata())
        assert meta.name == "nlsid" and meta.metadata["nlsid_format"] == "recording"
        assert meta.metadata["nlsid_format_version"] == "2"
        starts = {json.loads(m.data)["run"]: m.log_time for _, _, m in reader.iter_messages(topics=["/nlsid/run"])}
        # ms_00: 768 samples at 1 kHz end at 0.768 s -> next run at the first whole second >= 1.768 s = 2 s.
        # sine_03: 400 samples at 3333.3 Hz end at 2.12 s -> next at 4 s (first whole second >= 3.12 s).
        assert starts == {"ms_00": 0, "sine_03": 2_000_000_000, "zz_arbitrary": 4_000_000_000}
        u_blocks = [(m.log_time, json.loads(m.data)) for _, _, m in reader.iter_messages(topics=["/nlsid/u"])
                    if json.loads(m.data)["run"] == "zz_arbitrary"]
    assert [b["start"] for _, b in u_blocks] == [0, BLOCK_SAMPLES, 2 * BLOCK_SAMPLES]
    # Block log time = t0 + start / fs: 4096 / 3000 Hz = 1.365333... s -> 1_365_333_333 ns (rounded).
    assert [t for t, _ in u_blocks] == [4_000_000_000, 5_365_333_333, 6_730_666_667]
    samples = np.concatenate([np.frombuffer(base64.b64decode(b["data"]), dtype="<f8") for _, b in u_blocks])
    assert samples.tobytes() == runs[2].u.tobytes()


def test_write_refuses_existing_output_and_duplicate_ids(tmp_path):
    runs = _runs()
    target = tmp_path / "r.mcap"
    target.write_bytes(b"keep")
    with pytest.raises(InputError, match="output exists"):
        write_recording(target, runs)
    assert target.read_bytes() == b"keep"
    with pytest.raises(InputError, match="given twice"):
        write_recording(target, [runs[0], runs[0]], force=True)
    assert target.read_bytes() == b"keep" and len(list(tmp_path.iterdir())) == 1  # no temp file left


# ----------------------------------------------------------------------------------------- foreign


def _write_foreign(path, messages, schema: bool = True, summary: bool = True) -> None:
    """Write JSON messages ``(topic, log_time_ns, object)`` with the mcap Writer, as a logger would.

    ``summary=False`` writes no summary section (no index), as some streaming loggers do.
    """
    options = {} if summary else dict(index_types=IndexType.NONE, repeat_channels=False, repeat_schemas=False,
                                      use_statistics=False, use_summary_offsets=False)
    with open(path, "wb") as handle:
        writer = Writer(handle, **options)
        writer.start(profile="", library="test-logger")
        schema_id = writer.register_schema("Sample", "jsonschema", b'{"type": "object"}') if schema else 0
        channels = {}
        for topic, log_time, obj in messages:
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, "json", schema_id)
            writer.add_message(channels[topic], log_time, json.dumps(obj).encode(), log_time)
        writer.finish()


def _scalar_log(fs: float, n: int, t0: int = 1_700_000_000_000_000_000, skip=(), y_shift: int = 0):
    """u on /cmd as {"effort": x}, y on /joint as {"state": {"position": x}}, one sample per message."""
    rng = np.random.default_rng(3)
    u, y = rng.standard_normal(n), rng.standard_normal(n)
    messages = []
    for k in range(n):
        if k in skip:
            continue
        messages.append(("/cmd", t0 + round(k * 1e9 / fs), {"effort": u[k], "seq": k}))
        messages.append(("/joint", t0 + round((k + y_shift) * 1e9 / fs), {"state": {"position": y[k]}}))
    return messages, u, y


MAP = {"u": "/cmd:effort", "y": "/joint:state.position"}


def test_foreign_scalar_per_message(tmp_path):
    messages, u, y = _scalar_log(FS, 2000)
    _write_foreign(tmp_path / "log.mcap", messages)
    with open_recording(tmp_path / "log.mcap", mapping=MAP) as rec:
        assert rec.run_ids == ["log"] and rec.format == "recording"
        assert rec.provenance["start_time_ns"] == 1_700_000_000_000_000_000
        assert rec.provenance["mapping"] == MAP
        run = rec.load("log")
    # Timestamps are exact multiples of 1e6 ns: fs = 1e9 * 1999 / 1.999e9 = 1000 exactly.
    assert run.fs == 1000.0
    assert run.kind == "arbitrary" and run.period is None and run.excited_bins is None
    # JSON text of a Python float round-trips exactly (repr is the shortest exact decimal).
    assert run.u.tobytes() == u.tobytes() and run.y.tobytes() == y.tobytes()


def test_foreign_file_without_summary_section(tmp_path):
    messages, u, y = _scalar_log(FS, 300)
    _write_foreign(tmp_path / "stream.mcap", messages, summary=False)
    with open(tmp_path / "stream.mcap", "rb") as handle:
        assert make_reader(handle).get_summary() is None  # the case under test
    (run,) = read_runs(tmp_path / "stream.mcap", mapping=MAP)
    assert run.fs == 1000.0 and run.u.tobytes() == u.tobytes() and run.y.tobytes() == y.tobytes()
    with pytest.raises(InputError, match=r"no topic '/x'; topics in the file: /cmd, /joint"):
        read_runs(tmp_path / "stream.mcap", mapping={"u": "/x:effort", "y": "/joint:state.position"})


def test_foreign_rate_not_a_whole_number_of_ns(tmp_path):
    """At 3 kHz the interval 333333.33 ns is rounded to whole ns at each timestamp.

    Each end is off by at most 0.5 ns, so the span (n-1)/fs is off by at most 1 ns and the
    relative error of fs is at most 1 ns / span.
    """
    n = 3001
    messages, u, _ = _scalar_log(3000.0, n, t0=0)
    _write_foreign(tmp_path / "log.mcap", messages, schema=False)
    (run,) = read_runs(tmp_path / "log.mcap", mapping=MAP)
    span_ns = (n - 1) / 3000.0 * 1e9
    assert abs(run.fs - 3000.0) / 3000.0 <= 1.0 / span_ns
    assert run.u.tobytes() == u.tobytes()


def test_foreign_list_per_message_u_and_y_on_one_topic(tmp_path):
    fs, block, n_blocks = 500.0, 25, 40
    rng = np.random.default_rng(5)
    u, y = rng.standard_normal(block * n_blocks), rng.standard_normal(block * n_blocks)
    messages = [("/daq", round(m * block * 1e9 / fs),
                 {"ch": {"u": u[m * block:(m + 1) * block].tolist(), "y": y[m * block:(m + 1) * block].tolist()}})
                for m in range(n_blocks)]
    messages.append(("/other", 5, {"text": "ignored"}))
    _write_foreign(tmp_path / "daq.mcap", sorted(messages, key=lambda m: m[1]))
    (run,) = read_runs(tmp_path / "daq.mcap", mapping={"u": "/daq:ch.u", "y": "/daq:ch.y"})
    # Message interval 25 / 500 Hz = 50 ms exactly in ns: fs = 1e9 * 975 / 1.95e9 = 500 exactly.
    assert run.fs == 500.0 and run.n_samples == block * n_blocks
    assert run.u.tobytes() == u.tobytes() and run.y.tobytes() == y.tobytes()


def test_foreign_messages_out_of_file_order_are_sorted_by_log_time(tmp_path):
    fs, block, n_blocks = 500.0, 3, 30
    u = np.arange(block * n_blocks, dtype=float)  # sample k holds k: the order is visible
    messages = [("/daq", round(m * block * 1e9 / fs), {"u": u[m * block:(m + 1) * block].tolist()}) for m in range(n_blocks)]
    shuffled = [messages[i] for i in np.random.default_rng(2).permutation(n_blocks)]
    _write_foreign(tmp_path / "shuffled.mcap", shuffled)
    (run,) = read_runs(tmp_path / "shuffled.mcap", require_y=False, mapping={"u": "/daq:u"})
    assert run.fs == 500.0 and np.array_equal(run.u, u)


def test_foreign_dropped_message_is_reported_with_its_place(tmp_path):
    messages, _, _ = _scalar_log(FS, 1000, t0=0, skip={500})
    _write_foreign(tmp_path / "gap.mcap", messages)
    with pytest.raises(InputError) as err:
        read_runs(tmp_path / "gap.mcap", mapping=MAP)
    text = str(err.value)
    # Message 501 follows message 499: a 2 ms interval where 1 ms was expected, i.e. +1 interval,
    # before the 501st recorded sample (index 500), 0.501 s after the first sample.
    assert "/cmd:effort" in text and "not uniformly sampled" in text
    assert "1 of 998 intervals" in text and "before sample 500" in text and "(0.501 s after" in text
    assert "+1 intervals" in text


def test_foreign_jitter_tolerance():
    """Jitter below 1e-3 of the interval passes; above it is refused (uniform draws, bounds exact)."""
    rng = np.random.default_rng(11)
    base = np.arange(10_000) * 1_000_000
    counts = np.ones(base.size, dtype=int)
    # |jitter| <= 200 ns per timestamp -> interval deviation <= 400 ns = 4e-4 of 1 ms: accepted, and
    # fs is then within 2 * 200 ns / span of 1 kHz (one deviation at each end).
    small = base + rng.integers(-200, 201, base.size)
    sampling = uniform_sampling(small, counts, "x")
    assert abs(sampling.fs - 1000.0) / 1000.0 <= 400 / (base[-1] - base[0])
    # Uniform jitter of +-20 us: an interval deviates > 1 us (1e-3) unless both draws lie within
    # 1 us of each other, probability about 0.05 per interval; 9999 intervals cannot all pass.
    large = base + rng.integers(-20_000, 20_001, base.size)
    with pytest.raises(InputError, match="not uniformly sampled"):
        uniform_sampling(large, counts, "x")


def test_foreign_u_and_y_must_share_sample_instants(tmp_path):
    messages, _, _ = _scalar_log(FS, 500, t0=0, y_shift=5)
    _write_foreign(tmp_path / "shift.mcap", messages)
    with pytest.raises(InputError, match="first samples of u and y are 5 sample intervals apart"):
        read_runs(tmp_path / "shift.mcap", mapping=MAP)
    messages = [m for m in _scalar_log(FS, 500, t0=0)[0] if not (m[0] == "/joint" and m[1] >= 400_000_000)]
    _write_foreign(tmp_path / "short.mcap", messages)
    with pytest.raises(InputError, match="u has 500 samples .* and y has 400"):
        read_runs(tmp_path / "short.mcap", mapping=MAP)


def test_foreign_missing_topic_field_and_mapping(tmp_path):
    messages, _, _ = _scalar_log(FS, 50)
    _write_foreign(tmp_path / "log.mcap", messages)
    with pytest.raises(InputError, match=r"no topic '/sensor'; topics in the file: /cmd, /joint"):
        read_runs(tmp_path / "log.mcap", mapping={"u": "/cmd:effort", "y": "/sensor:position"})
    with pytest.raises(InputError, match=r"field 'state.pos' not found: fields in state are position"):
        read_runs(tmp_path / "log.mcap", mapping={"u": "/cmd:effort", "y": "/joint:state.pos"})
    with pytest.raises(InputError, match=r"fields at the top level are effort, seq"):
        read_runs(tmp_path / "log.mcap", mapping={"u": "/cmd:force", "y": "/joint:state.position"})
    with pytest.raises(InputError, match="signals are u, y and r, got x"):
        read_runs(tmp_path / "log.mcap", mapping={**MAP, "x": "/cmd:seq"})
    with pytest.raises(InputError, match="map the measured output too"):
        read_runs(tmp_path / "log.mcap", mapping={"u": "/cmd:effort"})
    (run,) = read_runs(tmp_path / "log.mcap", require_y=False, mapping={"u": "/cmd:effort"})
    assert run.y is None
    # A foreign file read without a mapping says how to read it and which topics it has.
    with pytest.raises(InputError, match=r"not an nlsid recording.*--map u=/topic:field.*topics: /cmd, /joint"):
        read_runs(tmp_path / "log.mcap")


def test_foreign_non_numeric_field(tmp_path):
    _write_foreign(tmp_path / "t.mcap", [("/cmd", k * 1000, {"effort": "high", "x": k}) for k in range(5)])
    with pytest.raises(InputError, match="expected a number or a non-empty list of numbers"):
        read_runs(tmp_path / "t.mcap", require_y=False, mapping={"u": "/cmd:effort"})


# --------------------------------------------------------------------------------------- bad files


def test_own_file_missing_run_topic_and_block(tmp_path):
    run = _runs()[2]  # 2 full blocks + 17 samples
    path = tmp_path / "gap.mcap"
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        writer.add_metadata("nlsid", {"nlsid_format": "recording", "nlsid_format_version": "1"})
        run_schema = writer.register_schema("nlsid.Run", "jsonschema", json.dumps(RUN_SCHEMA).encode())
        channel = writer.register_channel("/nlsid/run", "json", run_schema)
        writer.add_message(channel, 0, json.dumps(run_message(run)).encode(), 0)
        blocks = {name: writer.register_channel(f"/nlsid/{name}", "json", 0) for name in ("u", "y")}
        for name in ("u", "y"):
            for first in (0, 2 * BLOCK_SAMPLES):  # the block at 4096 is missing
                data = base64.b64encode(getattr(run, name)[first:first + BLOCK_SAMPLES].tobytes()).decode()
                writer.add_message(blocks[name], first, json.dumps({"run": run.run_id, "start": first, "data": data}).encode(), first)
        writer.finish()
    with pytest.raises(InputError, match=rf"/nlsid/u\[zz_arbitrary\]: blocks leave a gap at sample {BLOCK_SAMPLES}"):
        read_runs(path)

    path = tmp_path / "norun.mcap"
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        writer.add_metadata("nlsid", {"nlsid_format": "recording", "nlsid_format_version": "1"})
        writer.add_message(writer.register_channel("/nlsid/u", "json", 0), 0, b"{}", 0)
        writer.finish()
    with pytest.raises(InputError, match=r"missing topic /nlsid/run; topics in the file: /nlsid/u"):
        read_runs(path)


@pytest.mark.parametrize("fraction", [0.3, 0.6, 0.97])
def test_truncated_file_is_refused(tmp_path, fraction):
    write_recording(tmp_path / "r.mcap", _runs())
    data = (tmp_path / "r.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: int(len(data) * fraction)])
    with pytest.raises(InputError, match="truncated"):
        read_runs(tmp_path / "cut.mcap")
    messages, _, _ = _scalar_log(FS, 300)
    _write_foreign(tmp_path / "log.mcap", messages)
    data = (tmp_path / "log.mcap").read_bytes()
    (tmp_path / "logcut.mcap").write_bytes(data[: int(len(data) * fraction)])
    with pytest.raises(InputError, match="truncated"):
        read_runs(tmp_path / "logcut.mcap", mapping=MAP)


def test_garbage_and_damaged_files_are_refused(tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(np.random.default_rng(0).bytes(4000))
    with pytest.raises(InputError, match="not an MCAP file"):
        read_runs(garbage)
    text = tmp_path / "notes.mcap"
    text.write_text("hello")
    with pytest.raises(InputError, match="not an MCAP file"):
        read_runs(text, mapping=MAP)
    # Right magic at both ends, one flipped byte inside a compressed chunk: the CRC or zstd check fails.
    write_recording(tmp_path / "r.mcap", _runs())
    data = bytearray((tmp_path / "r.mcap").read_bytes())
    data[len(data) // 3] ^= 0xFF
    (tmp_path / "flip.mcap").write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"damaged MCAP file \(CRCValidationError"):
        read_runs(tmp_path / "flip.mcap")


# --------------------------------------------------------------------------------------------- CLI


def test_cli_info_reads_foreign_mcap(tmp_path, run_cli):
    messages, _, _ = _scalar_log(FS, 1000)
    _write_foreign(tmp_path / "log.mcap", messages)
    result = run_cli("info", tmp_path / "log.mcap", "--map", "u=/cmd:effort", "--map", "y=/joint:state.position", "--json")
    assert result.exit_code == 0, result.stderr
    (row,) = result.json()["runs"]
    assert row["fs"] == 1000.0 and row["samples"] == 1000 and row["kind"] == "arbitrary"
    result = run_cli("info", tmp_path / "log.mcap", "--map", "u=/cmd:effort", "--map", "y=/nope:x")
    assert result.exit_code == 2 and "Traceback" not in result.stderr
    assert "no topic '/nope'; topics in the file: /cmd, /joint" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def _first_chunk(data: bytes) -> int:
    """Offset of the first Chunk record's content (records: opcode u8, length u64, content)."""
    at = 8  # after the magic
    while data[at] != 0x06:
        at += 9 + int.from_bytes(data[at + 1:at + 9], "little")
    return at + 9


def _damaged_chunk(tmp_path, field: int, value: int):
    """A recording whose first chunk has ``value`` (u64) at ``field`` bytes into its content: start
    time u64, end time u64, uncompressed size u64 (16), crc u32, compression (u32 length + "zstd"),
    records (u64 length (36) + bytes)."""
    write_recording(tmp_path / "r.mcap", _runs())
    data = bytearray((tmp_path / "r.mcap").read_bytes())
    content = _first_chunk(bytes(data))
    assert data[content + 28:content + 36] == b"\x04\x00\x00\x00zstd"
    data[content + field:content + field + 8] = value.to_bytes(8, "little")
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    return tmp_path / "bad.mcap"


def test_chunk_records_length_beyond_the_file_is_not_allocated(tmp_path):
    """A records length of 2^62 bytes: a plain file read would first allocate it (MemoryError).
    Reads stop at the end of the file; the compressed records are intact, so the runs read right."""
    bad = _damaged_chunk(tmp_path, 36, 2 ** 62)
    for got, want in zip(read_runs(bad), _runs(), strict=True):
        _assert_same_run(got, want)


def test_chunk_uncompressed_size_beyond_c_is_damaged(tmp_path):
    with pytest.raises(InputError, match=re.escape("damaged MCAP file (OverflowError")):
        read_runs(_damaged_chunk(tmp_path, 16, 2 ** 64 - 1))
