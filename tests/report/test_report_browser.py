"""`nlsid report` pages opened in a real headless browser (Debian's chromium, installed by .ci/run).

The page itself has no script. The test loads a copy with a small probe script in its head that
records error events (script errors and failed resource loads, captured on window) and, after the
load event, writes into the DOM what a reader would see: the page's scroll width against the
window's, every element that reaches past the right edge of the text column, the rendered size
and the axis labels (SVG text) of every figure, the verdict's layout box and text, and the text of
every table and whether it fits the text column or scrolls in a box of its own; chromium's
--dump-dom prints the DOM after the load. Each page is rendered once per module and opened once per
window width (1280 px, a laptop, and 2400 px, a wide screen); in the 1280 px window the probe also
lays the page out in a frame 800 px wide (a small laptop, a tablet: its own viewport, so the page's
CSS sees 800 px) and measures it the same way, which costs no further start of chromium. Without
chromium the test skips, except in CI (CI=true), where it fails.
"""

from __future__ import annotations

import html
import importlib.util
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level  # noqa: E402

from nlsid.io.bla_file import read_bla  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

if CHROMIUM is None:
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("chromium is missing in CI: .ci/run installs it (apt-get install chromium)", pytrace=False)
    pytest.skip("no chromium on PATH: report pages are checked in a headless browser (apt-get install chromium, "
                "as .ci/run does)", allow_module_level=True)

WIDTHS = (1280, 2400)  # a window of chromium each
NARROW = 800  # a frame in the 1280 px window (browse(narrow=)): a small laptop or a tablet
ALL_WIDTHS = (NARROW, *WIDTHS)
CONFIGS = Path(__file__).resolve().parents[2] / "configs"

PROBE = """<script>
var errors = [];
window.addEventListener('error', function (e) {
  errors.push(String(e.message || (e.target && (e.target.src || e.target.href)) || 'error').slice(0, 80)); }, true);
function measure(win) {
  var doc = win.document, main = doc.querySelector('main'), style = win.getComputedStyle(main);
  var right = main.getBoundingClientRect().right - parseFloat(style.paddingRight) + 1;
  function scroller(el) {  // the nearest box between el and main that scrolls sideways, or null
    for (var p = el.parentElement; p && p !== main; p = p.parentElement) {
      if (/auto|scroll/.test(win.getComputedStyle(p).overflowX)) return p; }
    return null;
  }
  var overflowing = [];
  Array.prototype.forEach.call(main.querySelectorAll('*'), function (el) {
    if (el.closest('svg') && el.tagName.toLowerCase() !== 'svg') return;
    if (scroller(el)) return;  // clipped by its own box, which is checked itself
    var r = el.getBoundingClientRect();
    if (r.width > 0 && r.right > right) overflowing.push(el.tagName + ': ' + (el.textContent || '').slice(0, 60));
  });
  var figures = Array.prototype.map.call(doc.querySelectorAll('figure svg'), function (svg) {
    var r = svg.getBoundingClientRect();
    var labels = Array.prototype.map.call(svg.querySelectorAll('[id$="-x-label"], [id$="-y-label"]'),
      function (g) { return {id: g.id, text: g.textContent.replace(/\\s+/g, ' ').trim()}; });
    return {width: r.width, height: r.height, right: r.right, axes: svg.querySelectorAll('g[id*="-axes_"]').length,
            labels: labels, texts: svg.querySelectorAll('text').length, images: svg.querySelectorAll('image').length,
            visibility: win.getComputedStyle(svg).visibility};
  });
  var tables = Array.prototype.map.call(doc.querySelectorAll('table'), function (t) {
    var box = scroller(t), r = t.getBoundingClientRect();
    return {caption: t.caption ? t.caption.innerText : '', rows: Array.prototype.map.call(t.rows, function (row) {
      return Array.prototype.map.call(row.cells, function (c) { return c.innerText; }); }),
      fits: r.right <= right, box_fits: box ? box.getBoundingClientRect().right <= right : null,
      box_scrolls: box ? box.scrollWidth > box.clientWidth : null};
  });
  var v = doc.getElementById('verdict'), r = v.getBoundingClientRect(), s = win.getComputedStyle(v);
  return {scroll_width: doc.documentElement.scrollWidth, scrolling_width: doc.scrollingElement.scrollWidth,
    inner_width: win.innerWidth, text_right: right, overflowing: overflowing.slice(0, 10), figures: figures,
    tables: tables, verdict: {text: v.innerText, top: r.top, height: r.height, visibility: s.visibility,
                              display: s.display}};
}
window.addEventListener('load', function () {
  if (window.top !== window) return;  // the page again, in the narrow frame below
  var source = '<!DOCTYPE html>' + document.documentElement.outerHTML;
  var seen = measure(window);
  seen.errors = errors; seen.scripts = document.scripts.length;
  function report() {
    var out = document.createElement('pre'); out.id = 'probe';
    out.textContent = JSON.stringify(seen);
    document.body.appendChild(out);
  }
  if (!NARROW) { report(); return; }
  // the same page in a frame NARROW px wide: its own viewport (window.innerWidth, media queries),
  // laid out in this browser, so that a second width costs no second start of chromium
  var frame = document.createElement('iframe');
  frame.style.cssText = 'position: absolute; left: -20000px; top: 0; border: 0; width: ' + NARROW + 'px; height: 900px';
  frame.addEventListener('load', function () { seen.narrow = measure(frame.contentWindow); report(); });
  frame.srcdoc = source;
  document.body.appendChild(frame);
});
</script>"""

