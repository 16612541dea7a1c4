"""``nlsid bla --plots`` draws the frequency response matrix of every FRM level: ``frm_level_NN.png``,
the report page's Bode matrix, numbered as the terminal table numbers the levels (the multisine
levels, then those of arbitrary runs).

The recording is made here with scipy ``lfilter`` (not nlsid's simulator): a 2x2 system measured
with ``nlsid.design(inputs: 2)`` (one FRM level of orthogonal multisines) and by two white-noise
records (one level by the LPM for several inputs). What each figure draws is the data ``bla.h5``
stores for that level, read back by ``read_bla`` (the report draws from there): the same arrays,
element for element.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import signal

import nlsid
from nlsid.io.bla_file import read_bla
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

FS = 100.0
FILTERS = {(0, 0): ([1.0, 0.5], [1.0, -0.3]), (0, 1): ([0.2], [1.0, -0.5]),
           (1, 0): ([0.0, 0.4], [1.0]), (1, 1): ([1.0], [1.0, 0.2])}
PNG = b"\x89PNG\r\n\x1a\n"


def respond(u: np.ndarray) -> np.ndarray:
    y = np.zeros_like(u)
    for (i, a), (b, den) in FILTERS.items():
        y[i] += signal.lfilter(b, den, u[a])
    return y


def recording() -> Recording:
    rng = np.random.default_rng(7)
    exc = nlsid.design({"fs": FS, "seed": 3, "multisine": {
        "period": 64, "band": [1.0, 45.0], "lines": "odd", "realizations": 2, "periods": 2,
        "transient_periods": 1, "rms_levels": [1.0], "inputs": 2}})
    runs = []
    for run in exc.runs:
        y = respond(run.input_matrix()) + 0.01 * rng.standard_normal((2, run.n_samples))
        runs.append(dataclasses.replace(run, y=y[0], channels={**run.channels, "y2": y[1]}, outputs=("y", "y2")))
    for m in range(2):
        u = rng.standard_normal((2, 1024))
        y = respond(u) + 0.01 * rng.standard_normal((2, 1024))
        runs.append(Run(f"noise{m}", FS, "arbitrary", u[0], y=y[0], level=2.0, channels={"u2": u[1], "y2": y[1]},
                        inputs=("u", "u2"), outputs=("y", "y2")))
    return Recording(runs, {}, None)


def test_plots_write_the_frm_figure_of_each_level(run_cli, tmp_path):
    """The command writes the figure and lists it in --json: one level of arbitrary runs of one input
    and two outputs here (the 2x2 figure's eight panels take about 2 s of matplotlib, these four half)."""
    arbitrary = Recording([dataclasses.replace(run, channels={"y2": run.channels["y2"]}, inputs=("u",))
                           for run in recording().runs if run.kind == "arbitrary"], {}, None)
    path = arbitrary.write(tmp_path / "rec.h5")
    result = run_cli("bla", path, "-o", tmp_path / "bla.h5", "--plots", tmp_path / "figures", "--json")
    assert result.exit_code == 0, result.stderr
    assert result.json()["figures"] == [str(tmp_path / "figures" / "frm_level_00.png")]
    assert (tmp_path / "figures" / "frm_level_00.png").read_bytes().startswith(PNG)


def test_each_figure_draws_the_data_bla_h5_stores_numbered_as_the_table(tmp_path, monkeypatch):
    """Both kinds of level: the figure of each is drawn from the arrays its bla.h5 group holds
    (the report's source), named as the terminal table numbers the levels."""
    import nlsid.report.frm_plots
    from matplotlib.figure import Figure

    drawn = []
    monkeypatch.setattr(nlsid.report.frm_plots, "frm_figure",
                        lambda data, units, name: drawn.append((data, name)) or Figure(figsize=(1, 1)))
    analysed = nlsid.bla(recording())
    assert sorted(analysed.figures()) == ["frm_level_00.png", "frm_level_01.png"]
    assert [name for _, name in drawn] == ["FRM level 0, level 1", "FRM level 1, level 2"]
    content = read_bla(analysed.write(tmp_path / "bla.h5"))
    stored_levels = content["frm_levels"] + content["frm_lpm_levels"]
    assert len(stored_levels) == 2
    for (data, _), stored in zip(drawn, stored_levels):
        for key in ("inputs", "outputs", "confidence"):
            assert data["attrs"][key] == stored["attrs"][key], key
        for key in {"frequency", "G", "std_total", "std_noise", "var_G"} & set(data):
            np.testing.assert_array_equal(data[key], stored[key], err_msg=key)
        assert set(data["bounds"]) == set(stored["bounds"])
        for key in data["bounds"]:
            np.testing.assert_array_equal(data["bounds"][key], stored["bounds"][key], err_msg=key)
    assert "std_noise" in drawn[0][0] and "var_G" in drawn[1][0] and "std_noise" not in drawn[1][0]
