"""A free parameter's bad key path is reported under its own ``free:`` key, not as ``sweep.parameter``
(issue #14): both name a path into the config, but the user wrote only one of them."""

from __future__ import annotations

import pytest

DESIGN = """fs: 100.0
seed: 1
multisine: {period: 100, band: [1, 20], realizations: 2, periods: 2, rms_levels: [1.0]}
"""

MODEL = """model:
  type: transfer_function
  num: [1.0]
  den: [1.0, 2.0, 100.0]
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    folder = tmp_path_factory.mktemp("free_errors")
    (folder / "design.yaml").write_text(DESIGN)
    (folder / "model.yaml").write_text(MODEL)
    for args in (["design", folder / "design.yaml", "-o", folder / "e.h5"],
                 ["simulate", folder / "model.yaml", "--excitation", folder / "e.h5", "-o", folder / "r.h5"]):
        result = CliRunner().invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    return folder / "r.h5"


@pytest.mark.parametrize("key, what", [
    ("model.num[1]", "no item [1]: model.num has 1 item"),
    ("model.den[5].x", "no item [5]: model.den has 3 items"),
    ("model.type[0]", "model.type is not a list: no item [0]"),
])
def test_free_key_path_errors_name_the_free_key(run_cli, tmp_path, recording, key, what):
    config = tmp_path / "m.yaml"
    config.write_text(MODEL + f"free:\n  {key}: {{start: 1.0}}\n")  # the free key is on line 6
    result = run_cli("fit", "--model", config, "--data", recording, "-o", tmp_path / "f.yaml")
    result.assert_one_line_error(f"{config}:6: free.{key}: ", what)
    assert "sweep" not in result.stderr
    assert not (tmp_path / "f.yaml").exists() and not (tmp_path / "f.fit.json").exists()


def test_sweep_key_path_errors_still_name_the_sweep(run_cli, tmp_path, recording):
    config = tmp_path / "s.yaml"
    config.write_text(MODEL + "sweep:\n  parameter: model.num[2]\n  values: [1.0, 2.0]\n")
    result = run_cli("simulate", config, "--excitation", recording, "-o", tmp_path / "s.h5")
    result.assert_one_line_error("sweep.parameter: model.num[2]: no item [2]: model.num has 1 item")
