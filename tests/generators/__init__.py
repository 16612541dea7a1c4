"""Generators of test data, written independently of nlsid (exact discretisations, Runge-Kutta
references, measured-data stand-ins), the paths of the repository, and checks that several test
modules share; imported by the tests as ``generators`` (pytest's ``pythonpath = tests``)."""

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent


def assert_refused(result, folder, source, *fragments) -> None:
    """A refused import: exit 2, one ``nlsid: error:`` line holding each fragment, no traceback, nothing
    on stdout, and nothing written beside ``source`` in ``folder``."""
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("nlsid: error: "), lines
    assert "Traceback" not in result.stderr and result.stdout == ""
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert sorted(p.name for p in folder.iterdir()) == [source.name], "nothing written"
