"""The report page of a ``bla.h5`` holding 2 x 2 frequency response matrices, opened in headless chromium.

The recording is written here: two orthogonal multisine inputs u, u2 in N (``nlsid.design`` with
``inputs: 2``) drive first-order filters (scipy ``lfilter``, independent of nlsid's simulator) to
outputs y and y2 in m/s^2, with white output noise; y2 then passes a cubic, y does not. Two
records of white-noise inputs through the same filters (no cubic; arbitrary runs, started from
rest) give a second FRM level, by the Local Polynomial Method. ``nlsid bla`` measures both and
``nlsid report`` draws them; the page is loaded once with the probe of :mod:`test_report_browser`
in a 1280 px window, with the 800 px frame inside it.

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
from nlsid.io.bla_file import read_bla
from nlsid.io.run import Run
from report.test_report_browser import (  # noqa: E402  (skips without chromium, fails in CI)
    NARROW, WIDTHS, _report, assert_axes_labelled_with_units, assert_fits_the_window,
    assert_verdict_first_and_figures_shown, browse)
from report.test_report_data import csv_links  # noqa: E402

FILTERS = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (0, 1): ([0.2], [1.0, -0.5]),
           (1, 0): ([0.0, 0.4], [1.0]), (1, 1): ([1.0], [1.0, 0.2])}
UNITS = {"u": "N", "u2": "N", "y": "m/s^2", "y2": "m/s^2"}
ENTRIES = [(i, a) for i in range(2) for a in range(2)]
NAMES = (("y", "y2"), ("u", "u2"))


def respond(U: np.ndarray) -> np.ndarray:
    """The outputs (2, n) of the filters driven by the inputs U (2, n), from rest."""
    Y = np.zeros((2, U.shape[1]))
    for (i, a), (b, den) in FILTERS.items():
        Y[i] += signal.lfilter(b, den, U[a])
    return Y

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
        Y = respond(run.input_matrix())
        Y[1] += 0.3 * Y[1] ** 3
        Y += 1e-3 * rng.standard_normal(Y.shape)
        runs.append(dataclasses.replace(run, y=Y[0], channels={**run.channels, "y2": Y[1]}, outputs=("y", "y2"),
                                        units=UNITS))
    for m in range(2):  # q = M (2n + 1) - (R + 1)(n_u + M) = 2 with the default 7-line window
        U = rng.standard_normal((2, 256))
        Y = respond(U) + 1e-2 * rng.standard_normal(U.shape)
        runs.append(Run(f"noise{m}", 100.0, "arbitrary", U[0], y=Y[0], level=1.0, channels={"u2": U[1], "y2": Y[1]},
                        inputs=("u", "u2"), outputs=("y", "y2"), units=UNITS))
    nlsid.Recording(runs, {}, None).write(folder / "rec.h5")
    _report(["bla", folder / "rec.h5", "-o", folder / "bla.h5"], folder)
    summary = _report(["report", folder / "bla.h5", "-o", folder / "frm.html", "--json"], folder)
    seen = browse(folder / "frm.html", folder, WIDTHS[0], NARROW)
    return folder / "frm.html", summary, {WIDTHS[0]: seen, NARROW: seen.pop("narrow")}


def test_frm_page_passes_the_page_checks_at_1280_and_800_px(page):
    _, summary, seen = page
    assert summary["figures"] == ["frm_level_00", "frm_level_01"]  # multisine, then arbitrary runs
    for width, view in seen.items():
        assert_verdict_first_and_figures_shown(view, "Frequency response matrix of 2 outputs x 2 inputs", 2)
        assert_fits_the_window(view)
    assert_axes_labelled_with_units(seen[WIDTHS[0]])
    # a Bode plot per entry: magnitude and phase for each of the 2 x 2 entries
    assert [figure["axes"] for figure in seen[WIDTHS[0]]["figures"]] == [8, 8]


def test_entries_are_named_labelled_and_drawn_where_they_belong(page):
    path, _, seen = page
    for figure in seen[WIDTHS[0]]["figures"]:
        labels = [label["text"] for label in figure["labels"]]
        for i, a in ENTRIES:
            entry = f"{NAMES[1][a]} to {NAMES[0][i]}"
            assert labels.count(f"{entry}: |G|, std (dB re 1 m/s^2/N)") == 1 and f"{entry}: phase (deg)" in labels
        assert labels.count("frequency (Hz)") == 8
    text = path.read_text(encoding="utf-8")
    for title in ("from u to y", "from u2 to y", "from u to y2", "from u2 to y2"):
        assert len(re.findall(rf">{title}</text>", text)) == 2, title  # each panel's title, as SVG text
    # the figure data of each panel is the stored entry G[:, i, a] (from input a to output i)
    stored = read_bla(path.parent / "bla.h5")
    for columns, level in zip(csv_links(text), stored["frm_levels"] + stored["frm_lpm_levels"]):
        for i, a in ENTRIES:
            drawn = columns[f"|G|: {NAMES[1][a]} to {NAMES[0][i]}: |G|, std (dB re 1 m/s^2/N)"]
            np.testing.assert_allclose(drawn, 20 * np.log10(np.abs(level["G"][:, i, a])), rtol=1e-6, atol=1e-6)


def test_verdict_names_the_nonlinear_entries(page):
    _, summary, _ = page
    assert summary["headline"].startswith("Frequency response matrix of 2 outputs x 2 inputs over")
    assert summary["headline"].endswith("stochastic nonlinear distortion above the noise from u to y2, "
                                        "from u2 to y2; none from u to y, from u2 to y")
    entries = {(row["input"], row["output"]): row for row in summary["numbers"]["frm_levels"][0]["entries"]}
    assert entries["u", "y2"]["total_var_db"] - entries["u", "y2"]["noise_var_db"] > 30
    # the level of arbitrary runs: one variance, an upper bound of the noise, never a noise level
    (lpm,) = summary["numbers"]["frm_lpm_levels"]
    assert any(item.startswith("FRM level 1, level 1: Frequency response matrix of 2 outputs x 2 inputs of arbitrary "
                               "excitation by the Local Polynomial Method") and "an upper bound of the noise" in item
               for item in summary["findings"])
    assert lpm["lpm"]["dof"] == 2
