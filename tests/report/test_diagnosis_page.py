"""The diagnosis page's verdict box leads with the cause, its parameters and the standing against
the noise floor; nuisances, numerical settings and the fits' notes sit in a collapsed details
element. The summary is built here, in the shape of docs/formats.md's summary.json."""

from __future__ import annotations

import re

from nlsid.report.html import Page, render_html
from nlsid.report.render_diagnosis import cause_lines, optimiser_notes, split_findings, standing_lines

FINDINGS = [
    "nuisances estimated first (not causes): output_offset = -1.618e-08 +- 5.3e-06",
    "simulation error 0.0152 rms against the noise in it of 0.000709 (+26.6 dB, p < 1e-15)",
    "extended model simulated with 10 sub-steps per sample (output change to 40: 4.4e-07 rms)",
    "estimation budget: the hypotheses were fitted on 20000 of the 80000 samples",
    "initial state fitted to the start of 2 arbitrary record(s) (not a cause): position",
    "black-box yardstick (PNLSS, 3 states, degrees [2, 3], 40 parameters; stopped early): validation gain +27 dB",
    "Coulomb friction: validation gain +26.6 dB, 0.0 dB below the noise floor",
]


def _summary(chain=None, yardstick=None) -> dict:
    coulomb = {"name": "coulomb", "title": "Coulomb friction", "main_parameter": "fc", "unit": "N",
               "values": {"fc": 100.2, "damping": 20.0}, "std": {"fc": 0.17, "damping": 0.0018}, "reason": "",
               "note": "model.output_offset and model.output_timing: the data cannot tell these apart"}
    skipped = {"name": "delay", "title": "A dead time", "main_parameter": "delay", "unit": "s", "values": None,
               "std": None, "reason": "the BLA phase shows no dead time", "note": None}
    error = {"above_floor_db": 26.56, "noise_floor_zero": False}
    extended = {"above_floor_db": -0.04, "noise_floor_zero": False}
    out = {"verdict": {"winner": "coulomb"}, "hypotheses": [coulomb, skipped], "original": error,
           "gain": {"extended": extended, "gain_db": 26.6}, "findings": FINDINGS}
    if chain is not None:
        out["chain"] = chain
    if yardstick is not None:
        out["yardstick"] = yardstick
    return out


def test_findings_split_by_their_opening_words():
    lead, details = split_findings(FINDINGS)
    assert lead == [FINDINGS[1], FINDINGS[6]]
    assert details == [FINDINGS[0], FINDINGS[2], FINDINGS[3], FINDINGS[4], FINDINGS[5]]


def test_cause_with_every_parameter_and_its_standard_error():
    (line,) = cause_lines(_summary())
    assert line == ("cause: Coulomb friction: fc = 100.2 ± 0.17 N; with it, the model's damping = 20 ± 0.0018 "
                    "(± one standard error)")
    chain = [{"cause": "coulomb", "title": "Coulomb friction", "values": {"fc": 99.2}, "std": {"fc": 0.4}},
             {"cause": "cubic_stiffness", "title": "Cubic stiffness", "values": {"k3": 2.5e5}, "std": {"k3": 1.1e4}}]
    first, second = cause_lines(_summary(chain=chain))
    assert first == "cause 1, Coulomb friction: fc = 99.2 ± 0.4 N (± one standard error)"
    assert second == "cause 2, Cubic stiffness: k3 = 2.5e+05 ± 1.1e+04 (± one standard error)"


def test_standing_against_the_floor_with_the_yardstick():
    yardstick = {"fitted": True, "validation": {"above_floor_db": 2.04, "noise_floor_zero": False}}
    original, beside = standing_lines(_summary(yardstick=yardstick))
    assert original == ("validation error against the noise floor: original model 26.6 dB above, extended model "
                        "(named causes) 0.0 dB below, 26.6 dB smaller than the original's")
    assert beside.startswith("a black-box model fitted to the same data as a yardstick (PNLSS) reaches 2.0 dB above")
    assert len(standing_lines(_summary())) == 1  # without a yardstick (--no-yardstick) nothing is said of it


def test_details_are_collapsed_below_the_verdict():
    summary = _summary()
    lead, details = split_findings(summary["findings"])
    page = Page(kind="Model diagnosis", title="t", source="s", headline="Cause: Coulomb friction",
                findings=cause_lines(summary) + standing_lines(summary) + lead,
                details=details + optimiser_notes(summary), details_title="Details")
    text = render_html(page, "test")
    verdict = re.search(r'<section id="verdict">(.*?)</section>', text, re.S).group(1)
    for word in ("nuisances estimated first", "sub-steps", "estimation budget", "model.output_offset"):
        assert word not in verdict
    found = re.search(r"<details id=\"details\">(.*?)</details>", text, re.S)
    assert found and "<details id=\"details\" open" not in text  # collapsed
    assert text.index('id="verdict"') < text.index('id="details"')
    assert "Coulomb friction: model.output_offset and model.output_timing" in found.group(1)
    assert optimiser_notes(summary) == [f"Coulomb friction: {summary['hypotheses'][0]['note']}"]  # not the unfitted
