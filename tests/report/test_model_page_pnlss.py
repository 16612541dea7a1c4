"""The model page of a PNLSS config names what its monomials are of: the states and u, the states
alone, or, in the LFR form, the combinations z = Cz x + Dz u (``docs/pnlss.md``).

Monomial counts from theory: with v variables, binom(v + d - 1, d) of degree d. Two states and
the input (v = 3): 6 of degree 2 and 10 of degree 3; two states alone or two combinations z
(v = 2): 3 and 4. The linear part's mode: the pole pair r e^(+-j w) of A at fs gives
s = ln r +- j w per sample, natural frequency |s| fs / (2 pi).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from nlsid.report.render_model import render_model

FS = 100.0
R, W = 0.85, 0.4
A = [[R * math.cos(W), -R * math.sin(W)], [R * math.sin(W), R * math.cos(W)]]


def _config(E_columns, F_size, **extra):
    rng = np.random.default_rng(0)
    E = 0.01 * rng.standard_normal((2, E_columns))
    E[0, 0] = 0.0   # one coefficient zero: the page counts the nonzero ones
    return {"model": {"type": "pnlss", "fs": FS, "A": A, "B": [1.0, 0.5], "C": [0.3, 0.2], "D": 0.0,
                      "state_degrees": [2, 3], "output_degrees": [2, 3], "E": E.tolist(),
                      "F": (0.01 * rng.standard_normal(F_size)).tolist(), **extra}}


def _page(tmp_path, config):
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(config))
    return render_model(path)


def _terms(page):
    return {item["name"]: item for item in page.numbers["nonlinear"]}


def test_lfr_form_names_the_combinations_z(tmp_path):
    lfr = {"form": "lfr", "inputs": 2, "Cz": [[0.3, 0.2], [0.0, 0.0]], "Dz": [0.0, 1.0]}
    page = _page(tmp_path, _config(3 + 4, 3 + 4, nonlinearity=lfr))
    terms = _terms(page)
    for name in ("E, state equation", "F, output equation"):
        assert terms[name]["type"] == ("polynomial terms of degrees [2, 3] in the monomials of "
                                       "z = Cz x + Dz u (2 combinations)")
        assert terms[name]["monomials"] == 7 and terms[name]["combinations"] == 2
    assert terms["E, state equation"]["nonzero"] == 2 * 7 - 1 and terms["F, output equation"]["nonzero"] == 7
    table = next(t for t in page.tables if t.caption == "Nonlinear elements")
    assert all("monomials of z = Cz x + Dz u (2 combinations)" in row[1] for row in table.rows)
    assert "states and u" not in page.headline
    # the linear part is drawn in Hz at the model's fs
    (mode,) = page.numbers["elements"][0]["modes"]
    assert mode["frequency"] == pytest.approx(math.hypot(math.log(R), W) * FS / (2 * math.pi), rel=1e-9)


@pytest.mark.parametrize("with_input, monomials, what", [(True, 6 + 10, "the states and u"),
                                                         (False, 3 + 4, "the states")])
def test_full_form_names_the_states(tmp_path, with_input, monomials, what):
    terms = _terms(_page(tmp_path, _config(monomials, monomials, with_input=with_input)))
    for item in terms.values():
        assert item["type"] == f"polynomial terms of degrees [2, 3] in the monomials of {what}"
        assert item["monomials"] == monomials and item["combinations"] is None
