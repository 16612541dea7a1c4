"""The diagnosis report page opened in a real headless browser (chromium, as in test_report_browser).

A diagnosis of a mass-spring-damper whose hidden Coulomb friction (100 N) the model lacks is run
through the CLI and rendered by ``nlsid report``; the page is loaded with the probe of
:mod:`test_report_browser` (script errors, decoded image sizes, the verdict's layout box and text).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from test_diagnose_cli import _setup  # noqa: E402
from test_report_browser import assert_verdict_first_and_figures_shown, browse  # noqa: E402  (skips without chromium, fails in CI)


def test_diagnosis_page_renders_with_verdict_and_figures_visible(run_cli, tmp_path):
    model, rec = _setup(tmp_path)
    folder, page = tmp_path / "diagnosis", tmp_path / "diagnosis.html"
    assert run_cli("diagnose", "--model", model, "--data", rec, "-o", folder).exit_code == 0
    assert run_cli("report", folder, "-o", page).exit_code == 0
    # model vs BLA, line spectrum, BLA vs level, residual vs state, before/after: five figures
    assert_verdict_first_and_figures_shown(browse(page, tmp_path), "Cause: Coulomb friction (fc = ", 5)
