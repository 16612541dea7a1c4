"""``nlsid info`` says which stages a recording can feed, and its verdict is the stage's own.

Each recording here is one that some stage rejects (u all zero, y missing, one realization where
two are needed, sines only for bla, ...). For every stage the test runs the stage itself on the
file and compares: info's ``feeds`` is the stage's exit code 0, info's ``reason`` is the stage's
error line (nlsid.feeds holds the checks both run).
"""

from __future__ import annotations

import json
import re

import h5py
import numpy as np

from nlsid.io.recording import write_recording
from nlsid.io.run import Run

FS, N = 64.0, 64
BINS = np.array([1, 3, 5, 7, 9])

MODEL = """model:
  type: mass_spring_damper
  mass: 1.0
  damping: 20.0
  stiffness: 4000.0
  gain: 4000.0
"""
FREE = MODEL + """free:
  model.damping: {lower: 1.0, upper: 100.0}
"""


def multisine(run_id: str, realization: int, level: float = 0.5, u_scale: float = 1.0, periods: int = 2,
              bins=BINS, with_y: bool = True) -> Run:
    rng = np.random.default_rng(realization)
    spectrum = np.zeros(N // 2 + 1, complex)
    spectrum[bins] = np.exp(1j * rng.uniform(0, 2 * np.pi, bins.size))
    u = np.tile(np.fft.irfft(spectrum, n=N) * N / 2, periods + 1) * u_scale
    y = 0.5 * u + 0.01 * rng.standard_normal(u.size) if with_y else None
    return Run(run_id, FS, "multisine", u, y, period=N, transient_periods=1, realization=realization,
               level=level, excited_bins=np.array(bins))


def sine(run_id: str, k: float, amplitude: float, periods: int = 2, seed: int = 0) -> Run:
    """A single sine on bin k (a fraction of a bin: off the grid), y with a quadratic term and noise."""
    n = np.arange((periods + 1) * N)
    u = amplitude * np.sin(2 * np.pi * round(k) * n / N)
    y = u + 0.1 * u**2 + 0.01 * np.random.default_rng(seed).standard_normal(u.size)
    return Run(run_id, FS, "sine", u, y, period=N, transient_periods=1, level=amplitude, frequency=k * FS / N,
               excited_bins=np.array([round(k)]))


def stage_args(stage: str, rec: str, tmp_path) -> list:
    models = tmp_path / "models"
    models.mkdir(exist_ok=True)
    (models / "model.yaml").write_text(MODEL)
    (models / "free.yaml").write_text(FREE)
    out = tmp_path / "out" / stage.split()[0]
    out.parent.mkdir(exist_ok=True)
    return {
        "bla": ["bla", rec, "-o", f"{out}.h5"],
        "hosidf": ["hosidf", rec, "-o", f"{out}.h5"],
        "diagnose": ["diagnose", "--model", models / "model.yaml", "--data", rec, "-o", out],
        "fit --model": ["fit", "--model", models / "free.yaml", "--data", rec, "-o", f"{out}.yaml"],
        "simulate --excitation": ["simulate", models / "model.yaml", "--excitation", rec, "-o", f"{out}.h5"],
    }[stage]


def stage_verdict(run_cli, args: list) -> tuple[bool, str | None]:
    """(accepted, the error line without the ``nlsid: error:`` prefix) of running a stage."""
    result = run_cli("-q", *args)
    if result.exit_code == 0:
        return True, None
    result.assert_one_line_error()
    line = result.stderr.strip()
    assert line.startswith("nlsid: error: "), line
    return False, line.removeprefix("nlsid: error: ")


def info_stages(run_cli, rec: str, *extra) -> dict:
    result = run_cli("info", rec, *extra, "--json")
    assert result.exit_code == 0, result.stderr
    return result.json()["stages"]


def assert_same_verdicts(run_cli, tmp_path, rec: str, expected: dict[str, bool], *extra) -> dict:
    """Info's verdict on each stage of ``expected`` is what running the stage gives, and is ``expected``."""
    stages = info_stages(run_cli, rec, *extra)
    for stage, feeds in expected.items():
        accepted, error = stage_verdict(run_cli, stage_args(stage, rec, tmp_path) + list(extra))
        assert (stages[stage]["feeds"], stages[stage]["reason"]) == (accepted, error), stage
        assert accepted is feeds, (stage, error)
    return stages


def test_u_all_zero_feeds_neither_bla_nor_diagnose(run_cli, tmp_path):
    rec = str(tmp_path / "zero_u.h5")
    write_recording(rec, [multisine("m0", 0, u_scale=0.0), multisine("m1", 1, u_scale=0.0)])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False, "diagnose": False, "hosidf": False,
                                                           "fit --model": True, "simulate --excitation": True})
    assert stages["bla"]["reason"] == f"{rec}:/runs/m0/u: excited bin 1 carries no input; " \
                                      "excited_bins does not match the signal"
    assert set(stages) == {"bla", "hosidf", "diagnose", "fit --model", "simulate --excitation"}


