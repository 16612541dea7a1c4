"""Measured channels beside u, y, r (recording format version 2): round trips in HDF5 and MCAP,
version 1 files read unchanged, bad channels refused alike by both containers, channels from
``nlsid import --channel`` and ``--map channels.NAME=``, and ``nlsid simulate`` (closed-loop
reference from r, channels carried through)."""

from __future__ import annotations

import base64
import json
import math

import h5py
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from scipy.io import savemat

from nlsid.errors import InputError
from nlsid.io.mcap_recording import BLOCK_SAMPLES, RUN_SCHEMA
from nlsid.io.recording import read_runs, write_recording
from nlsid.io.run import Run

FS = 1000.0


def _run(run_id: str = "ms_00", n_periods: int = 3, period: int = 64, with_r: bool = False, seed: int = 0) -> Run:
    rng = np.random.default_rng(seed)
    n = period * n_periods
    return Run(run_id, FS, "multisine", rng.standard_normal(n), y=rng.standard_normal(n),
               r=rng.standard_normal(n) if with_r else None, period=period, transient_periods=1,
               excited_bins=np.array([1, 3, 5]), level=0.5, realization=seed,
               units={"u": "N", "y": "m", "d": "N"},
               channels={"d": rng.standard_normal(n), "temp_2": np.full(n, 21.5)})


def _assert_same(a: Run, b: Run) -> None:
    for name in ("u", "y", "r"):
        x, z = getattr(a, name), getattr(b, name)
        assert (x is None and z is None) or np.array_equal(x, z)
    assert sorted(a.channels) == sorted(b.channels)
    for name in a.channels:
        assert b.channels[name].dtype == np.float64
        np.testing.assert_array_equal(a.channels[name], b.channels[name])
    assert a.units == b.units


# --------------------------------------------------------------------------------- round trips


def test_hdf5_round_trip_and_layout(tmp_path):
    runs = [_run("ms_00"), _run("ms_01", with_r=True, seed=1)]
    path = write_recording(tmp_path / "rec.h5", runs)
    for a, b in zip(runs, read_runs(path)):
        _assert_same(a, b)
    with h5py.File(path) as f:
        assert f.attrs["nlsid_format_version"] == 2
        assert sorted(f["runs/ms_00/channels"]) == ["d", "temp_2"]
        assert f["runs/ms_00/channels/d"].dtype == np.float64
        assert f["runs/ms_00/channels/d"].attrs["unit"] == "N"
        assert "unit" not in f["runs/ms_00/channels/temp_2"].attrs


