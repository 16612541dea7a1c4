"""The terminal as an engineer reads it at 80 columns: tables that wrap whole words, identical notes
said once, a readable usage for bare ``nlsid``, and a word before numba's first compilation."""

from __future__ import annotations

import io
import os
import re
import time
from collections import Counter
from types import SimpleNamespace

import numpy as np
from rich.console import Console
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level

import nlsid.cli.common as common
import nlsid.cli.diagnose as diagnose_cli
from nlsid.io.recording import write_recording

WIDTH = 80


def _words_intact(text: str, words: list[str]) -> None:
    """Every word appears whole on some line: none cut to an ellipsis or folded."""
    assert "…" not in text, text
    tokens = set(re.findall(r"[^\s│┃|]+", text))
    for word in words:
        assert word in tokens, (word, text)


def _tokens(text: str) -> Counter:
    """The words of ``text``, without the table's rules and borders."""
    return Counter(token for token in re.findall(r"[^\s│┃|━─┏┓┗┛┡┩└┘┳┻╇┴┬]+", text))


def test_bla_table_fits_80_columns_with_whole_words(run_cli, tmp_path, monkeypatch):
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    rng = np.random.default_rng(2)
    bins = odd_random_bins(1, 41, 3, rng)
    b, a = signal.butter(2, 0.1)
    runs = runs_of_level(3, 256, bins, 1.0, lambda u: signal.lfilter(b, a, u) + 0.1 * signal.lfilter(b, a, u) ** 3,
                         2, rng, noise_y=0.01, level=1.0)
    write_recording(tmp_path / "rec.h5", runs, provenance={"tool": "test"})
    result = run_cli("bla", tmp_path / "rec.h5", "-o", tmp_path / "bla.h5")
    assert result.exit_code == 0, result.stderr
    lines = result.stderr.splitlines()
    assert max(len(line) for line in lines) <= WIDTH, result.stderr
    _words_intact(result.stderr, ["odd", "over", "even", "noise", "method", "level"])
    # rich crops a table it cannot fit (the last column lost): the words at 80 columns are those at 200
    monkeypatch.setenv("COLUMNS", "200")
    wide = run_cli("bla", tmp_path / "rec.h5", "-o", tmp_path / "bla_wide.h5")
    assert _tokens(result.stderr) == _tokens(wide.stderr.replace("bla_wide.h5", "bla.h5"))


def test_text_table_wraps_at_spaces_and_keeps_long_words():
    long_note = ("the data cannot separate the 6th and 7th coefficient; one was fixed at its start value "
                 "and the other carries both")
    rows = [["cubic stiffness", "k3 = 2.001e+08", "+27.3", "0.2 dB above", long_note],
            ["Coulomb friction", "fc = 0.3", "+1.0", "26.0 dB above", "-"]]
    table = common.text_table("Hypotheses", ["hypothesis", "main parameter", "gain dB", "vs noise floor", "note"],
                              rows)
    buffer, wide = io.StringIO(), io.StringIO()
    Console(file=buffer, width=WIDTH, color_system=None).print(table)
    Console(file=wide, width=300, color_system=None).print(table)
    text = buffer.getvalue()
    assert max(len(line) for line in text.splitlines()) <= WIDTH
    assert _tokens(text) == _tokens(wide.getvalue())  # nothing cropped
    _words_intact(text, long_note.split() + ["k3", "2.001e+08", "stiffness", "hypothesis"])


def test_identical_notes_are_grouped():
    reason = "the simpler friction model reached the noise floor already"
    named = [(f"h{i}", reason) for i in range(7)] + [("delay", "no delay above one sample")]
    lines = common.grouped_notes("not fitted: ", named)
    assert lines == [f"not fitted: {reason} (7 hypotheses: h0, h1, h2, h3, h4, h5, h6)",
                     "not fitted: no delay above one sample (delay)"]


