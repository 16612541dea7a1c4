"""Generators of test data, written independently of nlsid (exact discretisations, Runge-Kutta
references, measured-data stand-ins), and the paths of the repository; imported by the tests as
``generators`` (pytest's ``pythonpath = tests``)."""

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent
