"""The diagnosis report page opened in a real headless browser (chromium, as in test_report_browser).

A diagnosis of a mass-spring-damper whose hidden Coulomb friction (100 N) the model lacks is run
through the CLI once per module and rendered by ``nlsid report``, as it is and with a ``chain`` of
causes added to its summary (the shape of ``docs/formats.md``); each page is loaded with the probe
of :mod:`test_report_browser` at 1280 and 2400 px, and in an 800 px frame inside the 1280 px window.
"""

from __future__ import annotations

import json
import shutil

import pytest

from diagnose.test_diagnose_cli import _setup  # noqa: E402
from report.test_report_browser import (  # noqa: E402  (skips without chromium, fails in CI)
    ALL_WIDTHS, _report, assert_axes_labelled_with_units, assert_fits_the_window, assert_verdict_first_and_figures_shown,
    seen_at_every_width, verdict_headline)

CHAIN = [{"cause": "coulomb", "title": "Coulomb friction", "values": {"fc": 99.2}, "std": {"fc": 0.4},
          "error_rms": 2.5e-6, "gain_db": 31.5, "above_floor_db": 4.26},
         {"cause": "cubic_stiffness", "title": "Cubic stiffness", "values": {"k3": 2.5e5}, "std": {"k3": 1.1e4},
          "error_rms": 1.6e-6, "gain_db": 4.0, "above_floor_db": -0.31}]


# one worker runs the module: its module fixture is built once (xdist --dist loadgroup)
pytestmark = pytest.mark.xdist_group("diagnose_browser")


@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory):
    """The diagnosis folder, its summary, and the probe's view of its page and of the chained page."""
    folder = tmp_path_factory.mktemp("diagnose_browser")
    model, rec = _setup(folder)
    out = folder / "diagnosis"
    _report(["diagnose", "--model", model, "--data", rec, "-o", out], folder)
    _report(["report", out, "-o", folder / "diagnosis.html"], folder)
    chained = folder / "chained"
    shutil.copytree(out, chained)
    summary = json.loads((out / "summary.json").read_text())
    (chained / "summary.json").write_text(json.dumps({**summary, "chain": CHAIN}))
    _report(["report", chained, "-o", folder / "chained.html"], folder)
    seen = seen_at_every_width({name: folder / f"{name}.html" for name in ("diagnosis", "chained")}, folder)
    return summary, seen


def test_diagnosis_page_renders_with_verdict_and_figures_visible(diagnosis):
    _, seen = diagnosis
    # model vs BLA, line spectrum, BLA vs level, residual vs state, before/after: five figures
    for width in ALL_WIDTHS:
        assert_verdict_first_and_figures_shown(seen["diagnosis", width], "Cause: Coulomb friction (fc = ", 5)


@pytest.mark.parametrize("name", ["diagnosis", "chained"])
@pytest.mark.parametrize("width", ALL_WIDTHS)
def test_nothing_overflows_the_window(diagnosis, name, width):
    assert_fits_the_window(diagnosis[1][name, width])


def test_every_axis_is_labelled_with_its_unit(diagnosis):
    assert_axes_labelled_with_units(diagnosis[1]["diagnosis", 1280])


def _table(seen: dict, caption: str) -> list[dict]:
    """The rows of the table ``caption`` as dicts keyed by its header."""
    (table,) = [t for t in seen["tables"] if t["caption"] == caption]
    header, *rows = table["rows"]
    return [dict(zip(header, row)) for row in rows]


def test_verdict_and_tables_state_the_summary_numbers_alike(diagnosis):
    summary, seen = diagnosis
    page = seen["diagnosis", 1280]
    gain = summary["gain"]
    floor = gain["extended_above_floor_db"]
    side = "below" if floor < 0 else "above"
    (winner,) = [h for h in summary["hypotheses"] if h["name"] == summary["verdict"]["winner"]]
    main = winner["main_parameter"]
    unit = f" {winner['unit']}" if winner["unit"] else ""  # none where the recording's units leave it unknown
    assert verdict_headline(page) == (
        f"Cause: {winner['title']} ({main} = {winner['values'][main]:.4g}{unit}); the extended model's "
        f"validation error is {gain['gain_db']:.1f} dB smaller, {abs(floor):.1f} dB {side} the noise floor")
    # the hypotheses table says the same, with the same sign convention, and the distortion as a dB change
    row = _table(page, "Hypotheses, ranked by validation error")[0]
    assert row["hypothesis"] == winner["title"]
    assert row["validation gain dB"] == f"{gain['gain_db']:+.1f}"
    assert row["validation error vs noise floor"] == f"{abs(floor):.1f} dB {side}"
    assert row["distortion gain dB"] == f"{gain['distortion_gain_db']:+.1f}"
    (extended,) = [r for r in _table(page, "Validation error") if r["model"].startswith("extended model")]
    assert extended["vs noise floor"] == f"{abs(floor):.1f} dB {side}"


def test_a_chain_of_causes_is_a_table_of_steps(diagnosis):
    steps = _table(diagnosis[1]["chained", 1280], "Chain of causes")
    assert [row["cause"] for row in steps] == ["Coulomb friction", "Cubic stiffness"]
    assert steps[0]["values"] == "fc = 99.2 ± 0.4" and steps[1]["values"] == "k3 = 2.5e+05 ± 1.1e+04"
    assert [row["validation error rms (unit not recorded)"] for row in steps] == ["2.5e-06", "1.6e-06"]
    assert [row["validation gain dB"] for row in steps] == ["+31.5", "+4.0"]
    assert [row["validation error vs noise floor"] for row in steps] == ["4.3 dB above", "0.3 dB below"]


def test_the_verdict_leads_with_the_cause_and_keeps_settings_in_the_details(diagnosis):
    """The verdict box: the cause's parameters with their standard errors and unit, the errors
    against the floor; no nuisance, sub-step or optimiser note, and no internal key path. Those
    are in the collapsed details."""
    summary, seen = diagnosis
    verdict = seen["diagnosis", 1280]["verdict"]["text"]
    (winner,) = [h for h in summary["hypotheses"] if h["name"] == summary["verdict"]["winner"]]
    main = winner["main_parameter"]
    unit = f" {winner['unit']}" if winner["unit"] else ""  # none where the recording's units leave it unknown
    assert (f"{main} = {winner['values'][main]:.4g} ± {winner['std'][main]:.2g}{unit}") in verdict
    assert "validation error against the noise floor: original model" in verdict
    for internal in ("nuisances estimated first", "sub-steps", "model.", "singular value", "% of its value"):
        assert internal not in verdict, internal
