"""What a report page offers besides its text, checked without a browser: each figure's data as a
CSV ``data:`` URL (parsed back and compared with what the figure was drawn from, or with theory),
units from the recording, and citations as a reader finds them (authors, venue, year), never the
internal labels of the source files ("seed 003", "book Ex. 92")."""

from __future__ import annotations

import ast
import csv
import html
import io
import re
import urllib.parse
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level  # noqa: E402

from nlsid.citations import BOOK, SOURCES  # noqa: E402
from nlsid.cli.main import cli  # noqa: E402
from nlsid.diagnose.result import versus_floor  # noqa: E402
from nlsid.diagnose.gain import Score  # noqa: E402
from nlsid.io.bla_file import read_units  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402
from nlsid.io.units import common_units  # noqa: E402
from nlsid.report.html import Page, render_html  # noqa: E402
from nlsid.report.diagnosis_plots import model_vs_bla  # noqa: E402
from nlsid.report.render import render  # noqa: E402
from nlsid.report.render_diagnosis import floor_text  # noqa: E402
from nlsid.report.units import Units  # noqa: E402
from nlsid.report.vector import band, figure, figure_csv, new_figure  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
INTERNAL = re.compile(r"\bseed[ -]?0\d\d\b|\bbook\b", re.I)


def csv_links(page: str) -> list[dict[str, np.ndarray]]:
    """Each figure's CSV, from its data: URL, as header -> column (empty cells NaN, padding dropped)."""
    out = []
    for url in re.findall(r'href="data:text/csv;charset=utf-8,([^"]*)"', page):
        header, *rows = list(csv.reader(io.StringIO(urllib.parse.unquote(url))))
        columns = {}
        for i, name in enumerate(header):
            cells = [row[i] for row in rows]
            while cells and cells[-1] == "":
                cells.pop()
            columns[name] = np.array([float(c) if c else np.nan for c in cells])
        out.append(columns)
    return out


def test_csv_holds_what_the_figure_draws():
    """Shared x once, a band as its two edges, NaN as an empty cell, a marker line across the axes left out."""
    drawn, (top, bottom) = new_figure(2)
    x = np.array([1.0, 2.0, 4.0])
    top.plot(x, [1.0, np.nan, 3.0], label="a")
    top.plot(x, [4.0, 5.0, 6.0], label="b")
    top.axvline(2.0, label="marker")
    top.set_xlabel("frequency (Hz)")
    top.set_ylabel("level (dB re 1 V)")
    band(bottom, [0.0, 1.0], [-1.0, -2.0], [1.0, 2.0], "bounds")
    bottom.plot([0.5], [0.25], "x", label="point")
    bottom.set_xlabel("time (s)")
    bottom.set_ylabel("error (V)")
    rows = list(csv.reader(io.StringIO(figure_csv(drawn))))
    assert rows[0] == ["frequency (Hz)", "a: level (dB re 1 V)", "b: level (dB re 1 V)", "point: time (s)",
                       "point: error (V)", "bounds: time (s)", "bounds, lower: error (V)", "bounds, upper: error (V)"]
    assert rows[1:] == [["1", "1", "4", "0.5", "0.25", "0", "-1", "1"],
                        ["2", "", "5", "", "", "1", "-2", "2"],
                        ["4", "3", "6", "", "", "", "", ""]]


def test_model_page_data_is_the_frequency_response_of_theory():
    """configs/model_resonance.yaml: G(s) = 100 (s + 36) / (s^2 + 36 s + 3600) e^{-0.002 s}."""
    page = render_html(render(ROOT / "configs" / "model_resonance.yaml"), "test")
    (data,) = csv_links(page)
    f = data["linear plant: frequency (Hz)"]
    s = 2j * np.pi * f
    G = 100 * (s + 36) / (s**2 + 36 * s + 3600) * np.exp(-0.002 * s)
    magnitude = next(v for k, v in data.items() if k.startswith("linear plant: magnitude"))
    np.testing.assert_allclose(magnitude, 20 * np.log10(np.abs(G)), rtol=1e-6, atol=1e-5)
    phase = data["linear plant: phase (deg)"]
    np.testing.assert_allclose(np.radians(phase) % (2 * np.pi), np.angle(G) % (2 * np.pi), atol=1e-5)
    assert f.size == 400 and f.min() > 0


def test_diagnosis_figure_data_is_the_bla_it_was_drawn_from():
    rng = np.random.default_rng(1)
    f = np.linspace(1.0, 60.0, 40)
    G = rng.normal(size=40) + 1j * rng.normal(size=40)
    level = {"frequency": f, "G": G, "G_model": 1.1 * G, "radius": 0.1 * np.abs(G),
             "outside": (np.arange(40) % 3 == 0).astype(np.int8)}
    data = csv_links(render_html(_page_of(model_vs_bla(level, Units({"u": "N", "y": "m"}))), "test"))[0]
    assert "measured BLA: |G| (dB re 1 m/N)" in data and "phase (deg)" not in data
    np.testing.assert_allclose(data["measured BLA: frequency (Hz)"], f, rtol=1e-6)
    np.testing.assert_allclose(data["measured BLA: |G| (dB re 1 m/N)"], 20 * np.log10(np.abs(G)), rtol=1e-6)
    np.testing.assert_allclose(data["model outside bounds: frequency (Hz)"], f[::3], rtol=1e-6)
    np.testing.assert_allclose(data["BLA 95% bounds, upper: |G| (dB re 1 m/N)"], 20 * np.log10(1.1 * np.abs(G)),
                               rtol=1e-6)
    np.testing.assert_allclose(data["frequency (Hz)"], f, rtol=1e-6)  # the phase panel: both curves share x
    np.testing.assert_allclose(np.radians(data["model: phase (deg)"]) % (2 * np.pi), np.angle(1.1 * G) % (2 * np.pi),
                               atol=1e-5)


