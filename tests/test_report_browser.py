"""`nlsid report` pages opened in a real headless browser (Debian's chromium, installed by .ci/run).

The page itself has no script. The test loads a copy with a small probe script in its head that
records error events (script errors and failed resource loads, captured on window) and, after the
load event, writes into the DOM the decoded size of every image, the layout box of the verdict and
its rendered text; chromium's --dump-dom prints the DOM after the load. Without chromium the test
skips, except in CI (CI=true), where it fails.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

sys.path.insert(0, str(Path(__file__).parent))
from bla_cases import odd_random_bins, runs_of_level  # noqa: E402

from nlsid.io.recording import write_recording  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

if CHROMIUM is None:
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("chromium is missing in CI: .ci/run installs it (apt-get install chromium)", pytrace=False)
    pytest.skip("no chromium on PATH: report pages are checked in a headless browser (apt-get install chromium, "
                "as .ci/run does)", allow_module_level=True)

PROBE = """<script>
var errors = [];
window.addEventListener('error', function (e) {
  errors.push(String(e.message || (e.target && (e.target.src || e.target.href)) || 'error').slice(0, 80)); }, true);
window.addEventListener('load', function () {
  var images = Array.prototype.map.call(document.images, function (img) {
    var r = img.getBoundingClientRect();
    return {natural_width: img.naturalWidth, width: r.width, height: r.height}; });
  var v = document.getElementById('verdict'), r = v.getBoundingClientRect(), s = getComputedStyle(v);
  var out = document.createElement('pre'); out.id = 'probe';
  out.textContent = JSON.stringify({errors: errors, images: images, scripts: document.scripts.length,
    verdict: {text: v.innerText, top: r.top, height: r.height, visibility: s.visibility, display: s.display}});
  document.body.appendChild(out); });
</script>"""


def browse(page: Path, tmp_path: Path) -> dict:
    """Load ``page`` with the probe in headless chromium; return what the probe saw."""
    probed = tmp_path / f"probe_{page.name}"
    probed.write_text(page.read_text(encoding="utf-8").replace("<head>", "<head>" + PROBE, 1), encoding="utf-8")
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run",
               f"--user-data-dir={tmp_path / 'chromium-profile'}", "--window-size=1100,900",
               "--virtual-time-budget=5000", "--dump-dom", probed.resolve().as_uri()]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert found, f"the probe did not run (exit {done.returncode}): {done.stderr[-500:]}"
    return json.loads(html.unescape(found.group(1)))


@pytest.fixture(scope="module")
def bla_page(tmp_path_factory):
    """A bla.h5 report of a Wiener system with a cubic (two levels, 4 realizations, 3 periods)."""
    folder = tmp_path_factory.mktemp("browser")
    B, A = signal.butter(2, 0.25)
    rng = np.random.default_rng(5)
    bins = odd_random_bins(1, 161, 3, rng)
    runs = []
    for level in (0.5, 1.0):
        for run in runs_of_level(4, 512, bins, level, lambda u: (lambda x: x + 0.2 * x**3)(signal.lfilter(B, A, u)),
                                 3, rng, fs=1000.0, noise_y=0.01, level=level):
            run.run_id = f"L{level:g}_{run.run_id}"
            runs.append(run)
    write_recording(folder / "rec.h5", runs, provenance={"tool": "test"})
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    for args in (["bla", folder / "rec.h5", "-o", folder / "bla.h5"],
                 ["report", folder / "bla.h5", "-o", folder / "report.html"]):
        result = CliRunner().invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    return folder / "report.html"


def assert_verdict_first_and_figures_shown(seen: dict, verdict_start: str, figures: int) -> None:
    """What ``browse`` saw: no error, no script but the probe, the verdict laid out, visible and inside
    the first screen (900 px), starting with ``verdict_start``, and ``figures`` images decoded and shown."""
    assert seen["errors"] == []
    assert seen["scripts"] == 1  # the probe only: the page itself has no script
    verdict = seen["verdict"]
    assert verdict["visibility"] == "visible" and verdict["display"] != "none"
    assert verdict["height"] > 20 and 0 <= verdict["top"] < 900
    assert verdict["text"].startswith(verdict_start)
    assert len(seen["images"]) == figures
    for image in seen["images"]:
        assert image["natural_width"] > 0 and image["width"] > 100 and image["height"] > 100


def test_page_renders_with_verdict_and_figures_visible(bla_page, tmp_path):
    # bla_vs_level, then spectrum and BLA of each of the two levels: five figures.
    assert_verdict_first_and_figures_shown(browse(bla_page, tmp_path), "Odd nonlinear distortion", 5)


def test_probe_sees_a_broken_figure(bla_page, tmp_path):
    """The check can fail: a figure whose PNG is corrupt decodes to width 0 and raises an error event."""
    text = bla_page.read_text(encoding="utf-8")
    broken = tmp_path / "broken.html"
    broken.write_text(re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "data:image/png;base64,AAAA", text, count=1),
                      encoding="utf-8")
    seen = browse(broken, tmp_path)
    assert seen["images"][0]["natural_width"] == 0
    assert seen["errors"]
