"""``nlsid bla`` end to end: recording (HDF5 and MCAP) in, bla.h5 and figures out, clean errors."""

from __future__ import annotations

import hashlib
import platform
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

sys.path.insert(0, str(Path(__file__).parent))
from bla_cases import odd_random_bins, runs_of_level  # noqa: E402

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
