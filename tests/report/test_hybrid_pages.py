"""The report pages of a hybrid model: its model page (``type: hybrid``) is its physical part's
page with the black-box term in parallel stated; the diagnosis page stands it beside the yardstick.

From theory: the physical part, a discrete transfer function with denominator
z^2 - 1.2 z + 0.5 at 100 Hz, has the pole pair r e^(+-j w), r = sqrt(0.5), cos w = 0.6 / r, so
s = ln r +- j w per sample and natural frequency |s| fs / (2 pi). The black box, two states with
monomials of degree 2 in the state equation (of x1, x2, u: 6) and 3 in the output equation (10),
has n^2 + 2n + 1 + 2 x 6 + 10 = 31 coefficients.
"""

from __future__ import annotations

import math

import yaml

from nlsid.report.render_model import render_model

FS = 100.0
PHYSICAL = {"type": "transfer_function", "domain": "discrete", "fs": FS, "num": [0.0, 0.2, 0.1],
            "den": [1.0, -1.2, 0.5]}
BLACK_BOX = {"type": "pnlss", "fs": FS, "A": [[0.6, 0.2], [-0.1, 0.5]], "B": [1.0, 0.5], "C": [0.3, -0.2],
             "state_degrees": [2], "output_degrees": [3]}


def test_hybrid_page_is_the_physical_part_with_the_black_box_stated(tmp_path):
    path = tmp_path / "hybrid.yaml"
    path.write_text(yaml.safe_dump({"model": {"type": "hybrid", "physical": PHYSICAL, "black_box": BLACK_BOX}}))
    page = render_model(path)
    r = math.sqrt(0.5)
    frequency = abs(complex(math.log(r), math.acos(0.6 / r))) * FS / (2 * math.pi)
    (mode,) = page.numbers["elements"][0]["modes"]
    assert mode["poles"] == 2 and abs(mode["frequency"] - frequency) < 1e-9 * frequency
    assert page.numbers["model"] == "hybrid" and page.numbers["physical"] == "transfer_function"
    box = page.numbers["black_box"]
    assert box["parameters"] == 31 and box["states"] == 2 and box["form"] == "full"
    assert page.headline.startswith("Hybrid model:") and "black-box term" in page.findings[0]


def test_diagnosis_page_stands_the_hybrid_beside_the_yardstick():
    """The diagnosis page's lines of where each model stands against the floor name the hybrid
    where summary.json says it was fitted (its above_floor_db rounded as the verdict words it),
    and its finding goes to the details, as the yardstick's does."""
    from nlsid.report.render_diagnosis import split_findings, standing_lines

    error = {"above_floor_db": 41.1, "noise_floor_zero": False}
    summary = {"original": error, "gain": {"extended": {"above_floor_db": 27.3, "noise_floor_zero": False},
                                           "gain_db": 13.8},
               "yardstick": {"fitted": True, "validation": {"above_floor_db": 0.57, "noise_floor_zero": False}},
               "hybrid": {"fitted": True, "validation": {"above_floor_db": 11.23, "noise_floor_zero": False}}}
    lines = standing_lines(summary)
    assert "(hybrid_model.yaml) reaches 11.2 dB above the floor" in lines[-1]
    assert not any("hybrid" in line for line in standing_lines({**summary, "hybrid": {"fitted": False}}))
    lead, details = split_findings(["hybrid model (the extended model with a black-box PNLSS term ...)", "cause"])
    assert lead == ["cause"] and details[0].startswith("hybrid model")
