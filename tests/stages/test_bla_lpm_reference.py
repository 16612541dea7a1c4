"""``nlsid bla`` on closed-loop arbitrary runs of two inputs that carry their references r and r2:
the FRM by the LPM with references (the indirect method), into ``bla.h5`` and ``--json``.

The loop is ``generators.mimo_loop`` (a 2x2 plant under a diagonal controller, output noise fed
back into u, simulated sample by sample in the test). The stage only groups, cuts and stores: its
numbers are those of ``lpm_mimo_reference`` (or ``lpm_mimo`` with ``--method io``) on the same
arrays, to rounding. Which method a level takes, and what it says when it does not use r, is
checked on runs with and without their second reference.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import nlsid
from generators.mimo_loop import closed_loop
from nlsid.analysis.lpm_mimo import lpm_mimo, lpm_mimo_reference
from nlsid.errors import InputError
from nlsid.io.bla_file import read_bla
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

FS = 10.0


@pytest.fixture(scope="module")
def loop():
    return closed_loop(np.random.default_rng(5), records=2, samples=1024)


def recording(r, u, y, second_reference: bool = True) -> Recording:
    runs = []
    for m in range(r.shape[0]):
        channels = {"u2": u[m, 1], "y2": y[m, 1], **({"r2": r[m, 1]} if second_reference else {})}
        runs.append(Run(f"loop{m}", FS, "arbitrary", u[m, 0], y=y[m, 0], r=r[m, 0], level=1.0, channels=channels,
                        inputs=("u", "u2"), outputs=("y", "y2")))
    return Recording(runs, {}, None)


def test_runs_with_their_references_give_the_indirect_frm(loop, tmp_path, run_cli):
    r, u, y = loop
    path = recording(r, u, y).write(tmp_path / "rec.h5")
    printed = run_cli("bla", path, "-o", tmp_path / "cli.h5")
    assert printed.exit_code == 0, printed.stderr
    assert "FRM level 0: from the references r, r2 (the LPM with references" in " ".join(printed.stderr.split())
    result = nlsid.bla(recording(r, u, y))
    (level,) = result.frm_lpm_levels
    assert level.result.method == "lpm_reference" and level.references == ("r", "r2")
    assert not any("not used" in warning for warning in level.warnings), level.warnings
    expected = lpm_mimo_reference(r, u, y, FS)           # 2 records: 7 lines leave q = 14 - 12 = 2
    np.testing.assert_allclose(level.G, expected.G[level.band], rtol=1e-12)
    np.testing.assert_allclose(level.var_G, expected.var_G[level.band], rtol=1e-9)
    assert level.band.size > 0.9 * expected.lines.size       # white references: (nearly) every line
    summary = result.summary()["frm_lpm_levels"][0]
    assert summary["method"] == "lpm_reference" and summary["references"] == ["r", "r2"]

    content = read_bla(result.write(tmp_path / "bla.h5"))
    (stored,) = content["frm_lpm_levels"]
    assert stored["attrs"]["method"] == "lpm_reference" and stored["attrs"]["references"] == ["r", "r2"]
    np.testing.assert_array_equal(stored["G_ur"], expected.G_ur[level.band])
    assert stored["cov_z"].shape == (level.band.size, 4, 4)


def test_method_io_takes_u_as_known_and_says_r_is_not_used(loop):
    r, u, y = loop
    (level,) = nlsid.bla(recording(r, u, y), method="io").frm_lpm_levels
    assert level.result.method == "lpm" and level.references == ()
    np.testing.assert_allclose(level.G, lpm_mimo(u, y, FS).G[level.band], rtol=1e-12)
    assert any("references are not used (--method io)" in warning for warning in level.warnings)


def test_a_missing_second_reference(loop, run_cli, tmp_path):
    r, u, y = loop
    partial = recording(r, u, y, second_reference=False)
    (level,) = nlsid.bla(partial).frm_lpm_levels
    assert level.result.method == "lpm"
    assert any("need the references r, r2, and run loop0 lacks r2" in warning for warning in level.warnings)
    path = partial.write(tmp_path / "rec.h5")
    result = run_cli("bla", path, "-o", tmp_path / "bla.h5", "--method", "reference")
    result.assert_one_line_error(f"{path}:/runs/loop0: --method reference needs one reference per input (r, r2); "
                                 "this run lacks r2")
    assert not (tmp_path / "bla.h5").exists()
    runs = [dataclasses.replace(run, r=None) for run in partial.runs]
    with pytest.raises(InputError) as error:
        nlsid.bla(Recording(runs, {}, None), method="reference")
    assert error.value.where == "recording:/runs/loop0" and "lacks r, r2" in error.value.what
