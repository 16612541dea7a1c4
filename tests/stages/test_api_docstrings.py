"""Every name of the library's face (``nlsid.__all__``) carries a numpydoc docstring whose examples
run: a class has a summary, Parameters or Attributes, and Examples; a function a summary,
Parameters, Returns and Examples. Every public method and property of the face's classes has a
docstring. The examples run from the repository's folder (some read sample_data/stage.h5)."""

from __future__ import annotations

import doctest
import importlib
import inspect
import re
import types
from pathlib import Path

import pytest

import nlsid

ROOT = Path(__file__).resolve().parents[2]
FACE = [name for name in nlsid.__all__ if name != "__version__"]
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
#: a numpydoc section heading: its title, then a line of dashes as long as the title
HEADING = re.compile(r"^([A-Z][A-Za-z ]*)\n(-+)$", re.M)


def documented(name: str):
    """The object whose docstring documents ``nlsid.<name>``: the object itself, or for a face name
    that is a callable package (``nlsid.diagnose``) the stage function that calling it runs."""
    obj = getattr(nlsid, name)
    if isinstance(obj, types.ModuleType):
        function = getattr(importlib.import_module(f"nlsid.stages.{name}"), name)
        assert inspect.signature(obj) == inspect.signature(function), name
        return function
    return obj


def sections(docstring: str) -> list[str]:
    """The numpydoc section titles of a docstring, in order."""
    text = inspect.cleandoc(docstring)
    return [title for title, dashes in HEADING.findall(text) if len(dashes) == len(title)]


def test_sections_are_read_as_numpydoc_writes_them():
    doc = """Summary.

    Parameters
    ----------
    x : int
        A number.

    Examples
    -------
    >>> 1
    1
    """
    assert sections(doc) == ["Parameters"]  # a line of dashes shorter than its title is no heading


def test_every_face_name_has_a_summary_and_its_sections():
    missing = {}
    for name in FACE:
        obj = documented(name)
        doc = obj.__doc__ or ""
        found = set(sections(doc))
        needed = {"Examples"} | ({"Parameters", "Returns"} if inspect.isroutine(obj) else set())
        lacking = sorted(needed - found)
        if inspect.isclass(obj) and not found & {"Parameters", "Attributes"}:
            lacking.append("Parameters or Attributes")
        summary = inspect.cleandoc(doc).split("\n\n")[0] if doc.strip() else ""
        if not summary or HEADING.search(summary):
            lacking.append("summary")
        if lacking:
            missing[name] = lacking
    assert missing == {}


def test_every_public_method_of_the_face_classes_has_a_docstring():
    undocumented = []
    classes = [documented(name) for name in FACE if inspect.isclass(documented(name))]
    for cls in classes:
        for owner in cls.__mro__:
            if not owner.__module__.startswith("nlsid"):
                continue
            for attribute, value in vars(owner).items():
                method = isinstance(value, (property, classmethod, staticmethod)) or inspect.isfunction(value)
                if method and not attribute.startswith("_"):
                    function = value.fget if isinstance(value, property) else getattr(value, "__func__", value)
                    if not (function.__doc__ or "").strip():
                        undocumented.append(f"{owner.__name__}.{attribute}")
    assert classes and undocumented == []


def test_every_face_docstring_example_runs(monkeypatch):
    monkeypatch.chdir(ROOT)
    finder = doctest.DocTestFinder()
    report: list[str] = []
    examples = {}
    failed = 0
    for name in FACE:
        obj = documented(name)
        runner = doctest.DocTestRunner(optionflags=FLAGS)
        for test in finder.find(obj, f"nlsid.{name}"):
            runner.run(test, out=report.append)
        result = runner.summarize(verbose=False)
        examples[name], failed = result.attempted, failed + result.failed
    assert failed == 0, "".join(report)
    assert [name for name, count in examples.items() if count == 0] == []


@pytest.mark.parametrize("text, expected", [("'1'\n", 0), ("'2'\n", 1)])
def test_a_wrong_example_is_counted_as_a_failure(text, expected):
    test = doctest.DocTestParser().get_doctest(f">>> str(1)\n{text}", {}, "probe", None, 0)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    runner.run(test, out=lambda _: None)
    assert runner.summarize(verbose=False).failed == expected