#: an axis label ends with its unit in parentheses; a level in dB names its reference
UNIT = re.compile(r"\([^()]+\)$")


def browse(page: Path, tmp_path: Path, width: int = 1280, narrow: int | None = None) -> dict:
    """Load ``page`` with the probe in headless chromium, ``width`` px wide; return what the probe saw.
    With ``narrow``, also what it saw of the page in a frame of that width (key ``narrow``)."""
    probed = tmp_path / f"probe_{width}_{page.name}"
    probe = PROBE.replace("NARROW", str(narrow or 0))
    probed.write_text(page.read_text(encoding="utf-8").replace("<head>", "<head>" + probe, 1), encoding="utf-8")
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars",
               f"--user-data-dir={tmp_path / 'chromium-profile'}", f"--window-size={width},900",
               "--virtual-time-budget=5000", "--dump-dom", probed.resolve().as_uri()]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert found, f"the probe did not run (exit {done.returncode}): {done.stderr[-500:]}"
    return json.loads(html.unescape(found.group(1)))


def assert_verdict_first_and_figures_shown(seen: dict, verdict_start: str, figures: int) -> None:
    """What ``browse`` saw: no error, no script but the probe, the verdict laid out, visible and inside
    the first screen (900 px), starting with ``verdict_start``, and ``figures`` figures drawn with a size,
    visible and inside the text column. (A narrow frame's view has no errors or scripts of its own.)"""
    assert seen.get("errors", []) == []
    assert seen.get("scripts", 1) == 1  # the probe only: the page itself has no script
    verdict = seen["verdict"]
    assert verdict["visibility"] == "visible" and verdict["display"] != "none"
    assert verdict["height"] > 20 and 0 <= verdict["top"] < 900
    assert verdict["text"].startswith(verdict_start)
    assert len(seen["figures"]) == figures
    for figure in seen["figures"]:
        assert figure["width"] > 100 and figure["height"] > 100
        assert figure["visibility"] == "visible" and figure["right"] <= seen["text_right"], figure["labels"]


def assert_fits_the_window(seen: dict) -> None:
    """Nothing wider than the window, no element past the text column's right edge; a table wider
    than the column scrolls sideways in a box of its own that fits it."""
    assert seen["scroll_width"] <= seen["inner_width"], seen["overflowing"]
    assert seen["scrolling_width"] <= seen["inner_width"] + 1, seen["overflowing"]
    assert seen["overflowing"] == []
    for table in seen["tables"]:
        assert table["fits"] or table["box_fits"], (table["caption"], table["rows"][:1])