def test_a_later_run_whose_reference_misses_an_excited_line(run_cli, tmp_path):
    """bla checks the input on the spectra its analysis computes, after the first run of the level
    has been accumulated; info checks the same line with its own: the same verdict, the same line."""
    first, second = multisine("m0", 0), multisine("m1", 1)
    first.r = first.u.copy()
    second.r = np.zeros_like(second.u)  # --method auto: the reference method, and no reference at all
    rec = str(tmp_path / "no_r.h5")
    write_recording(rec, [first, second])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False})
    assert stages["bla"]["reason"].startswith(f"{rec}:/runs/m1/u: excited bin ")
    assert stages["bla"]["reason"].endswith(" carries no input; excited_bins does not match the signal")


def test_an_excitation_file_feeds_only_simulate(run_cli, tmp_path):
    rec = str(tmp_path / "excitation.h5")
    write_recording(rec, [multisine("m0", 0, with_y=False), multisine("m1", 1, with_y=False)])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False, "hosidf": False, "diagnose": False,
                                                           "fit --model": False, "simulate --excitation": True})
    assert {stages[s]["reason"] for s in ("bla", "hosidf", "diagnose", "fit --model")} == {
        f"{rec}: is an excitation without measured output y: run `nlsid simulate` on it or measure the machine first"}


def test_a_run_without_y_in_a_recording_is_named(run_cli, tmp_path):
    rec = str(tmp_path / "lab.h5")
    runs = [multisine("m0", 0), multisine("m1", 1)]
    with h5py.File(rec, "w") as f:  # as a lab script might write it: the second run lost its y
        f.attrs["nlsid_format"], f.attrs["nlsid_format_version"] = "recording", 1
        for i, run in enumerate(runs):
            group = f.create_group(f"runs/{run.run_id}")
            group.attrs.update(run.attrs())
            group["u"] = run.u
            if i == 0:
                group["y"] = run.y
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False, "diagnose": False, "fit --model": False,
                                                           "simulate --excitation": True})
    assert stages["bla"]["reason"].startswith(f"{rec}:/runs/m1: missing dataset 'y'")


def test_one_realization_feeds_bla_but_not_diagnose_or_fit(run_cli, tmp_path):
    rec = str(tmp_path / "one.h5")
    write_recording(rec, [multisine("m0", 0)])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": True, "diagnose": False, "fit --model": False})
    assert "needs two runs (realizations) of one excitation" in stages["diagnose"]["reason"]
    assert stages["fit --model"]["reason"].startswith("runs: need at least two runs: some to fit and one to validate on")
    # and the routes that feed it with one record, as fit --model itself offers them
    assert "--validate-on" in stages["fit --model"]["reason"] and "--estimation-range" in stages["fit --model"]["reason"]


def test_realizations_of_one_level_on_different_lines(run_cli, tmp_path):
    rec = str(tmp_path / "lines.h5")
    write_recording(rec, [multisine("m0", 0), multisine("m1", 1, bins=np.array([1, 3, 5, 7, 11]))])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False, "diagnose": False})
    assert stages["bla"]["reason"].startswith(f"{rec}:/runs/m1.excited_bins: differ from those of run m0")


def test_sines_only_feed_hosidf_not_bla(run_cli, tmp_path):
    rec = str(tmp_path / "sines.h5")
    write_recording(rec, [sine(f"s{f}_{r}", f, 1.0, seed=r) for f in (2, 4) for r in range(2)])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False, "hosidf": True})
    assert stages["bla"]["reason"] == (f"{rec}: holds no multisine or arbitrary runs; the BLA needs random-phase "
                                       "multisines or arbitrarily excited records (sines are for `nlsid hosidf`)")
    assert stages["bla"]["notes"] == ["skips 4 runs that are not multisines"]
    assert stages["hosidf"]["notes"] == ["--harmonics 7 at most"]  # bin 4 of 64: 7 * 4 < 32