def test_diagnose_prints_each_not_fitted_reason_once(monkeypatch):
    reason = "needs a mechanical model (a mass, a spring and a damper) with velocity as a state"
    fitted = SimpleNamespace(hypothesis=SimpleNamespace(title="cubic stiffness", main="k3"),
                             estimate=SimpleNamespace(values={"k3": 2.0e8}), reason="",
                             unit=lambda name, units: "N/m^3" if units == {"u": "N", "y": "m"} else None,
                             score=SimpleNamespace(gain_db=27.3, exact=False, distortion_gain_db=12.0,
                                                   summary=lambda: {"above_floor_db": 0.2}))
    skipped = [SimpleNamespace(hypothesis=SimpleNamespace(title=f"hypothesis {i}", main="x"), reason=reason, score=None)
               for i in range(7)]
    nuisance = "nuisances estimated first (not causes): output_offset = 3.1e-06 +- 2.4e-05"
    fitted.estimate.note = "model.output_offset and model.output_timing: the data cannot tell these apart"
    result = SimpleNamespace(headline=lambda: "Cause: cubic stiffness", evidence=SimpleNamespace(findings=lambda: []),
                             outcomes=[fitted, *skipped], winner=fitted, units={"u": "N", "y": "m"},
                             findings=lambda: [nuisance, "simulation error 0.0152 rms"])
    printed = {}
    for verbose in (0, 1):
        buffer = io.StringIO()
        console = Console(file=buffer, width=WIDTH, color_system=None)
        monkeypatch.setattr(diagnose_cli, "settings", lambda: SimpleNamespace(console=console, verbose=verbose))
        diagnose_cli._print(result, "diag/")
        printed[verbose] = " ".join(buffer.getvalue().split())
    # the settings and the fits' notes only with -v, as the page keeps them in its details
    assert "nuisances estimated first" not in printed[0] and "cannot tell" not in printed[0]
    assert nuisance in printed[1] and f"cubic stiffness: {fitted.estimate.note}" in printed[1]
    assert "simulation error" not in printed[1]  # the evidence is not repeated among the details
    text = buffer.getvalue()
    assert text.count("needs a mechanical") == 1  # seven rows' note said once
    assert "7 hypotheses: hypothesis 0, hypothesis 1" in " ".join(text.split())
    assert max(len(line) for line in text.splitlines()) <= WIDTH
    _words_intact(text, ["stiffness", "k3", "2e+08", "N/m^3", "winner", "mechanical", "velocity"])


def test_bare_nlsid_prints_a_readable_usage(run_cli):
    result = run_cli()
    assert result.exit_code in (0, 2)
    text = result.stdout + result.stderr
    lines = text.strip().splitlines()
    assert len(lines) > 10 and lines[0].startswith("Usage: nlsid")
    assert "nlsid: error" not in text
    assert any(line.strip().startswith("diagnose") for line in lines)  # the commands, one a line


def test_cold_kernel_cache_is_detected(tmp_path, monkeypatch):
    """The cache sub-folder is numba's own (its locator names it), so this checks the guess against numba."""
    from numba.core.caching import _CacheLocator

    from nlsid.simulate import jit

    source = os.path.join(os.path.dirname(jit.__file__), "kernels.py")
    monkeypatch.setattr(jit, "CACHING", True)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert common.kernels_not_compiled()  # an empty cache
    folder = tmp_path / _CacheLocator.get_suitable_cache_subpath(source)
    folder.mkdir()
    index = folder / "kernels._derived-97.py311.nbi"
    index.write_bytes(b"")
    stamp = os.stat(source).st_mtime
    os.utime(index, (stamp - 10, stamp - 10))
    assert common.kernels_not_compiled()  # older than the source: numba recompiles
    os.utime(index, (time.time(), time.time()))
    assert not common.kernels_not_compiled()
    monkeypatch.setattr(jit, "CACHING", False)
    assert common.kernels_not_compiled()  # no cache folder: every run compiles


class _Bar:
    """Stands in for rich's Progress: records the task's descriptions."""

    seen: list[str] = []

    def __init__(self, *columns, **options):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def add_task(self, description, total, **fields):
        _Bar.seen.append(description)
        return 0

    def update(self, task, description=None, total=None, completed=None, **fields):
        if description is not None:
            _Bar.seen.append(description)

    def advance(self, task, advance):
        pass


def test_the_bar_says_kernels_compile_until_its_first_step(monkeypatch):
    import click
    import rich.progress

    monkeypatch.setenv("FORCE_COLOR", "1")  # a terminal for rich: the bar is drawn
    monkeypatch.setattr(rich.progress, "Progress", _Bar)
    for cold in (True, False):
        _Bar.seen = []
        monkeypatch.setattr(common, "kernels_not_compiled", lambda: cold)
        with click.Context(click.Command("diagnose")):
            with common.progress("diagnose", 3, kernels=True) as step:
                step()
                step()
        expected = [f"diagnose: {common.COMPILING_NOTE}", "diagnose"] if cold else ["diagnose"]
        assert _Bar.seen == expected
    with click.Context(click.Command("bla")):  # a stage that does not simulate never says it
        _Bar.seen = []
        monkeypatch.setattr(common, "kernels_not_compiled", lambda: True)
        with common.progress("bla", 1) as step:
            step()
        assert _Bar.seen == ["bla"]


def test_a_ten_column_table_fits_without_cropping():
    """rich crops a table wider than the console (losing its right edge and, when wider still, its
    last column): the table's own minimum width, as rich measures it, must fit 80 columns. Ten
    columns of five-character numbers, as the BLA table per level."""
    header = ["level", "u rms", "M x P", "method", "|G| dB", "NL var", "noise var", "odd over even",
              "odd over noise", "even over noise"]
    rows = [["4", "4", "3 x 2", "io", "-72.1", "-24.1", "-78.9", "67.2", "67.4", "-0.1"]]
    buffer = io.StringIO()
    # printed uncropped, the table shows its real width (with vertical borders: 81 columns)
    Console(file=buffer, width=WIDTH, color_system=None).print(common.text_table("BLA per level", header, rows),
                                                               crop=False)
    assert max(len(line.rstrip()) for line in buffer.getvalue().splitlines()) <= WIDTH
