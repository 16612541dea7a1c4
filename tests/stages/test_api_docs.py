"""The examples of docs/api.md and of the face's docstrings run as doctests, from the repository's
folder (they read sample_data/stage.h5), and the face's names are what docs/api.md lists."""

from __future__ import annotations

import doctest
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FACE_MODULES = ("nlsid.errors", "nlsid.stages.recording", "nlsid.stages.bla", "nlsid.stages.hosidf",
                "nlsid.stages.design", "nlsid.stages.model", "nlsid.stages.fit",
                "nlsid.stages.diagnose")


def test_api_page_examples_run(monkeypatch):
    monkeypatch.chdir(ROOT)
    # a code fence ends an example's expected output, as a blank line does in a docstring
    text = (ROOT / "docs" / "api.md").read_text().replace("\n```", "\n\n```")
    test = doctest.DocTestParser().get_doctest(text, {}, "docs/api.md", str(ROOT / "docs" / "api.md"), 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.attempted > 5 and result.failed == 0


@pytest.mark.parametrize("name", FACE_MODULES)
def test_face_modules_other_docstring_examples_run(name, monkeypatch):
    """The examples in the face's modules beside the face names' own (module docstrings, helpers),
    which tests/stages/test_api_docstrings.py runs."""
    import nlsid

    monkeypatch.chdir(ROOT)
    module = importlib.import_module(name)
    face = {getattr(nlsid, n) for n in nlsid.__all__ if n != "__version__"}
    face |= {getattr(module, n) for n in nlsid.__all__ if isinstance(getattr(nlsid, n), type(nlsid))
             and hasattr(module, n)}  # a callable package's stage function (nlsid.diagnose)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for test in doctest.DocTestFinder().find(module, name):
        owner = test.name[len(name) + 1:].split(".")[0]
        if getattr(module, owner, None) not in face:
            runner.run(test)
    assert runner.summarize(verbose=False).failed == 0


def test_every_public_name_is_documented_and_has_a_docstring():
    import nlsid

    page = (ROOT / "docs" / "api.md").read_text()
    for name in nlsid.__all__:
        if name == "__version__":
            continue
        assert re.search(rf"`(nlsid\.)?{name}\b", page), f"{name} is not in docs/api.md"
        assert (getattr(nlsid, name).__doc__ or "").strip(), f"nlsid.{name} has no docstring"


def test_import_nlsid_is_light_and_the_face_imports_no_cli():
    import subprocess
    import sys

    probe = "import sys, nlsid; print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'click')))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"
    face = [ROOT / "nlsid" / "__init__.py", ROOT / "nlsid" / "errors.py", *(ROOT / "nlsid" / "stages").glob("*.py")]
    offenders = [path.name for path in face if re.search(r"^\s*(from|import) nlsid\.cli", path.read_text(), re.M)]
    assert offenders == [], offenders
