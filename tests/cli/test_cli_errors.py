"""The command line's promise for every mistake a user can make: one line on stderr naming what is
wrong (``nlsid: error: ...``), exit code 2 (130 for Ctrl-C), no traceback, nothing written and no
input touched; and the global flags accepted where users type them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "configs" / "stage_design.yaml"
STAGE = ROOT / "sample_data" / "stage.h5"


def one_line(result, *fragments: str, code: int = 2) -> str:
    assert result.exit_code == code, (result.exit_code, result.stdout, result.stderr, result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0].startswith("nlsid: error: ") or lines[0] == "nlsid: interrupted", lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


@pytest.mark.parametrize("args, fragments", [
    (["simulate", "m.yaml", "--excitation", "e.h5", "-o", "r.h5", "--seed", "-5"], ["--seed", "-5"]),
    (["bla", "{tmp}", "-o", "{tmp}/b.h5"], ["RECORDING", "is a directory"]),
    (["bla"], ["Missing argument", "nlsid bla --help"]),
    (["bla", "x.h5", "-o", "y.h5", "--no-such-option"], ["--no-such-option"]),
    (["nosuch"], ["nosuch"]),
    (["fit", "b.h5", "-o", "m.yaml", "--max-order", "0"], ["--max-order"]),
])
def test_click_usage_errors_are_one_line(run_cli, tmp_path, args, fragments):
    result = run_cli(*[a.replace("{tmp}", str(tmp_path)) for a in args])
    one_line(result, *fragments)
    assert list(tmp_path.iterdir()) == []


def test_global_flags_after_the_subcommand(run_cli, tmp_path):
    """-q typed after the subcommand silences it as before it; --json before it goes to the command."""
    quiet = run_cli("design", DESIGN, "-o", tmp_path / "a.h5", "-q")
    assert quiet.exit_code == 0 and quiet.stderr == "", quiet.stderr
    loud = run_cli("design", DESIGN, "-o", tmp_path / "b.h5")
    assert loud.exit_code == 0 and "design" in loud.stderr  # the summary table, on stderr
    as_json = run_cli("--json", "design", DESIGN, "-o", tmp_path / "c.h5")
    assert as_json.exit_code == 0 and as_json.json()["runs"] == 3 * 3 + 3 * 3 * 3


def test_verbose_cluster_after_the_subcommand(run_cli, tmp_path):
    result = run_cli("info", STAGE, "-vv", "--json")
    assert result.exit_code == 0 and result.json()["format"] == "recording"


def read_only_folder(tmp_path: Path) -> Path:
    """A folder no file can be created in: permission bits stop a normal user; root ignores them,
    so as root a read-only system folder stands in."""
    if os.geteuid() == 0:
        return Path("/sys")
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    return folder


@pytest.mark.parametrize("stage", ["design", "bla"])
def test_output_into_read_only_folder(run_cli, tmp_path, stage):
    out = read_only_folder(tmp_path) / "out.h5"
    args = ["design", DESIGN, "-o", out] if stage == "design" else ["bla", STAGE, "-o", out]
    one_line(run_cli(*args), "cannot write into folder", str(out.parent))


def test_output_below_an_existing_file(run_cli, tmp_path):
    (tmp_path / "afile").write_text("x")
    one_line(run_cli("design", DESIGN, "-o", tmp_path / "afile" / "x.h5"), "is a file, not a folder")
    one_line(run_cli("diagnose", "--model", DESIGN, "--data", STAGE, "-o", tmp_path / "afile" / "d"),
             "is a file, not a folder")
    assert [p.name for p in tmp_path.iterdir()] == ["afile"]


def test_output_naming_an_input_is_refused_even_with_force(run_cli, tmp_path):
    recording = tmp_path / "rec.h5"
    assert run_cli("-q", "design", DESIGN, "-o", recording).exit_code == 0
    before = recording.read_bytes()
    one_line(run_cli("bla", recording, "-o", recording, "--force"), "output is the input")
    one_line(run_cli("bla", recording, "-o", tmp_path / "." / "rec.h5", "--force"), "output is the input")
    link = tmp_path / "link.h5"
    link.symlink_to(recording)
    one_line(run_cli("bla", link, "-o", recording, "--force"), "output is the input")
    one_line(run_cli("diagnose", "--model", DESIGN, "--data", recording, "-o", tmp_path, "--force"),
             "output holds the input")
    assert recording.read_bytes() == before


def test_diagnose_checks_its_output_before_working(run_cli, tmp_path):
    """A non-empty output folder is refused at once, not after the diagnosis (about 14 s)."""
    folder = tmp_path / "diagnosis"
    folder.mkdir()
    (folder / "old.txt").write_text("keep")
    started = time.perf_counter()
    result = run_cli("diagnose", "--model", ROOT / "configs" / "stage_model.yaml", "--data", STAGE, "-o", folder)
    one_line(result, "not empty", "--force")
    assert time.perf_counter() - started < 3.0
    assert (folder / "old.txt").read_text() == "keep"


def test_an_empty_output_folder_is_written_into(tmp_path):
    from nlsid.io.atomic import check_output_folder
    from nlsid.errors import InputError

    empty = tmp_path / "empty"
    empty.mkdir()
    assert check_output_folder(empty, force=False) == empty
    (empty / "x").write_text("x")
    with pytest.raises(InputError, match="not empty"):
        check_output_folder(empty, force=False)


def test_ctrl_c_while_writing_leaves_nothing(run_cli, tmp_path, monkeypatch):
    """An interrupt in the middle of writing: exit 130, one line, no file and no temporary left."""
    import nlsid.signals.design as design_module

    real = design_module.design_runs

    def interrupted(cfg):
        for i, run in enumerate(real(cfg)):
            if i == 4:
                raise KeyboardInterrupt
            yield run

    monkeypatch.setattr(design_module, "design_runs", interrupted)
    result = run_cli("design", DESIGN, "-o", tmp_path / "e.h5")
    assert result.stderr.strip() == "nlsid: interrupted" and result.exit_code == 130, result.stderr
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_in_a_weakref_callback_ends_the_command():
    """An interrupt that lands in a weakref callback during a collection is one Python cannot raise:
    it printed "Exception ignored in ... Traceback ... KeyboardInterrupt" and the command went on
    (seen once in test_ctrl_c_at_any_moment_of_a_real_process). The entry point's unraisable hook
    delivers it again, so it ends the command as any interrupt does."""
    code = "\n".join([
        "import time, weakref",
        "from nlsid.cli import entry",
        "import sys",
        "sys.unraisablehook = entry._interrupt_again",
        "class Thing: pass",
        "def callback(ref): raise KeyboardInterrupt",
        "thing = Thing(); ref = weakref.ref(thing, callback)",
        "try:",
        "    del thing",
        "    start = time.perf_counter()",
        "    while time.perf_counter() - start < 5: pass",
        "    print('went on')",
        "except KeyboardInterrupt:",
        "    print('interrupted')",
    ])
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.stdout.strip() == "interrupted" and "Exception ignored" not in result.stderr, result


@pytest.mark.parametrize("after_start", [0.0, 0.1, 0.3, 0.6])
def test_ctrl_c_at_any_moment_of_a_real_process(tmp_path, after_start):
    """SIGINT at several moments of start-up and work: either the command finished first (exit 0, its
    output complete) or it ends in exit 130 with one line; never a traceback or a temporary file.

    The moments count from the end of the interpreter's own start-up (measured on ``python -c
    pass`` here): an interrupt while Python itself initialises is Python's to report, not nlsid's.
    """
    started = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    interpreter = time.perf_counter() - started
    out = tmp_path / "e.h5"
    process = subprocess.Popen([sys.executable, "-c", "from nlsid.cli.entry import main; main()",
                                "design", str(DESIGN), "-o", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.5 * interpreter + after_start)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert "Traceback" not in stderr, stderr
    written = [p.name for p in tmp_path.iterdir()]
    if process.returncode == 0:
        assert written == ["e.h5"]
    else:
        assert process.returncode == 130 and stderr.strip().splitlines() == ["nlsid: interrupted"], \
            (process.returncode, stderr)
        # nothing, or (an interrupt in the moment after the rename published it) the whole output
        assert written in ([], ["e.h5"]), written
    if written:
        from nlsid.io.recording import read_runs

        assert len(read_runs(out, require_y=False)) == 36  # the design's 9 multisines and 27 sines: complete
