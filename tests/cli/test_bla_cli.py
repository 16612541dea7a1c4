"""``nlsid bla`` end to end: recording (HDF5 and MCAP) in, bla.h5 and figures out, clean errors."""

from __future__ import annotations

import hashlib
import json
import platform
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level  # noqa: E402

from nlsid.errors import InputError  # noqa: E402
from nlsid.io.bla_file import read_bla  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402

B, A = signal.butter(2, 0.25)


def system(u):
    return signal.lfilter(B, A, u)


def two_level_runs(seed=1, M=4):
    rng = np.random.default_rng(seed)
    bins = odd_random_bins(1, 161, 3, rng)
    runs = []
    for level in (0.5, 1.0):
        for run in runs_of_level(M, 512, bins, level, system, 3, rng, fs=1000.0, noise_y=0.01, level=level):
            run.run_id = f"L{level:g}_{run.run_id}"
            runs.append(run)
    return runs, bins


@pytest.fixture
def recording(tmp_path):
    runs, bins = two_level_runs()
    path = tmp_path / "rec.h5"
    write_recording(path, runs, provenance={"tool": "test"})
    return path, bins


def test_writes_results_and_figures(tmp_path, recording, run_cli):
    path, bins = recording
    out, figures = tmp_path / "bla.h5", tmp_path / "figs"
    result = run_cli("bla", path, "-o", out, "--plots", figures, "--json")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    assert [row["level"] for row in summary["levels"]] == [0.5, 1.0]
    stored = read_bla(out)
    assert stored["attrs"]["provenance"]["inputs"] == {str(path): hashlib.sha256(path.read_bytes()).hexdigest()}
    assert len(stored["levels"]) == 2
    level = stored["levels"][0]
    assert level["attrs"]["n_realizations"] == 4 and level["attrs"]["method"] == "io"
    np.testing.assert_array_equal(level["excited_bins"], bins)
    np.testing.assert_allclose(level["frequency"], bins * 1000.0 / 512)
    # A linear system: the stored BLA is G(e^jw) inside the stored 95% circles at most lines
    # (4 binomial standard deviations below 95%).
    G = level["robust"]["G"]
    assert np.iscomplexobj(G)
    _, G_true = signal.freqz(B, A, worN=2 * np.pi * bins / 512)
    inside = np.mean(np.abs(G - G_true) <= level["robust"]["radius"])
    assert inside > 0.95 - 4 * np.sqrt(0.95 * 0.05 / bins.size)
    assert level["fast"] is not None and np.iscomplexobj(level["fast"]["G"])
    assert set(level["lines"]) >= {"kind", "in_band", "u_power", "u_noise", "y_power", "y_noise"}
    names = sorted(p.name for p in figures.iterdir())
    assert names == ["bla_level_00.png", "bla_level_01.png", "bla_vs_level.png",
                     "spectrum_level_00.png", "spectrum_level_01.png"]
    assert all((figures / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for n in names)
    rows = stored["attrs"]["across_levels"]["levels"]
    # Linear: the BLA does not change with the level beyond its noise (std of |G| ratio ~ 1e-3 here).
    assert abs(rows[1]["bla_change_mean_db"]) < 0.05


def test_mcap_and_hdf5_give_the_same_bla(tmp_path, recording, run_cli):
    path, _ = recording
    runs, _ = two_level_runs()
    mcap = tmp_path / "rec.mcap"
    write_recording(mcap, runs, provenance={"tool": "test"})
    assert run_cli("-q", "bla", path, "-o", tmp_path / "a.h5").exit_code == 0
    result = run_cli("-q", "bla", mcap, "-o", tmp_path / "b.h5")
    assert result.exit_code == 0, result.stderr
    a, b = read_bla(tmp_path / "a.h5"), read_bla(tmp_path / "b.h5")
    for la, lb in zip(a["levels"], b["levels"]):
        np.testing.assert_allclose(lb["robust"]["G"], la["robust"]["G"], rtol=1e-12)


def test_refuses_existing_output_and_bad_confidence(tmp_path, recording, run_cli):
    path, _ = recording
    out = tmp_path / "bla.h5"
    out.write_text("keep")
    result = run_cli("bla", path, "-o", out)
    assert result.exit_code == 2 and "--force" in result.stderr
    assert out.read_text() == "keep"
    result = run_cli("bla", path, "-o", tmp_path / "x.h5", "--confidence", "1.5")
    assert result.exit_code == 2 and "--confidence" in result.stderr
    assert not (tmp_path / "x.h5").exists()


def test_runs_of_a_level_with_different_lines_is_one_clear_error(tmp_path, run_cli):
    runs, bins = two_level_runs()
    runs[1].excited_bins = bins[1:]
    path = tmp_path / "bad.h5"
    write_recording(path, runs)
    out = tmp_path / "bla.h5"
    result = run_cli("bla", path, "-o", out)
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "excited_bins" in lines[0] and runs[1].run_id in lines[0]
    assert "Traceback" not in result.stderr and not out.exists()


def test_read_bla_rejects_other_files(recording):
    path, _ = recording
    with pytest.raises(InputError, match="nlsid_format is 'recording', expected a 'bla' file"):
        read_bla(path)


def test_the_input_hash_in_background_raises_when_asked(tmp_path):
    """The provenance hash runs beside the analysis: its digest is the file's, and an unreadable
    input fails only where the digest is asked for (the stage has said why already)."""
    from nlsid.io.provenance import file_sha256, provenance, sha256_in_background

    path = tmp_path / "data.bin"
    path.write_bytes(b"nlsid" * 1000)
    digest = sha256_in_background(path)
    assert provenance(input_paths=[path], digests={str(path): digest})["inputs"] == {str(path): file_sha256(path)}
    missing = sha256_in_background(tmp_path / "missing.h5")
    with pytest.raises(FileNotFoundError):
        missing()


FREED_RSS_PROBE = """
import os, sys
import numpy as np
from nlsid.cli.common import keep_freed_memory
def rss():
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
if sys.argv[1] == "keep":
    keep_freed_memory()
block = np.ones(2 << 20)  # 16 MB, touched
held = rss()
del block
print(held - rss())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
                    reason="glibc's malloc only")
def test_freed_run_buffers_are_kept_for_the_next_run():
    """bla keeps freed memory for reuse (glibc's mallopt): a freed 16 MB block stays mapped, where
    by default it is handed back at once (and the next run page-faults its buffers in anew)."""
    import subprocess

    def released(mode: str) -> int:
        out = subprocess.run([sys.executable, "-c", FREED_RSS_PROBE, mode], capture_output=True, text=True, check=True)
        return int(out.stdout)

    assert released("default") > 12 << 20
    assert released("keep") < 4 << 20


@pytest.mark.parametrize("flags", [[], ["-q"], ["--json"], ["-q", "--json"]], ids=" ".join)
def test_a_stderr_that_is_no_terminal_gets_what_the_rich_bar_writes_there(tmp_path, recording, run_cli,
                                                                            monkeypatch, flags):
    """Where stderr is no terminal the progress bar is not drawn (nlsid.cli.common.progress): rich's
    bar writes one empty line there when it ends, and so does its stand-in, after a run as after an
    error inside the bar; the table or summary and the error line that follow are the same."""
    import nlsid.cli.common as common

    path, _ = recording
    runs, bins = two_level_runs()
    runs[1].excited_bins = bins[1:]  # the second run of a level on other lines: an error inside the bar
    bad = tmp_path / "bad.h5"
    write_recording(bad, runs)

    def outputs() -> list[tuple]:
        done = run_cli(*flags, "bla", path, "-o", tmp_path / "bla.h5", "--force")
        failed = run_cli(*flags, "bla", bad, "-o", tmp_path / "bad_bla.h5")
        return [(result.exit_code, result.stdout, result.stderr) for result in (done, failed)]

    without_bar = outputs()
    monkeypatch.setattr(common, "_stderr_is_plain_file", lambda: False)  # rich's bar, on the same stderr
    assert outputs() == without_bar
    (done, summary, report), (failed, _, error) = without_bar
    quiet, as_json = "-q" in flags, "--json" in flags
    assert done == 0 and failed == 2 and bool(summary) is as_json
    assert report.startswith("" if quiet else "\n") and ("G_BLA" in report) is not (quiet or as_json)
    assert error.startswith("nlsid: error: " if quiet else "\nnlsid: error: ")


LOADED_PROBE = """
import json, sys
from click.testing import CliRunner
from nlsid.cli.main import cli
result = CliRunner().invoke(cli, sys.argv[1:])
assert result.exit_code == 0, result.output
print(json.dumps(sorted({name.split(".")[0] for name in sys.modules})))
"""


def test_the_json_summary_on_a_pipe_loads_no_rich(tmp_path, recording):
    """rich draws the bar and the table: ``--json`` on a stderr that is no terminal needs neither."""
    import os
    import subprocess

    path, _ = recording
    env = {key: value for key, value in os.environ.items()
           if key not in ("TTY_COMPATIBLE", "TTY_INTERACTIVE", "FORCE_COLOR")}

    def loaded(*extra: str) -> set[str]:
        out = subprocess.run([sys.executable, "-c", LOADED_PROBE, "bla", str(path), "-o", str(tmp_path / "bla.h5"),
                              "--force", *extra], capture_output=True, text=True, env=env, check=True)
        return set(json.loads(out.stdout.splitlines()[-1]))

    assert "rich" not in loaded("--json")
    assert "rich" in loaded()  # the probe sees rich where the table is printed


def test_each_level_is_summarised_once(tmp_path, recording, run_cli, monkeypatch):
    """The table, ``--json``, bla.h5 and the summary across levels share one summary per level."""
    import nlsid.analysis.levels as levels_module

    path, _ = recording
    calls = []
    classify = levels_module.classify
    monkeypatch.setattr(levels_module, "classify", lambda *args: calls.append(args) or classify(*args))
    out = tmp_path / "bla.h5"
    result = run_cli("bla", path, "-o", out, "--json")
    assert result.exit_code == 0, result.stderr
    assert len(calls) == 2  # the distortion class, once for each of the two levels
    stored = read_bla(out)
    assert [level["attrs"]["summary"] for level in stored["levels"]] == result.json()["levels"]


TEARDOWN_PROBE = """
import atexit, gc, sys
atexit.register(lambda: print(gc.get_freeze_count()))
sys.argv = ["nlsid", *sys.argv[1:]]
from nlsid.cli.entry import main
main()
"""


@pytest.mark.parametrize("args, code", [(["--version"], 0), (["bla", "missing.h5", "-o", "x.h5"], 2)])
def test_a_finished_command_leaves_its_objects_out_of_the_last_collections(tmp_path, args, code):
    """The console script freezes the objects of a finished command (cli/entry.py), so that the
    interpreter's teardown does not trace them all again; the exit code is the command's."""
    import subprocess

    out = subprocess.run([sys.executable, "-c", TEARDOWN_PROBE, *args], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == code, out.stderr
    assert int(out.stdout.splitlines()[-1]) > 1000
