"""``nlsid bla`` on closed-loop orthogonal multisine runs of two inputs that carry their references
r and r2: the FRM of each level from the references (``frm_reference``), into ``bla.h5`` and ``--json``.

The loop is ``generators.mimo_periodic_loop``: the 2x2 plant of ``generators.mimo_loop`` under
its diagonal controller, driven by orthogonal multisine references, simulated sample by sample,
output noise fed back. The stage only groups, cuts and
stores: its numbers are those of ``frm_reference`` on the same arrays. Which estimate a level
takes, and what it says when it does not use the references, is checked on runs with and without
their second reference.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import nlsid
from generators.mimo_periodic_loop import BINS, N, P, closed_loop, periods, references
from nlsid.analysis.frm import frm, frm_reference
from nlsid.errors import InputError
from nlsid.io.bla_file import read_bla
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

FS = 10.0


@pytest.fixture(scope="module")
def loop():
    """3 realizations of 4 experiments (two orthogonal pairs: E = 2 n_u, where the direct least
    squares and the references differ), whole records with their transient periods."""
    rng = np.random.default_rng(6)
    r = references(rng, (3,), 2)                                        # (M, E, 2, N)
    u, y = closed_loop(r, 1.0, rng)                                     # (M, E, 2, P, N), steady state
    return r, u, y


def recording(r, u, y, second_reference: bool = True) -> Recording:
    """The steady-state periods as runs (transient_periods 0), one per experiment."""
    runs = []
    whole = lambda x: x.reshape(x.shape[:-2] + (P * N,))                # noqa: E731
    rr, uu, yy = whole(periods(r)), whole(u), whole(y)
    for m in range(r.shape[0]):
        for e in range(r.shape[1]):
            channels = {"u2": uu[m, e, 1], "y2": yy[m, e, 1], **({"r2": rr[m, e, 1]} if second_reference else {})}
            runs.append(Run(f"ms_m{m}_e{e}", FS, "multisine", uu[m, e, 0], y=yy[m, e, 0], r=rr[m, e, 0], period=N,
                            realization=m, experiment=e, level=1.0, excited_bins=BINS, channels=channels,
                            inputs=("u", "u2"), outputs=("y", "y2")))
    return Recording(runs, {}, None)


def test_runs_with_their_references_give_the_frm_from_the_references(loop, tmp_path, run_cli):
    r, u, y = loop
    result = nlsid.bla(recording(r, u, y))
    (level,) = result.frm_levels
    assert level.references == ("r", "r2") and level.frm.method == "frm_reference"
    expected = frm_reference(periods(r), u, y, BINS, FS)
    np.testing.assert_allclose(level.frm.G, expected.G, rtol=1e-12)
    np.testing.assert_allclose(level.frm.std_noise, expected.std_noise, rtol=1e-9)
    assert np.max(np.abs(frm(u, y, BINS, FS).G - expected.G)) > 1e-3     # E > n_u: not the direct estimate
    summary = result.summary()["frm_levels"][0]
    assert summary["method"] == "frm_reference" and summary["references"] == ["r", "r2"]
    stored = read_bla(result.write(tmp_path / "bla.h5"))["frm_levels"][0]
    assert stored["attrs"]["summary"]["references"] == ["r", "r2"]

    path = recording(r, u, y).write(tmp_path / "rec.h5")
    printed = run_cli("bla", path, "-o", tmp_path / "cli.h5")
    assert printed.exit_code == 0, printed.stderr
    assert "FRM level 0: from the references r, r2" in " ".join(printed.stderr.split())
    info = run_cli("info", path, "--json")
    assert info.exit_code == 0, info.stderr
    assert any("from the references r, r2" in note for note in json.loads(info.stdout)["stages"]["bla"]["notes"])


def test_method_io_and_a_missing_reference_take_the_inputs(loop, run_cli, tmp_path):
    r, u, y = loop
    direct = frm(u, y, BINS, FS).G
    (level,) = nlsid.bla(recording(r, u, y), method="io").frm_levels
    assert level.references == () and level.frm.method == "frm"
    np.testing.assert_allclose(level.frm.G, direct, rtol=1e-12)
    assert any("references are not used (--method io)" in warning for warning in level.frm.warnings)
    assert "method" not in nlsid.bla(recording(r, u, y), method="io").summary()["frm_levels"][0]

    partial = recording(r, u, y, second_reference=False)
    (level,) = nlsid.bla(partial).frm_levels
    assert level.frm.method == "frm"
    assert any("run ms_m0_e0 lacks r2" in warning for warning in level.frm.warnings)
    path = partial.write(tmp_path / "rec.h5")
    info = run_cli("info", path, "--json")
    notes = json.loads(info.stdout)["stages"]["bla"]["notes"]
    assert any("not from the references" in note and "ms_m0_e0 lacks r2" in note for note in notes), notes
    result = run_cli("bla", path, "-o", tmp_path / "bla.h5", "--method", "reference")
    result.assert_one_line_error(f"{path}:/runs/ms_m0_e0: --method reference needs one reference per input (r, r2); "
                                 "this run lacks r2")
    assert not (tmp_path / "bla.h5").exists()
    runs = [dataclasses.replace(run, r=None) for run in partial.runs]
    with pytest.raises(InputError) as error:
        nlsid.bla(Recording(runs, {}, None), method="reference")
    assert error.value.where == "recording:/runs/ms_m0_e0" and "lacks r, r2" in error.value.what