def test_a_sine_off_the_bins_feeds_neither_hosidf_nor_diagnose(run_cli, tmp_path):
    rec = str(tmp_path / "off.h5")
    write_recording(rec, [sine(f"s_{r}", 4.5, 1.0, seed=r) for r in range(2)])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"hosidf": False, "diagnose": False})
    assert "4.5 Hz is not on a bin of the 64-sample period" in stages["hosidf"]["reason"]
    assert stages["diagnose"]["reason"].startswith("run s_0.frequency: 4.5 Hz is not on a bin")


def test_one_run_of_one_period_cannot_feed_hosidf_whatever_the_options(run_cli, tmp_path):
    rec = str(tmp_path / "single.h5")
    write_recording(rec, [sine("s", 2, 1.0, periods=1)])
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"hosidf": False})
    assert "Table I needs at least two spectra" in stages["hosidf"]["reason"]
    for variance in ("repeats", "periods"):
        args = stage_args("hosidf", rec, tmp_path) + ["--variance", variance]
        assert stage_verdict(run_cli, args) == (False, stages["hosidf"]["reason"])


def test_what_depends_on_options_is_a_note(run_cli, tmp_path):
    """One repeat per cell, and a tone whose 5th harmonic is above Nyquist: hosidf can be fed, but
    only with --variance periods and --harmonics 3; the notes quote what the defaults give."""
    rec = str(tmp_path / "repeat.h5")
    write_recording(rec, [sine("s", 10, 1.0)])
    stages = info_stages(run_cli, rec)
    hosidf = stages["hosidf"]
    assert hosidf["feeds"] and hosidf["reason"] is None
    args = stage_args("hosidf", rec, tmp_path)
    _, default_error = stage_verdict(run_cli, args)
    _, harmonics_error = stage_verdict(run_cli, args + ["--variance", "periods"])
    _, variance_error = stage_verdict(run_cli, args + ["--harmonics", "3"])
    assert hosidf["notes"] == [
        f"--harmonics 3 at most; the default 5 stops it: {harmonics_error}",
        f"the default --variance both stops it: {variance_error}; --variance periods does not",
    ]
    assert default_error == harmonics_error  # the stage meets the harmonics first, run by run
    assert stage_verdict(run_cli, args + ["--variance", "periods", "--harmonics", "3", "--force"]) == (True, None)


def test_foreign_mcap_without_y(run_cli, tmp_path):
    from mcap.writer import Writer

    rec = str(tmp_path / "log.mcap")
    with open(rec, "wb") as handle:
        writer = Writer(handle)
        writer.start(profile="", library="test-logger")
        channel = writer.register_channel("/cmd", "json", writer.register_schema("S", "jsonschema", b"{}"))
        for k in range(256):
            t = 1_000_000 * k
            writer.add_message(channel, t, json.dumps({"effort": float(np.sin(k / 5))}).encode(), t)
        writer.finish()
    stages = assert_same_verdicts(run_cli, tmp_path, rec, {"bla": False, "hosidf": False}, "--map", "u=/cmd:effort")
    assert stages["bla"]["reason"] == "--map: map the measured output too: --map y=/topic:field"
    accepted, error = stage_verdict(run_cli, stage_args("simulate --excitation", rec, tmp_path))  # no --map
    assert (stages["simulate --excitation"]["feeds"], stages["simulate --excitation"]["reason"]) == (accepted, error)
    assert not accepted and "not an nlsid recording" in error


def test_table_lists_every_stage_with_its_reason(run_cli, tmp_path):
    """The reasons are printed as they are: run ids with [brackets] are not taken for markup."""
    rec = str(tmp_path / "lines.h5")
    write_recording(rec, [multisine("m[a]0", 0), multisine("m[a]1", 1, bins=np.array([1, 3, 5, 7, 11]))])
    stages = info_stages(run_cli, rec)
    result = run_cli("info", rec)
    assert result.exit_code == 0, result.stderr
    text = re.sub(r"[\s│┃|]", "", result.stderr)
    for stage, verdict in stages.items():
        row = stage.replace(" ", "") + ("yes" if verdict["feeds"] else "no")
        first = verdict["reason"] or (f"note: {verdict['notes'][0]}" if verdict["notes"] else "-")
        assert row + re.sub(r"\s", "", first) in text
    assert "[a]1.excited_bins" in stages["bla"]["reason"] and not stages["bla"]["feeds"]