def test_mcap_round_trip_and_layout(tmp_path):
    n = 2 * BLOCK_SAMPLES + 36  # three blocks per channel
    big = Run("zz_long", FS, "arbitrary", np.arange(n, dtype=float), y=-np.arange(n, dtype=float),
              channels={"d": np.sin(np.arange(n))})
    runs = [_run("ms_00"), big]
    path = write_recording(tmp_path / "rec.mcap", runs)
    for a, b in zip(runs, read_runs(path)):
        _assert_same(a, b)
    with open(path, "rb") as handle:
        reader = make_reader(handle)
        topics = {c.topic: c for c in reader.get_summary().channels.values()}
        schemas = reader.get_summary().schemas
        assert {"/nlsid/channel/d", "/nlsid/channel/temp_2"} <= set(topics)
        assert schemas[topics["/nlsid/channel/d"].schema_id].name == "nlsid.SampleBlock"
        (meta,) = list(reader.iter_metadata())
        assert meta.metadata["nlsid_format_version"] == "2"
        messages = {json.loads(m.data)["run"]: json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/nlsid/run"])}
        assert messages["ms_00"]["channels"] == ["d", "temp_2"] and messages["zz_long"]["channels"] == ["d"]
        blocks = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/nlsid/channel/d"])]
    assert [b["start"] for b in blocks if b["run"] == "zz_long"] == [0, BLOCK_SAMPLES, 2 * BLOCK_SAMPLES]


def test_hdf5_mcap_hdf5_keeps_channels(tmp_path):
    runs = [_run(with_r=True)]
    write_recording(tmp_path / "a.h5", runs)
    write_recording(tmp_path / "b.mcap", read_runs(tmp_path / "a.h5"))
    write_recording(tmp_path / "c.h5", read_runs(tmp_path / "b.mcap"))
    _assert_same(runs[0], read_runs(tmp_path / "c.h5")[0])


def test_writers_refuse_bad_channels_and_write_nothing(tmp_path):
    run = _run()
    run.channels["d"][5] = np.nan
    for suffix in ("h5", "mcap"):
        with pytest.raises(InputError, match=r"/runs/ms_00/channels/d: 1 NaN or Inf samples \(first at index 5\)"):
            write_recording(tmp_path / f"nan.{suffix}", [run])
        assert not (tmp_path / f"nan.{suffix}").exists()
    run = _run()
    run.channels["fs"] = run.channels.pop("d")
    with pytest.raises(InputError, match="channel name 'fs' is reserved"):
        write_recording(tmp_path / "clash.h5", [run])


# --------------------------------------------------------------------------------- version 1


def _v1_hdf5(path, version=1, channel=None) -> np.ndarray:
    """A version-1 file as plain h5py writes it; ``channel`` adds a member ``channels/d``."""
    u = np.cos(2 * np.pi * 3 * np.arange(128) / 64)
    with h5py.File(path, "w") as f:
        f.attrs["nlsid_format"], f.attrs["nlsid_format_version"] = "recording", version
        run = f.create_group("runs/ms_00")
        run.attrs.update({"fs": FS, "kind": "multisine", "period": 64, "excited_bins": [3]})
        run.create_dataset("u", data=u)
        run.create_dataset("y", data=2 * u)
        if channel is not None:
            run.create_dataset("channels/d", data=channel)
    return u


def test_version_1_hdf5_reads_unchanged(tmp_path, run_cli):
    # A member "channels" meant nothing in version 1: it is not read (here it would be refused: 3 samples).
    u = _v1_hdf5(tmp_path / "v1.h5", channel=np.ones(3))
    (run,) = read_runs(tmp_path / "v1.h5")
    np.testing.assert_array_equal(run.u, u)
    assert run.channels == {} and run.n_periods == 2
    result = run_cli("info", tmp_path / "v1.h5", "--json")
    assert result.exit_code == 0 and result.json()["runs"][0]["channels"] == []


def test_newer_version_is_refused_in_one_line(tmp_path, run_cli):
    _v1_hdf5(tmp_path / "v4.h5", version=4)
    run_cli("info", tmp_path / "v4.h5").assert_one_line_error("v4.h5", "nlsid_format_version is 4, expected 1 or 2 or 3")
    _write_mcap(tmp_path / "v4.mcap", "4", {"u": np.ones(64)})
    run_cli("info", tmp_path / "v4.mcap").assert_one_line_error("v4.mcap", "nlsid_format_version must be '1' or '2' or '3', got '4'")


def _write_mcap(path, version: str, signals: dict[str, np.ndarray], channels: dict[str, np.ndarray] | None = None,
                listed: list | None = None) -> None:
    """An nlsid-layout MCAP file written by hand with the mcap writer: one arbitrary run ``a``.

    ``listed`` is the run message's ``channels`` field (default: the names of ``channels``)."""
    channels = channels or {}
    message = {"run": "a", "fs": FS, "kind": "arbitrary", "transient_periods": 0,
               "n_samples": len(signals["u"]), "signals": list(signals)}
    if listed is not None or channels:
        message["channels"] = list(channels) if listed is None else listed
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        writer.add_metadata("nlsid", {"nlsid_format": "recording" if "y" in signals else "excitation",
                                      "nlsid_format_version": version})
        schema = writer.register_schema("nlsid.Run", "jsonschema", json.dumps(RUN_SCHEMA).encode())
        writer.add_message(writer.register_channel("/nlsid/run", "json", schema), 0, json.dumps(message).encode(), 0)
        topics = {f"/nlsid/{k}": v for k, v in signals.items()} | {f"/nlsid/channel/{k}": v for k, v in channels.items()}
        for topic, samples in topics.items():
            data = base64.b64encode(np.asarray(samples, dtype="<f8").tobytes()).decode()
            writer.add_message(writer.register_channel(topic, "json", 0), 0,
                               json.dumps({"run": "a", "start": 0, "data": data}).encode(), 0)
        writer.finish()


def test_version_1_mcap_reads_unchanged(tmp_path):
    u = np.arange(100.0)
    # A version-1 run message with a field "channels" (and its blocks): ignored, as before version 2.
    _write_mcap(tmp_path / "v1.mcap", "1", {"u": u, "y": 2 * u}, {"d": np.ones(7)})
    (run,) = read_runs(tmp_path / "v1.mcap")
    np.testing.assert_array_equal(run.y, 2 * u)
    assert run.channels == {}
    _write_mcap(tmp_path / "v2.mcap", "2", {"u": u, "y": 2 * u}, {"d": np.ones(100)})
    np.testing.assert_array_equal(read_runs(tmp_path / "v2.mcap")[0].channels["d"], np.ones(100))


# --------------------------------------------------------------------------------- bad channels

# name, samples, the problem stated. A short channel in MCAP does not cover the run's n_samples: the
# block check of every MCAP signal names it first.
MCAP_SHORT = "blocks hold 99 samples, the run message says n_samples = 100"
BAD = {
    "short": ("d", np.ones(99), "channel has 99 samples, u has 100"),
    "nan": ("d", np.r_[np.ones(50), np.nan, np.ones(49)], "1 NaN or Inf samples (first at index 50)"),
    "not_identifier": ("2d", np.ones(100), "channel name '2d' is not an identifier"),
    "dash": ("a-b", np.ones(100), "channel name 'a-b' is not an identifier"),
    "clash_signal": ("y", np.ones(100), "channel name 'y' is reserved"),
    "clash_attribute": ("period", np.ones(100), "channel name 'period' is reserved"),
}


def _bad_hdf5(path, name: str, samples: np.ndarray) -> None:
    with h5py.File(path, "w") as f:
        f.attrs["nlsid_format"], f.attrs["nlsid_format_version"] = "recording", 2
        run = f.create_group("runs/a")
        run.attrs.update({"fs": FS, "kind": "arbitrary"})
        run.create_dataset("u", data=np.arange(100.0))
        run.create_dataset("y", data=np.arange(100.0))
        run.create_dataset(f"channels/{name}", data=samples)


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_channel_is_one_line_naming_file_run_and_channel_in_both_containers(tmp_path, run_cli, case):
    name, samples, problem = BAD[case]
    u = np.arange(100.0)
    _bad_hdf5(tmp_path / "bad.h5", name, samples)
    _write_mcap(tmp_path / "bad.mcap", "2", {"u": u, "y": u}, {name: samples})
    run_cli("info", tmp_path / "bad.h5").assert_one_line_error(f"bad.h5:/runs/a/channels/{name}: {problem}")
    if case == "short":
        run_cli("info", tmp_path / "bad.mcap").assert_one_line_error(f"bad.mcap:/nlsid/channel/d[a]: {MCAP_SHORT}")
    else:  # the one check of both containers, word for word
        run_cli("info", tmp_path / "bad.mcap").assert_one_line_error(f"bad.mcap:/nlsid/run[a]/channels/{name}: {problem}")


def test_channels_group_of_datasets_and_a_listed_channel_without_blocks(tmp_path, run_cli):
    with h5py.File(tmp_path / "g.h5", "w") as f:
        f.attrs["nlsid_format"], f.attrs["nlsid_format_version"] = "recording", 2
        run = f.create_group("runs/a")
        run.attrs.update({"fs": FS, "kind": "arbitrary"})
        run.create_dataset("u", data=np.arange(10.0))
        run.create_dataset("y", data=np.arange(10.0))
        run.create_dataset("channels", data=np.arange(10.0))
    run_cli("info", tmp_path / "g.h5").assert_one_line_error("g.h5:/runs/a/channels", "expected a group of channel datasets")
    u = np.arange(10.0)
    _write_mcap(tmp_path / "m.mcap", "2", {"u": u, "y": u}, listed=["d"])
    run_cli("info", tmp_path / "m.mcap").assert_one_line_error("m.mcap:/nlsid/channel/d[a]", "blocks hold 0 samples")


def test_info_lists_channels(tmp_path, run_cli):
    write_recording(tmp_path / "rec.mcap", [_run()])
    result = run_cli("info", tmp_path / "rec.mcap", "--json")
    assert result.exit_code == 0, result.stderr
    (run,) = result.json()["runs"]
    assert run["signals"] == ["u", "y"] and run["channels"] == ["d", "temp_2"]
    table = run_cli("info", tmp_path / "rec.mcap")
    assert table.exit_code == 0 and "temp_2" in table.stderr


# --------------------------------------------------------------------------------- import and --map


def _periodic(seed: int = 0, period: int = 128, periods: int = 4) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = np.arange(period)[:, None]
    bins = np.arange(1, 40, 2)
    one = np.cos(2 * np.pi * bins * n / period + rng.uniform(0, 2 * np.pi, bins.size)).sum(axis=1)
    return np.tile(one * math.sqrt(2 / bins.size), periods)


def test_csv_and_mat_import_of_a_channel(tmp_path, run_cli):
    lead = np.random.default_rng(5).normal(0, 0.2, 50)
    u = np.r_[lead, _periodic()]
    d = np.arange(u.size, dtype=float)  # the sample index: shows which samples each run kept
    source = tmp_path / "rig.csv"
    rows = [f"{a:.18e},{2 * a:.18e},{b:.18e}" for a, b in zip(u, d)]
    source.write_text("u,y,force\n" + "\n".join(rows) + "\n")
    result = run_cli("import", source, "--fs", FS, "--channel", "d=force", "-o", tmp_path / "rec.h5", "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["signals"] == ["u", "y"] and result.json()["channels"] == ["d"]
    (run,) = read_runs(tmp_path / "rec.h5")
    assert run.kind == "multisine" and run.n_samples < u.size  # the lead-in was cut off
    kept = run.channels["d"].astype(int)
    np.testing.assert_array_equal(run.u, u[kept])  # the channel is cut exactly as u
    np.testing.assert_array_equal(kept, np.arange(kept[0], kept[0] + run.n_samples))

    savemat(tmp_path / "rig.mat", {"data": {"u": u, "y": 2 * u, "force": d}})
    result = run_cli("import", tmp_path / "rig.mat", "--fs", FS, "--u", "data.u", "--y", "data.y",
                     "--channel", "d=data.force", "-o", tmp_path / "mat.mcap")
    assert result.exit_code == 0, result.stderr
    np.testing.assert_array_equal(read_runs(tmp_path / "mat.mcap")[0].channels["d"], run.channels["d"])

    run_cli("import", source, "--fs", FS, "--channel", "d=nope", "-o", tmp_path / "x.h5").assert_one_line_error(
        "rig.csv: --channel d=nope", "no column 'nope'")
    run_cli("import", source, "--fs", FS, "--channel", "fs=force", "-o", tmp_path / "x.h5").assert_one_line_error(
        "--channel fs=force", "channel name 'fs' is reserved")
    run_cli("import", source, "--fs", FS, "--channel", "force", "-o", tmp_path / "x.h5").assert_one_line_error(
        "--channel", "expected NAME=SOURCE")
    assert not (tmp_path / "x.h5").exists()


def _rig_log(path, n: int, force_samples: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A foreign JSON log: /cmd effort, /joint position, /rig force (``force_samples`` of them)."""
    u, force = np.sin(np.arange(n) / 7), np.cos(np.arange(n) / 3)
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start(profile="", library="test-logger")
        schema = writer.register_schema("Sample", "jsonschema", b'{"type": "object"}')
        cmd, joint, rig = (writer.register_channel(t, "json", schema) for t in ("/cmd", "/joint", "/rig"))
        for k in range(n):
            t = 1_000_000_000 + round(k * 1e9 / FS)
            writer.add_message(cmd, t, json.dumps({"effort": u[k]}).encode(), t)
            writer.add_message(joint, t, json.dumps({"position": 3 * u[k]}).encode(), t)
            if k < (force_samples or n):
                writer.add_message(rig, t, json.dumps({"force": {"x": force[k]}}).encode(), t)
        writer.finish()
    return u, force


def test_map_and_import_of_a_channel_from_a_foreign_mcap(tmp_path, run_cli):
    u, force = _rig_log(tmp_path / "log.mcap", 300)
    mapping = ("--map", "u=/cmd:effort", "--map", "y=/joint:position", "--map", "channels.d=/rig:force.x")
    result = run_cli("info", tmp_path / "log.mcap", *mapping, "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["runs"][0]["channels"] == ["d"]
    (run,) = read_runs(tmp_path / "log.mcap", mapping={"u": "/cmd:effort", "y": "/joint:position",
                                                       "channels.d": "/rig:force.x"})
    np.testing.assert_array_equal(run.channels["d"], force)
    result = run_cli("import", tmp_path / "log.mcap", "--u", "/cmd:effort", "--y", "/joint:position",
                     "--channel", "d=/rig:force.x", "-o", tmp_path / "rec.h5")
    assert result.exit_code == 0, result.stderr
    (imported,) = read_runs(tmp_path / "rec.h5")
    np.testing.assert_array_equal(imported.u, u)
    np.testing.assert_array_equal(imported.channels["d"], force)

    run_cli("info", tmp_path / "log.mcap", "--map", "u=/cmd:effort", "--map", "d=/rig:force.x").assert_one_line_error(
        "--map", "SIGNAL one of u, y, r or channels.NAME")
    run_cli("info", tmp_path / "log.mcap", "--map", "u=/cmd:effort", "--map", "channels.r=/rig:force.x"
            ).assert_one_line_error("--map channels.r", "channel name 'r' is reserved")
    _rig_log(tmp_path / "short.mcap", 300, force_samples=250)
    run_cli("info", tmp_path / "short.mcap", "--map", "u=/cmd:effort", "--map", "channels.d=/rig:force.x"
            ).assert_one_line_error("u has 300 samples", "channels.d has 250")


# --------------------------------------------------------------------------------- simulate

# Plant y[k] = u[k-1] (discrete z^-1) under the P controller u = 0.5 (r - y).
LOOP = ("model: {type: transfer_function, domain: discrete, num: [0.0, 1.0], den: [1.0]}\n"
        "closed_loop: {controller: {type: pid, kp: 0.5}}\n")
GAIN = "model: {type: transfer_function, domain: discrete, num: [3.0], den: [1.0]}\n"  # y = 3 u


def _simulate(run_cli, tmp_path, config: str, runs: list[Run], name: str) -> list[Run]:
    (tmp_path / "model.yaml").write_text(config)
    write_recording(tmp_path / f"{name}_in.h5", runs, force=True)
    result = run_cli("simulate", tmp_path / "model.yaml", "--excitation", tmp_path / f"{name}_in.h5",
                     "-o", tmp_path / f"{name}_out.h5", "--force")
    assert result.exit_code == 0, result.stderr
    return read_runs(tmp_path / f"{name}_out.h5")


def test_closed_loop_takes_the_reference_from_r(tmp_path, run_cli):
    rng = np.random.default_rng(3)
    n = 400
    r, u1, u2 = rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n)
    d = rng.standard_normal(n)
    first = _simulate(run_cli, tmp_path, LOOP, [Run("a", FS, "arbitrary", u1, y=u1, r=r, units={"r": "mm", "d": "N"},
                                                    channels={"d": d})], "first")[0]
    second = _simulate(run_cli, tmp_path, LOOP, [Run("a", FS, "arbitrary", u2, y=u2, r=r)], "second")[0]
    # The loop by hand: y[k] = u[k-1], u[k] = 0.5 (r[k] - y[k]).
    y, u = np.zeros(n), np.zeros(n)
    for k in range(n):
        y[k] = u[k - 1] if k else 0.0
        u[k] = 0.5 * (r[k] - y[k])
    for out in (first, second):
        np.testing.assert_array_equal(out.r, r)
        np.testing.assert_allclose(out.u, u, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.y, y, rtol=0, atol=1e-12)
    assert first.units == {"r": "mm", "d": "N"}  # the reference's unit, and the channel's
    np.testing.assert_array_equal(first.channels["d"], d)
    # Without r, the excitation's u is the reference, as before.
    plain = _simulate(run_cli, tmp_path, LOOP, [Run("a", FS, "arbitrary", r)], "plain")[0]
    np.testing.assert_array_equal(plain.u, first.u)


def test_open_loop_carries_channels_and_ignores_r(tmp_path, run_cli):
    rng = np.random.default_rng(4)
    u, r, d = rng.standard_normal(200), rng.standard_normal(200), rng.standard_normal(200)
    (out,) = _simulate(run_cli, tmp_path, GAIN, [Run("a", FS, "arbitrary", u, r=r, units={"d": "N"},
                                                     channels={"d": d})], "open")
    np.testing.assert_allclose(out.y, 3 * u, rtol=0, atol=1e-12)
    assert out.r is None and out.units["d"] == "N"
    np.testing.assert_array_equal(out.channels["d"], d)