def assert_axes_labelled_with_units(seen: dict) -> None:
    """Every axis of every figure has a label (SVG text, so searchable) ending in its unit; dB has a reference."""
    for figure in seen["figures"]:
        assert figure["texts"] > 10  # ticks, labels and legends are text, not paths
        assert len(figure["labels"]) == 2 * figure["axes"] > 0, figure["labels"]
        for label in figure["labels"]:
            assert UNIT.search(label["text"]), label
            assert "dB" not in label["text"] or "dB re" in label["text"], label


def verdict_headline(seen: dict) -> str:
    return seen["verdict"]["text"].splitlines()[0]


def _report(args: list, folder: Path) -> dict:
    """Run ``nlsid`` with ``args`` in-process (CliRunner); the --json summary when asked for."""
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout) if "--json" in args else {}


# one worker runs the module: its module fixture is built once (xdist --dist loadgroup)
pytestmark = pytest.mark.xdist_group("report_browser")


@pytest.fixture(scope="module")
def bla_page(tmp_path_factory):
    """A bla.h5 report of a Wiener system with a cubic (two levels, 4 realizations, 3 periods), u and y in V."""
    folder = tmp_path_factory.mktemp("browser")
    B, A = signal.butter(2, 0.25)
    rng = np.random.default_rng(5)
    bins = odd_random_bins(1, 161, 3, rng)
    runs = []
    for level in (0.5, 1.0):
        for run in runs_of_level(4, 512, bins, level, lambda u: (lambda x: x + 0.2 * x**3)(signal.lfilter(B, A, u)),
                                 3, rng, fs=1000.0, noise_y=0.01, level=level):
            run.run_id = f"L{level:g}_{run.run_id}"
            run.units = {"u": "V", "y": "V"}
            runs.append(run)
    write_recording(folder / "rec.h5", runs, provenance={"tool": "test"})
    _report(["bla", folder / "rec.h5", "-o", folder / "bla.h5"], folder)
    _report(["report", folder / "bla.h5", "-o", folder / "report.html"], folder)
    return folder / "report.html"


@pytest.fixture(scope="module")
def hosidf_page(tmp_path_factory):
    """A hosidf.h5 report of the two-branch LPL system of tests/analysis/test_hosidf.py, u in N and y in m."""
    spec = importlib.util.spec_from_file_location("test_hosidf", Path(__file__).resolve().parents[1] / "analysis" / "test_hosidf.py")
    cases = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cases)
    folder = tmp_path_factory.mktemp("browser_hosidf")
    runs = [cases.sine_run(f"f{line}_a{a}_r{r}", line, a, cases.two_branch) for line in (2, 7) for a in (0.5, 1.2)
            for r in range(2)]
    for run in runs:
        run.units = {"u": "N", "y": "m"}
    write_recording(folder / "lpl.h5", runs, provenance={})
    _report(["hosidf", folder / "lpl.h5", "-o", folder / "hosidf.h5", "--harmonics", "4"], folder)
    summary = _report(["report", folder / "hosidf.h5", "-o", folder / "hosidf.html", "--json"], folder)
    return folder / "hosidf.html", summary


@pytest.fixture(scope="module")
def model_page(tmp_path_factory):
    """The page of configs/model_resonance.yaml (s^2 + 36 s + 3600: 9.55 Hz, zeta 0.3)."""
    folder = tmp_path_factory.mktemp("browser_model")
    summary = _report(["report", CONFIGS / "model_resonance.yaml", "-o", folder / "model.html", "--json"], folder)
    return folder / "model.html", summary


@pytest.fixture(scope="module")
def seen(bla_page, hosidf_page, model_page, tmp_path_factory):
    """What the probe saw of each page kind at each window width."""
    folder = tmp_path_factory.mktemp("probe")
    pages = {"bla": bla_page, "hosidf": hosidf_page[0], "model": model_page[0]}
    return seen_at_every_width(pages, folder)