def _page_of(mpl_figure):
    return Page(kind="Test", title="t", source="s", headline="h", findings=[],
                figures=[figure(mpl_figure, "Caption. More.", "test")])


@pytest.mark.parametrize("units, expected", [
    ({"u": "N", "y": "m"}, "dB re 1 m/N"),
    ({"u": "V", "y": "V"}, "dB re 1 V/V"),
    ({"u": "N"}, "dB re 1 y/N, unit of y not recorded"),
    ({}, "dB re 1 y/u, units of u and y not recorded"),
])
def test_a_level_in_db_names_its_reference(units, expected):
    assert Units(units).ratio_db("y", "u") == expected
    assert Units(units).ratio("y", "y") == f"{units.get('y', 'y')}/{units.get('y', 'y')}"  # like units cancel
    assert Units(units).label("u rms", "u") == f"u rms ({units.get('u', 'unit not recorded')})"


def _user_strings(path: Path) -> list[tuple[int, str]]:
    """String constants of a module that are not docstrings (messages, help, captions, table text)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings]


def test_no_message_help_or_caption_cites_an_internal_label():
    """Docstrings may cite the source files (seed 000, book); what a user reads may not."""
    found = [f"{path.relative_to(ROOT)}:{line}: {text[:80]!r}" for folder in ("nlsid", "cli")
             for path in sorted((ROOT / folder).rglob("*.py")) for line, text in _user_strings(path)
             if INTERNAL.search(text)]
    assert found == []


def test_no_command_help_cites_an_internal_label(run_cli):
    for name in cli.commands:
        result = run_cli(name, "--help")
        assert result.exit_code == 0 and not INTERNAL.search(result.stdout), (name, INTERNAL.findall(result.stdout))


def test_a_page_lists_the_full_reference_of_what_it_cites():
    page = render_html(render(ROOT / "configs" / "model_resonance.yaml"), "test")
    assert "References" not in page  # the model page cites nothing
    text = render_html(Page(kind="k", title="t", source="s", headline=f"bounds ({BOOK}, Ex. 92)", findings=[]), "test")
    assert not INTERNAL.search(text)
    assert re.search(r'<ol class="references" id="references"><li>J. Schoukens, R. Pintelon and Y. Rolain, '
                     r'Mastering System Identification in 100 Exercises', text)
    assert text.count("<li>") == 1 and SOURCES[BOOK] in html.unescape(text)



@pytest.mark.parametrize("above", [-0.22, 0.04, 56.7, -3.0])
def test_the_table_states_the_distance_to_the_floor_as_the_verdict(above):
    """The verdict's "0.2 dB below the noise floor" and the table's cell read alike, sign and rounding."""
    score = Score(error_rms=1.0, noise_rms=1.0, gain_db=3.0, above_floor_db=above, distortion_explained=0.5,
                  distortion_gain_db=3.0, p_above_noise=0.9)
    assert versus_floor(score) == f"{floor_text(score.summary())} the noise floor"


def test_units_are_those_every_run_records_alike():
    assert common_units([{"u": "N", "y": "m"}, {"u": "N"}]) == {"u": "N"}  # one run without a unit of y
    assert common_units([{"u": "N"}, {"u": "V"}]) == {}  # runs that disagree
    assert common_units([]) == {}


def test_bla_keeps_the_recording_units_for_its_page(run_cli, tmp_path):
    rng = np.random.default_rng(2)
    B, A = signal.butter(2, 0.25)
    runs = runs_of_level(2, 256, odd_random_bins(1, 81, 3, rng), 1.0, lambda u: signal.lfilter(B, A, u), 2, rng,
                         fs=1000.0, noise_y=0.01, level=1.0)
    for run in runs:
        run.units = {"u": "V", "y": "m"}
    write_recording(tmp_path / "rec.h5", runs, provenance={})
    assert run_cli("bla", tmp_path / "rec.h5", "-o", tmp_path / "bla.h5").exit_code == 0
    assert read_units(tmp_path / "bla.h5") == {"u": "V", "y": "m"}
    result = run_cli("report", tmp_path / "bla.h5", "-o", tmp_path / "bla.html", "--json")
    assert result.exit_code == 0 and result.json()["numbers"]["units"] == {"u": "V", "y": "m"}
    page = (tmp_path / "bla.html").read_text(encoding="utf-8")
    assert "dB re 1 m/V" in page and "u rms (V)" in page and "not recorded" not in page
