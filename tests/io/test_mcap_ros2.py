"""ROS 2 MCAP topics through ``--map`` and ``nlsid import``: CDR messages with ros2msg schemas.

Files are written here as ``ros2 bag record -s mcap`` writes them (``mcap_ros2.writer``, profile
``ros2``, one ``.msg`` definition text per schema), and, for one topic, byte by byte from the CDR
rules (encapsulation header ``00 01 00 00`` = little-endian CDR, then the fields), independently
of the decoder. CDR stores float64 as its 8 IEEE 754 bytes, so every value must come back exactly;
log times that are whole multiples of the sample interval in ns give the sample rate exactly
(``fs = 1e9 * (samples between first and last) / (t_last - t_first)``, no rounding).
"""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest
from mcap.writer import IndexType, Writer
from mcap_ros2.writer import Writer as Ros2Writer

from nlsid.errors import InputError
from nlsid.io.recording import open_recording, read_runs

FLOAT64 = "float64 data\n"

# sensor_msgs/msg/JointState as rosbag2 stores it: the message, then each nested definition.
JOINT_STATE = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""

FLOAT64_MULTI_ARRAY = """MultiArrayLayout layout
float64[] data
================================================================================
MSG: std_msgs/MultiArrayLayout
MultiArrayDimension[] dim
uint32 data_offset
================================================================================
MSG: std_msgs/MultiArrayDimension
string label
uint32 size
uint32 stride
"""

T0 = 1_700_000_000_000_000_000  # ns; a multiple of every interval used below
MS = 1_000_000  # ns


