"""The report page of a ``bla.h5`` holding a 2 x 2 frequency response matrix, opened in headless chromium.

The recording is written here: two orthogonal multisine inputs u, u2 in N (``nlsid.design`` with
``inputs: 2``) drive first-order filters (scipy ``lfilter``, independent of nlsid's simulator) to
outputs y and y2 in m/s^2, with white output noise; y2 then passes a cubic, y does not. ``nlsid bla``
measures the FRM and ``nlsid report`` draws it; the page is loaded once with the probe of
:mod:`test_report_browser` in a 1280 px window, with the 800 px frame inside it.

Theory for the verdict: a linear path has no stochastic nonlinear distortion, so the total variance
of the entries to y is the noise variance (their band means agree within the 3 dB threshold: a
band mean over L = 14 lines of a variance with 2 (M - 1) = 6 degrees of freedom per line scatters
by 1/sqrt(L (M - 1)) = 0.15, about 0.7 dB); the cubic on y2 adds a nonlinear variance of the
order of (0.3 |x|^2)^2, 50 dB above the noise of 1e-3.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from scipy import signal

import nlsid
from report.test_report_browser import (  # noqa: E402  (skips without chromium, fails in CI)
    NARROW, WIDTHS, _report, assert_axes_labelled_with_units, assert_fits_the_window,
    assert_verdict_first_and_figures_shown, browse)

FILTERS = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (0, 1): ([0.2], [1.0, -0.5]),
           (1, 0): ([0.0, 0.4], [1.0]), (1, 1): ([1.0], [1.0, 0.2])}
UNITS = {"u": "N", "u2": "N", "y": "m/s^2", "y2": "m/s^2"}

pytestmark = pytest.mark.xdist_group("frm_browser")


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """The FRM page, its --json summary, and what the probe saw at 1280 px and in the 800 px frame."""
    folder = tmp_path_factory.mktemp("frm_page")
    excitation = nlsid.design({"fs": 100.0, "seed": 3, "multisine": {
        "period": 64, "band": [1.0, 45.0], "lines": "odd", "realizations": 4, "periods": 2, "transient_periods": 1,
        "rms_levels": [1.0], "inputs": 2}})
    rng = np.random.default_rng(0)
    runs = []
    for run in excitation.runs:
        U = run.input_matrix()
        Y = np.zeros((2, U.shape[1]))
        for (i, a), (b, den) in FILTERS.items():
            Y[i] += signal.lfilter(b, den, U[a])
        Y[1] += 0.3 * Y[1] ** 3
        Y += 1e-3 * rng.standard_normal(Y.shape)
        runs.append(dataclasses.replace(run, y=Y[0], channels={**run.channels, "y2": Y[1]}, outputs=("y", "y2"),
                                        units=UNITS))
    nlsid.Recording(runs, {}, None).write(folder / "rec.h5")
    _report(["bla", folder / "rec.h5", "-o", folder / "bla.h5"], folder)
    summary = _report(["report", folder / "bla.h5", "-o", folder / "frm.html", "--json"], folder)
    seen = browse(folder / "frm.html", folder, WIDTHS[0], NARROW)
    return folder / "frm.html", summary, {WIDTHS[0]: seen, NARROW: seen.pop("narrow")}


def test_frm_page_passes_the_page_checks_at_1280_and_800_px(page):
    _, _, seen = page
    for width, view in seen.items():
        assert_verdict_first_and_figures_shown(view, "Frequency response matrix of 2 outputs x 2 inputs", 1)
        assert_fits_the_window(view)
    assert_axes_labelled_with_units(seen[WIDTHS[0]])
    # a Bode plot per entry: magnitude and phase for each of the 2 x 2 entries
    assert seen[WIDTHS[0]]["figures"][0]["axes"] == 8


def test_entries_are_named_and_labelled_with_the_recording_units(page):
    path, _, seen = page
    labels = [label["text"] for label in seen[WIDTHS[0]]["figures"][0]["labels"]]
    assert labels.count("|G|, std (dB re 1 m/s^2/N)") == 4 and labels.count("phase (deg)") == 4
    assert labels.count("frequency (Hz)") == 8
    text = path.read_text(encoding="utf-8")
    for title in ("from u to y", "from u2 to y", "from u to y2", "from u2 to y2"):
        assert re.search(rf">{title}</text>", text), title  # each panel's title, as SVG text


def test_verdict_names_the_nonlinear_entries(page):
    _, summary, _ = page
    assert summary["headline"].endswith("stochastic nonlinear distortion above the noise from u to y2, "
                                        "from u2 to y2; none from u to y, from u2 to y")
    entries = {(row["input"], row["output"]): row for row in summary["numbers"]["frm_levels"][0]["entries"]}
    assert entries["u", "y2"]["total_var_db"] - entries["u", "y2"]["noise_var_db"] > 30