def seen_at_every_width(pages: dict, folder: Path) -> dict:
    """What the probe saw of each page at each of ALL_WIDTHS, keyed (name, width): a window per
    width of WIDTHS, the narrow width a frame inside the first window."""
    seen = {}
    for name, page in pages.items():
        for width in WIDTHS:
            seen[name, width] = browse(page, folder, width, NARROW if width == WIDTHS[0] else None)
        seen[name, NARROW] = seen[name, WIDTHS[0]].pop("narrow")
    return seen


@pytest.mark.parametrize("kind, figures, verdict", [("bla", 5, "Odd nonlinear distortion"),
                                                    ("hosidf", 3, "Harmonics above their noise bound"),
                                                    ("model", 1, "Transfer function in open loop")])
def test_page_renders_with_verdict_and_figures_visible(seen, kind, figures, verdict):
    # bla: bla_vs_level, then spectrum and BLA of each of the two levels; hosidf: the H_1 map and one
    # figure per frequency; model: one Bode plot.
    for width in ALL_WIDTHS:
        assert_verdict_first_and_figures_shown(seen[kind, width], verdict, figures)


@pytest.mark.parametrize("kind", ["bla", "hosidf", "model"])
@pytest.mark.parametrize("width", ALL_WIDTHS)
def test_nothing_overflows_the_window(seen, kind, width):
    assert_fits_the_window(seen[kind, width])


@pytest.mark.parametrize("kind", ["bla", "hosidf", "model"])
def test_every_axis_is_labelled_with_its_unit(seen, kind):
    assert_axes_labelled_with_units(seen[kind, 1280])


def test_units_come_from_the_recording(seen):
    """u and y in V: the BLA is in dB re 1 V/V (a ratio of like units); u in N and y in m: H_1 in m/N."""
    bla_labels = [label["text"] for figure in seen["bla", 1280]["figures"] for label in figure["labels"]]
    assert any("dB re 1 V/V" in text for text in bla_labels) and any("u rms (V)" in text for text in bla_labels)
    assert not any("not recorded" in text for text in bla_labels)
    hosidf_labels = [label["text"] for figure in seen["hosidf", 1280]["figures"] for label in figure["labels"]]
    assert "|H_1| (m/N)" in hosidf_labels and any("amplitude (N)" in text for text in hosidf_labels)
    model_labels = [label["text"] for figure in seen["model", 1280]["figures"] for label in figure["labels"]]
    assert any("units not recorded" in text for text in model_labels)  # a config records no units


def test_verdict_numbers_are_the_summary_numbers(seen, bla_page, hosidf_page, model_page):
    # bla: the headline from the file's own numbers, read independently, at the highest level
    stored = read_bla(bla_page.parent / "bla.h5")
    spectrum = stored["levels"][-1]["attrs"]["summary"]["spectrum"]
    rows = stored["attrs"]["across_levels"]["levels"]
    assert verdict_headline(seen["bla", 1280]) == (
        f"Odd nonlinear distortion {spectrum['odd_above_even_db']:.0f} dB above even, "
        f"{spectrum['odd_above_noise_db']:.0f} dB above the noise; BLA changes by up to "
        f"{rows[1]['bla_change_max_db']:+.1f} dB over 2 levels "
        f"(u rms {rows[0]['u_rms']:.3g} to {rows[1]['u_rms']:.3g} V)")
    # hosidf: the largest |H_1| change of the --json summary
    changes = hosidf_page[1]["numbers"]["grid"]["h1_change"]
    worst = max(changes, key=lambda row: abs(row["change_db"]))
    assert (f"|H_1| changes by up to {worst['change_db']:+.2f} dB from amplitude {worst['from_level']:g} to "
            f"{worst['to_level']:g} N") in verdict_headline(seen["hosidf", 1280])
    # model: the mode of the --json summary, as in the modes table
    (mode,) = model_page[1]["numbers"]["elements"][0]["modes"]
    assert f"mode {mode['frequency']:.3g} Hz (ζ {mode['damping']:.2g})" in verdict_headline(seen["model", 1280])
    (modes,) = [t for t in seen["model", 1280]["tables"] if t["caption"] == "Modes of the LTI elements"]
    assert modes["rows"][1][1] == f"{mode['frequency']:.4g} Hz"