def joint_state(log_time: int, position: list[float], velocity: list[float]) -> dict:
    return {"header": {"stamp": {"sec": log_time // 10**9, "nanosec": log_time % 10**9}, "frame_id": "base"},
            "name": ["hip", "knee"], "position": position, "velocity": velocity, "effort": []}


def write_ros2_log(path, u: np.ndarray, y: np.ndarray, r: np.ndarray, interval_ns: int = MS) -> None:
    """u on /cmd (std_msgs/msg/Float64), y and r as knee position and hip velocity on /joint_states."""
    with open(path, "wb") as handle:
        writer = Ros2Writer(handle)
        cmd = writer.register_msgdef("std_msgs/msg/Float64", FLOAT64)
        joints = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        for k in range(u.size):
            t = T0 + k * interval_ns
            writer.write_message("/cmd", cmd, {"data": float(u[k])}, log_time=t)
            writer.write_message("/joint_states", joints, joint_state(t, [0.5, float(y[k])], [float(r[k]), 0.0]), log_time=t)
        writer.finish()


def signals(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n)


ROS2_MAP = {"u": "/cmd:data", "y": "/joint_states:position.1", "r": "/joint_states:velocity.0"}


def test_float64_and_joint_state_fields_via_map(tmp_path):
    u, y, r = signals(500, seed=1)
    write_ros2_log(tmp_path / "bag.mcap", u, y, r)
    with open_recording(tmp_path / "bag.mcap", mapping=ROS2_MAP) as rec:
        assert rec.format == "recording" and rec.provenance["mcap_profile"] == "ros2"
        assert rec.provenance["start_time_ns"] == T0
        (run,) = list(rec)
    # 499 intervals of exactly 1 ms: fs = 1e9 * 499 / 4.99e8 = 1000 exactly.
    assert run.fs == 1000.0 and run.kind == "arbitrary" and run.n_samples == 500
    assert run.u.tobytes() == u.tobytes() and run.y.tobytes() == y.tobytes() and run.r.tobytes() == r.tobytes()


def test_list_field_gives_several_samples_per_message(tmp_path):
    """std_msgs/msg/Float64MultiArray blocks of 25 samples at 500 Hz: one message every 50 ms."""
    fs, block, n_blocks = 500, 25, 40
    u = np.random.default_rng(2).standard_normal(block * n_blocks)
    with open(tmp_path / "daq.mcap", "wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef("std_msgs/msg/Float64MultiArray", FLOAT64_MULTI_ARRAY)
        layout = {"dim": [{"label": "sample", "size": block, "stride": block}], "data_offset": 0}
        for m in range(n_blocks):
            writer.write_message("/daq", schema, {"layout": layout, "data": u[m * block:(m + 1) * block].tolist()},
                                 log_time=T0 + m * block * 10**9 // fs)
        writer.finish()
    (run,) = read_runs(tmp_path / "daq.mcap", require_y=False, mapping={"u": "/daq:data"})
    # 39 intervals of exactly 50 ms hold 975 samples: fs = 1e9 * 975 / 1.95e9 = 500 exactly.
    assert run.fs == 500.0 and run.u.tobytes() == u.tobytes()


def test_narrow_number_types(tmp_path):
    """float32 comes back as the float32 value (exact in float64); integer arrays, fixed or as bytes, exactly."""
    msgdef = "float32 voltage\nint16[3] counts\nuint8[] flags\n"
    n = 20
    volts = np.random.default_rng(3).standard_normal(n)
    with open(tmp_path / "adc.mcap", "wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef("adc_msgs/msg/Reading", msgdef)
        for k in range(n):
            writer.write_message("/adc", schema, {"voltage": float(volts[k]), "counts": [k, -k, 32767], "flags": [k, 255]},
                                 log_time=T0 + k * 3 * MS)
        writer.finish()
    path = tmp_path / "adc.mcap"
    (run,) = read_runs(path, require_y=False, mapping={"u": "/adc:voltage"})
    np.testing.assert_array_equal(run.u, volts.astype(np.float32).astype(np.float64))
    # Three samples per message every 3 ms: 1 kHz (1e9 * 57 / 5.7e7).
    (run,) = read_runs(path, require_y=False, mapping={"u": "/adc:counts"})
    assert run.fs == 1000.0
    np.testing.assert_array_equal(run.u, np.array([[k, -k, 32767] for k in range(n)], dtype=float).ravel())
    (run,) = read_runs(path, require_y=False, mapping={"u": "/adc:flags.1"})
    np.testing.assert_array_equal(run.u, np.full(n, 255.0))


def cdr_float64(value: float) -> bytes:
    """A std_msgs/msg/Float64 in CDR by hand: little-endian encapsulation header, then the double."""
    return b"\x00\x01\x00\x00" + struct.pack("<d", value)


def write_mixed_log(path, u: np.ndarray, y: np.ndarray, summary: bool) -> None:
    """u on a JSON topic, y on a hand-encoded ROS 2 topic, and two topics of encodings not read."""
    options = {} if summary else dict(index_types=IndexType.NONE, repeat_channels=False, repeat_schemas=False,
                                      use_statistics=False, use_summary_offsets=False)
    with open(path, "wb") as handle:
        writer = Writer(handle, **options)
        writer.start(profile="", library="test-logger")
        json_schema = writer.register_schema("Sample", "jsonschema", b'{"type": "object"}')
        ros_schema = writer.register_schema("std_msgs/msg/Float64", "ros2msg", FLOAT64.encode())
        idl_schema = writer.register_schema("std_msgs/msg/Float64", "ros2idl", b"module std_msgs { module msg { struct Float64 { double data; }; }; };")
        proto_schema = writer.register_schema("Sample", "protobuf", b"")
        cmd = writer.register_channel("/cmd", "json", json_schema)
        out = writer.register_channel("/out", "cdr", ros_schema)
        idl = writer.register_channel("/idl", "cdr", idl_schema)
        proto = writer.register_channel("/proto", "protobuf", proto_schema)
        for k in range(u.size):
            t = T0 + k * MS
            writer.add_message(cmd, t, json.dumps({"effort": u[k]}).encode(), t)
            writer.add_message(out, t, cdr_float64(y[k]), t)
            writer.add_message(idl, t, cdr_float64(y[k]), t)
            writer.add_message(proto, t, b"\x09" + struct.pack("<d", y[k]), t)
        writer.finish()


@pytest.mark.parametrize("summary", [True, False], ids=["summary", "no-summary"])
def test_hand_encoded_cdr_beside_json_and_unread_encodings(tmp_path, summary):
    u, y, _ = signals(200, seed=4)
    path = tmp_path / "mixed.mcap"
    write_mixed_log(path, u, y, summary)
    (run,) = read_runs(path, mapping={"u": "/cmd:effort", "y": "/out:data"})
    assert run.fs == 1000.0 and run.u.tobytes() == u.tobytes() and run.y.tobytes() == y.tobytes()
    readable = r"--map reads JSON topics and ROS 2 topics \(cdr messages with a ros2msg schema\) \(readable topics here: /cmd, /out\)"
    with pytest.raises(InputError, match=r"mixed.mcap:/idl: messages are 'cdr'-encoded with a 'ros2idl' schema; " + readable):
        read_runs(path, mapping={"u": "/cmd:effort", "y": "/idl:data"})
    with pytest.raises(InputError, match=r"mixed.mcap:/proto: messages are 'protobuf'-encoded with a 'protobuf' schema; " + readable):
        read_runs(path, mapping={"u": "/proto:data", "y": "/out:data"})


def test_missing_field_names_the_fields_that_exist(tmp_path, capsys):
    u, y, r = signals(10, seed=5)
    path = tmp_path / "bag.mcap"
    write_ros2_log(path, u, y, r)

    def error(field: str) -> str:
        with pytest.raises(InputError) as err:
            read_runs(path, require_y=False, mapping={"u": f"/joint_states:{field}"})
        return str(err.value)

    # The fields of sensor_msgs/msg/JointState and of its nested messages, as in JOINT_STATE above.
    assert "field 'pos' not found: fields at the top level are effort, header, name, position, velocity" in error("pos")
    assert "field 'header.stamp.secs' not found: fields in header.stamp are nanosec, sec" in error("header.stamp.secs")
    assert "field 'position.2' not found: position is a list of 2 (indexed position.0 to position.1)" in error("position.2")
    assert "field 'position.x' not found: position is a list of 2" in error("position.x")
    assert "field 'effort.0' not found: effort is a list of 0 (empty)" in error("effort.0")
    assert "field 'header.frame_id.x' not found: header.frame_id is a str, not an object" in error("header.frame_id.x")
    assert 'expected a number or a non-empty list of numbers, got ["hip", "knee"]' in error("name")
    # A nested message is shown as the JSON object of its fields (first 60 characters); message 0 is at T0.
    header = {"stamp": {"sec": T0 // 10**9, "nanosec": 0}, "frame_id": "base"}
    assert f"got {json.dumps(header)[:60]}" in error("header")
    assert f"/joint_states message at log_time {T0} ns" in error("pos")
    # Data the CDR header of one message is too short for, and a schema that does not parse.
    bad = tmp_path / "bad.mcap"
    with open(bad, "wb") as handle:
        writer = Writer(handle)
        writer.start(profile="ros2", library="test-logger")
        good = writer.register_channel("/out", "cdr", writer.register_schema("std_msgs/msg/Float64", "ros2msg", FLOAT64.encode()))
        broken = writer.register_channel("/typo", "cdr", writer.register_schema("std_msgs/msg/Float64", "ros2msg", b"flot64 data\n"))
        writer.add_message(good, T0, cdr_float64(1.0), T0)
        writer.add_message(good, T0 + MS, cdr_float64(2.0)[:9], T0 + MS)
        writer.add_message(broken, T0, cdr_float64(1.0), T0)
        writer.finish()
    with pytest.raises(InputError, match=rf"/out message at log_time {T0 + MS} ns: not a CDR-encoded std_msgs/msg/Float64 message \(unpack_from requires"):
        read_runs(bad, require_y=False, mapping={"u": "/out:data"})
    with pytest.raises(InputError, match=r"bad.mcap:/typo: ROS 2 schema 'std_msgs/msg/Float64' does not parse \(InvalidResourceName: 'flot64'"):
        read_runs(bad, require_y=False, mapping={"u": "/typo:data"})
    assert capsys.readouterr().err == ""  # the ROS 2 parser's own stderr complaint stays out of the one-line error


def multisine_period(n: int, bins: np.ndarray, seed: int) -> np.ndarray:
    phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, bins.size)
    k = np.arange(n)[:, None]
    return math.sqrt(2.0 / bins.size) * np.cos(2 * np.pi * bins[None, :] * k / n + phases).sum(axis=1)


def test_nlsid_import_and_info_read_ros2_topics(run_cli, tmp_path):
    """Three periods of an odd multisine (bins 1, 3, ..., 39 of N = 128) with 1e-3 noise, imported by field."""
    n, bins = 128, np.arange(1, 40, 2)
    rng = np.random.default_rng(6)
    u = np.tile(multisine_period(n, bins, seed=7), 3) + rng.normal(0, 1e-3, 3 * n)
    y = np.convolve(u, [0.5, 0.3, 0.1])[: u.size]
    source = tmp_path / "bag.mcap"
    write_ros2_log(source, u, y, np.zeros_like(u))
    out = tmp_path / "rec.h5"
    result = run_cli("import", source, "--u", "/cmd:data", "--y", "/joint_states:position.1", "-o", out, "--json")
    assert result.exit_code == 0, (result.stderr, result.exception)
    summary = result.json()
    assert summary["fs"] == 1000.0 and summary["fs_from"] == "MCAP log times"
    (run,) = read_runs(out)
    # The excited lines stand 60 dB above the noise: the F test of the inference finds exactly them.
    assert (run.kind, run.period, run.n_periods) == ("multisine", n, 3)
    assert run.excited_bins.tolist() == bins.tolist()
    np.testing.assert_array_equal(run.periods("u").ravel(), u)
    np.testing.assert_array_equal(run.periods("y").ravel(), y)

    result = run_cli("info", source, "--map", "u=/cmd:data", "--map", "y=/joint_states:position.1", "--json")
    assert result.exit_code == 0, (result.stderr, result.exception)
    (listed,) = result.json()["runs"]
    assert (listed["fs"], listed["samples"], listed["signals"]) == (1000.0, 3 * n, ["u", "y"])

    bad = run_cli("import", source, "--u", "/cmd:value", "-o", tmp_path / "bad.h5")
    assert bad.exit_code == 2 and not (tmp_path / "bad.h5").exists()
    assert bad.stderr.count("\n") == 1 and "fields at the top level are data" in bad.stderr
