"""The model page lists the numbers of the model as written, by the key paths free: and sweep take."""

from __future__ import annotations

import yaml

from nlsid.report.render_model import MAX_WRITTEN, render_model


def table(page, caption):
    return next(t for t in page.tables if t.caption == caption)


def test_a_mechanical_model_lists_its_numbers_by_key_path(tmp_path):
    config = {"model": {"type": "mass_spring_damper", "mass": 2.5, "damping": 20.0, "stiffness": 2000.0,
                        "nonlinearities": [{"type": "coulomb", "fc": 0.75}]}}
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(config))
    rows = dict(map(tuple, table(render_model(path), "Parameters as written").rows))
    assert rows == {"model.mass": "2.5", "model.damping": "20", "model.stiffness": "2000",
                    "model.nonlinearities[0].fc": "0.75"}


def test_a_model_with_many_numbers_is_summarised_per_block(tmp_path):
    n = 8  # an 8-state state-space model: 64 + 8 + 8 + 1 numbers, above the page's limit
    A = [[(-1.0 if i == j else 0.0) for j in range(n)] for i in range(n)]
    config = {"model": {"type": "state_space", "A": A, "B": [1.0] * n, "C": [1.0] * n, "D": 0.5}}
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(config))
    assert n * n + 2 * n + 1 > MAX_WRITTEN
    rows = dict(map(tuple, table(render_model(path), "Parameters as written").rows))
    assert rows == {"model.A": str(n * n), "model.B": str(n), "model.C": str(n), "model.D": "1"}