def test_probe_sees_overflow_and_an_empty_figure(bla_page, tmp_path):
    """The checks can fail: a figure of zero size, an element wider than the window and a table
    wider than the text column outside a box of its own are seen; the same table in a scroll box
    is not counted as overflowing."""
    text = bla_page.read_text(encoding="utf-8")
    text = re.sub(r'(<svg [^>]*?) width="[^"]*" height="[^"]*"', r'\1 width="0" height="0"', text, count=1)
    broken = tmp_path / "broken.html"
    wide_table = '<table><caption>{}</caption><tr><td style="min-width: 1200px">cell</td></tr></table>'
    broken.write_text(text.replace("</header>", '</header><div style="width: 3000px">wide</div>'
                                   + wide_table.format("loose") + '<div class="scroll">' + wide_table.format("boxed")
                                   + "</div>", 1), encoding="utf-8")
    seen = browse(broken, tmp_path)
    assert seen["figures"][0]["width"] <= 2  # its border only
    assert seen["scroll_width"] > seen["inner_width"] and any("wide" in item for item in seen["overflowing"])
    tables = {t["caption"]: t for t in seen["tables"]}
    assert not tables["loose"]["fits"] and tables["loose"]["box_fits"] is None
    assert any(item.startswith("TABLE: loose") for item in seen["overflowing"])
    assert not tables["boxed"]["fits"] and tables["boxed"]["box_fits"] and tables["boxed"]["box_scrolls"]
    assert not any(item.startswith("TABLE: boxed") for item in seen["overflowing"])


def test_the_fleet_page_fits_1280_and_800_px(tmp_path):
    """The batch's fleet page (its results table is wide: a column per field) on two machines, one of
    them drifting, with long recording names: at 1280 px and in the 800 px frame nothing passes the
    window or the text column, each table fits or scrolls in its own box, and the drift figure is
    drawn inside the column with its unit on the axis. (The page has a script of its own, its
    table sorter, so the scripts are not counted.)"""
    from nlsid.cli.fleet.fleet_page import render_page
    from nlsid.cli.fleet.results import drift

    rows = []
    for machine, slope in (("stage-north-bay-07", 0.0), ("stage-south-bay-12", 0.02)):
        for day in range(6):
            name = f"{machine}_2026-03-{day + 1:02d}_shift-a_run-0001_with_a_long_name"
            fc = {"value": 0.5 + slope * day + 0.001 * (-1) ** day, "std": 0.002, "unit": "N"}
            rows.append({"name": name, "recording": f"{name}.h5", "machine": machine,
                         "recorded": f"2026-03-{day + 1:02d}T08:00:00+00:00", "recorded_from": "attribute",
                         "status": "ok", "run": "ran", "verdict": "explained",
                         "causes": [{"name": "coulomb", "title": "Coulomb friction"}],
                         "parameters": {"coulomb.fc": fc}, "gain_db": 31.2, "above_floor_db": 0.4,
                         "floor_of": "y", "seconds": 12.5, "error": None, "headline": None, "output": name})
    summary = {"ran": 12, "up_to_date": 0, "output": "fleet", "pipeline": "pipeline.yaml",
               "executor": "2 local processes", "version": "test"}
    page = tmp_path / "fleet.html"
    page.write_text(render_page(rows, summary, "coulomb.fc", drift(rows, "coulomb.fc"),
                                {"coulomb": "Coulomb friction"}), encoding="utf-8")
    seen = browse(page, tmp_path, WIDTHS[0], NARROW)
    for view in (seen, seen.pop("narrow")):
        assert view.get("errors", []) == []
        assert_fits_the_window(view)
        assert len(view["tables"]) == 3 and len(view["figures"]) == 1
        figure = view["figures"][0]
        assert figure["width"] > 100 and figure["right"] <= view["text_right"]
        assert any(label["text"].endswith("(N)") for label in figure["labels"]), figure["labels"]
