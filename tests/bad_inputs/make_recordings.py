"""Write the deliberately broken recordings of tests/bad_inputs/recordings/ (run to regenerate).

Each case is a small file that breaks one rule of the recording format (docs/formats.md), and
``expected.json`` maps its file name to a fragment the one-line error message must contain and to
the extra command-line arguments it is read with (``--map`` for foreign MCAP files).
Usage: ``python tests/bad_inputs/make_recordings.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
from mcap.writer import Writer

HERE = Path(__file__).parent / "recordings"
N = 64
CASES: dict[str, dict] = {}


def good_run(group: h5py.Group, name: str = "ms_00", periods: int = 3) -> h5py.Group:
    run = group.create_group(name)
    run.attrs.update({"fs": 1000.0, "kind": "multisine", "period": N, "transient_periods": 1,
                      "excited_bins": np.array([1, 3, 5]), "level": 1.0})
    n = np.arange(N * periods)
    u = np.cos(2 * np.pi * n / N) + np.cos(2 * np.pi * 3 * n / N) + np.cos(2 * np.pi * 5 * n / N)
    run.create_dataset("u", data=u)
    run.create_dataset("y", data=0.5 * u)
    return run


def case(name: str, expect: str, args: tuple[str, ...] = ()):
    def register(build):
        CASES[name] = {"expect": expect, "args": list(args)}
        build(HERE / name)
        return build
    return register


def recording(path: Path) -> h5py.File:
    handle = h5py.File(path, "w")
    handle.attrs["nlsid_format"] = "recording"
    handle.attrs["nlsid_format_version"] = 1
    return handle


def with_run(path: Path, edit) -> None:
    with recording(path) as f:
        edit(good_run(f.create_group("runs")))


def foreign_mcap(path: Path, topics: dict[str, str], times: np.ndarray, both: bool = False) -> None:
    """A foreign MCAP log: one JSON message per sample on each topic (field u and, if ``both``, y)."""
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        schema = writer.register_schema("sample", "jsonschema", b"{}")
        for topic, field in topics.items():
            channel = writer.register_channel(topic, "json", schema)
            for i, t in enumerate(times):
                message = {field: float(np.sin(0.1 * i))}
                if both:
                    message["y"] = 0.5 * message[field]
                writer.add_message(channel, int(t), json.dumps(message).encode(), int(t))
        writer.finish()


def main() -> None:
    HERE.mkdir(exist_ok=True)
    for old in HERE.iterdir():
        old.unlink()

    @case("not_hdf5.h5", "not an HDF5 file")
    def _(path):
        path.write_text("time,u,y\n0,1,2\n")

    @case("truncated.h5", "truncated or not an HDF5 file")
    def _(path):
        with_run(path, lambda run: None)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])

    @case("no_format_attr.h5", "attribute nlsid_format is missing, expected 'recording'")
    def _(path):
        with h5py.File(path, "w") as f:
            good_run(f.create_group("runs"))

    @case("wrong_version.h5", "attribute nlsid_format_version is 7, expected 1")
    def _(path):
        with recording(path) as f:
            f.attrs["nlsid_format_version"] = 7
            good_run(f.create_group("runs"))

    @case("no_runs_group.h5", "missing group 'runs'")
    def _(path):
        recording(path).close()

    @case("empty_runs.h5", "holds no runs")
    def _(path):
        with recording(path) as f:
            f.create_group("runs")

    @case("missing_fs.h5", "missing attribute 'fs'")
    def _(path):
        with_run(path, lambda run: run.attrs.__delitem__("fs"))

    @case("negative_fs.h5", "sample rate must be > 0")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("fs", -1000.0))

    @case("text_fs.h5", "fs: expected a finite number")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("fs", "1 kHz"))

    @case("bad_kind.h5", "kind: expected one of multisine, sine, arbitrary")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("kind", "chirp"))

    @case("missing_period.h5", "missing attribute 'period'")
    def _(path):
        with_run(path, lambda run: run.attrs.__delitem__("period"))

    @case("length_mismatch.h5", "signals differ in length: u has 192, y has 191")
    def _(path):
        def edit(run):
            y = run["y"][:-1]
            del run["y"]
            run.create_dataset("y", data=y)
        with_run(path, edit)

    @case("not_whole_periods.h5", "is not (transient_periods 1 + whole periods >= 1) x period 64")
    def _(path):
        def edit(run):
            for name in ("u", "y"):
                x = run[name][:-5]
                del run[name]
                run.create_dataset(name, data=x)
        with_run(path, edit)

    @case("only_transient.h5", "whole periods >= 1")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("transient_periods", 3))

    @case("nan_samples.h5", "/y: 2 NaN or Inf samples (first at index 10)")
    def _(path):
        def edit(run):
            y = run["y"][()]
            y[[10, 20]] = np.nan
            run["y"][...] = y
        with_run(path, edit)

    @case("inf_samples.h5", "/u: 1 NaN or Inf samples (first at index 0)")
    def _(path):
        def edit(run):
            u = run["u"][()]
            u[0] = np.inf
            run["u"][...] = u
        with_run(path, edit)

    @case("bins_out_of_range.h5", "excited_bins: bins must lie in 1..31")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("excited_bins", np.array([1, 3, 40])))

    @case("bins_not_integer.h5", "excited_bins: expected integer bin indices")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("excited_bins", np.array([1.0, 3.5])))

    @case("missing_u.h5", "missing dataset 'u'")
    def _(path):
        with_run(path, lambda run: run.__delitem__("u"))

    @case("two_dimensional_u.h5", "/u: expected a 1-D real array, got shape (3, 64)")
    def _(path):
        def edit(run):
            u = run["u"][()].reshape(3, N)
            del run["u"]
            run.create_dataset("u", data=u)
        with_run(path, edit)

    @case("sine_above_nyquist.h5", "frequency: must lie in (0, fs/2 = 500) Hz")
    def _(path):
        def edit(run):
            run.attrs.update({"kind": "sine", "frequency": 700.0})
        with_run(path, edit)

    @case("params_not_json.h5", "params: expected JSON text")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("params", "K_fc=0.1"))

    @case("negative_transient.h5", "transient_periods: must be >= 0")
    def _(path):
        with_run(path, lambda run: run.attrs.__setitem__("transient_periods", -1))

    @case("mcap_missing_topic.mcap", "no topic '/joint'; topics in the file: /cmd", ("--map", "u=/cmd:effort", "--map", "y=/joint:position"))
    def _(path):
        foreign_mcap(path, {"/cmd": "effort"}, np.arange(50) * 1_000_000)

    @case("mcap_non_uniform.mcap", "not uniformly sampled", ("--map", "u=/log:u", "--map", "y=/log:y"))
    def _(path):
        times = np.arange(50) * 1_000_000
        times[25:] += 400_000  # one interval 40% too long: a dropped or late sample
        foreign_mcap(path, {"/log": "u"}, times, both=True)

    @case("mcap_no_nlsid_layout.mcap", "not an nlsid recording")
    def _(path):
        foreign_mcap(path, {"/log": "u"}, np.arange(10) * 1_000_000)

    @case("mcap_truncated.mcap", "truncated")
    def _(path):
        foreign_mcap(path, {"/log": "u"}, np.arange(200) * 1_000_000)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) * 2 // 3])

    (HERE / "expected.json").write_text(json.dumps(CASES, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
