"""``hosidf`` on sine runs of one input and two outputs: the HOSIDFs of each output against closed forms.

The recording is generated here with numpy and scipy, independently of nlsid's simulator. The
force u = A cos(w0 t) drives

- y = d + a u + b u^3 (a static cubic with an offset d, as a converter adds): since
  cos^3 x = (3 cos x + cos 3x)/4, Y(w0) = a A + (3/4) b A^3 and Y(3 w0) = b A^3/4, so
  H_1 = a + (3/4) b A^2, H_3 = Y(3 w0)/U^3 = b/4 and, in the seed 000 form |Y(3 w0)|/|U|,
  b A^2/4; H_0 = d, H_2 = 0;
- y2 = c x^2 with x = g * u, an FIR filter (scipy.signal.lfilter): x = A |G| cos(w0 t + phi),
  G = G(e^{i w0}) = sum_n g_n e^{-i w0 n}, so y2 = c A^2 |G|^2 (1 + cos(2 w0 t + 2 phi))/2:
  H_0 = c A^2 |G|^2/2, H_2 = Y2(2 w0)/U^2 = c G^2/2, H_1 = H_3 = 0.

White noise of standard deviation s on both outputs: a harmonic's single-sided phasor
2 DFT[k b]/N of one period has complex variance 4 s^2/N, the mean over R repeats of P periods
4 s^2/(N R P), and H_k divides it by A^k. A complex Gaussian error exceeds 5 of its standard
deviations with probability exp(-25). The filter's transient (two samples) lies in the first
period, which is a transient period.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from scipy import signal

import nlsid
from nlsid.errors import InputError
from nlsid.io.hosidf_file import read_hosidf
from nlsid.io.run import Run

FS, N, P, R = 64.0, 64, 2, 2  # bin b is b Hz
LINES, AMPLITUDES = (3, 5), (0.5, 1.0)
A, B, D, C = 1.5, -0.4, 0.05, 0.8
G_FIR = np.array([0.6, 0.3, -0.1])
NOISE = 1e-3


def _runs(rng, lines=LINES):
    runs = []
    for line in lines:
        for level in AMPLITUDES:
            for r in range(R):
                t = np.arange((P + 1) * N) / FS
                u = level * np.cos(2 * np.pi * line * t)
                y = D + A * u + B * u**3 + NOISE * rng.standard_normal(u.size)
                y2 = C * signal.lfilter(G_FIR, [1.0], u) ** 2 + NOISE * rng.standard_normal(u.size)
                runs.append(Run(f"b{line}_a{level:g}_r{r}", FS, "sine", u, y=y, period=N, transient_periods=1,
                                level=level, frequency=line * FS / N, channels={"acc2": y2}, outputs=("y", "acc2"),
                                units={"u": "N", "y": "m/s^2", "acc2": "m/s^2"}))
    return runs


@pytest.fixture(scope="module")
def result():
    return nlsid.hosidf(nlsid.Recording(_runs(np.random.default_rng(4)), {}, None), harmonics=3)


def _std(k: int) -> np.ndarray:
    """(A,) standard deviation of H_k over the grid's amplitudes (module docstring)."""
    return np.sqrt(4 * NOISE**2 / (N * R * P)) / np.array(AMPLITUDES) ** k


def test_each_output_has_its_closed_form_hosidfs(result):
    assert result.outputs == ("y", "acc2")
    level = np.array(AMPLITUDES)[None, :]
    y, acc2 = result.output("y"), result.output("acc2")
    assert np.array_equal(y.H, result.H, equal_nan=True)  # the arrays of the result are those of y
    cubic = {0: np.full((2, 2), D), 1: np.broadcast_to(A + 0.75 * B * level**2, (2, 2)), 2: np.zeros((2, 2)),
             3: np.full((2, 2), B / 4)}
    w0 = 2 * np.pi * np.array(LINES) / N
    gain = np.array([np.sum(G_FIR * np.exp(-1j * w * np.arange(G_FIR.size))) for w in w0])[:, None]
    square = {0: C * level**2 * np.abs(gain) ** 2 / 2, 1: np.zeros((2, 2)), 2: C * gain**2 / 2 * np.ones((1, 2)),
              3: np.zeros((2, 2))}
    for measured, truth in ((y, cubic), (acc2, square)):
        for k, value in truth.items():
            std = _std(k) if k else NOISE / np.sqrt(N * R * P)  # DC: DFT[0]/N, variance s^2/N per period
            assert np.all(np.abs(measured.H[:, :, k] - value) < 5 * std), (measured.outputs, k)
    # the seed 000 form of the cubic's third harmonic: b A^2/4
    assert np.all(np.abs(np.abs(y.H000[:, :, 3]) - abs(B) * level**2 / 4) < 5 * _std(3) * level**3 / level)
    # the harmonics of each output clear their noise bound (|Y(k w0)| / std > 100 here)
    assert y.significant[:, :, 3].all() and acc2.significant[:, :, 2].all()


def _axis_texts(figure) -> str:
    """Stands in for the SVG of a page's figure (whose drawing costs half a second each): the
    titles and labels of its axes, what the page would show as text."""
    return " | ".join(f"{ax.get_title()}; {ax.get_xlabel()}; {ax.get_ylabel()}" for ax in figure.axes)


def test_file_json_and_page_carry_every_output(result, tmp_path, monkeypatch):
    from nlsid.report import vector
    from nlsid.report.render import render

    path = tmp_path / "h.h5"
    result.write(path, provenance={})
    with h5py.File(path, "r") as handle:
        assert handle.attrs["nlsid_format_version"] == 2 and json.loads(handle.attrs["outputs"]) == ["y", "acc2"]
        assert sorted(handle["grid/outputs"]) == ["acc2"]
    stored = read_hosidf(path)
    np.testing.assert_array_equal(stored["grid"]["H"], result.H)
    np.testing.assert_array_equal(stored["grid"]["outputs"]["acc2"]["H"], result.output("acc2").H)
    summary = result.summary()
    assert [row["output"] for row in summary["outputs"]] == ["y", "acc2"]
    h1 = np.array(summary["outputs"][1]["H1"])
    np.testing.assert_array_equal(h1[..., 0] + 1j * h1[..., 1], result.output("acc2").H[:, :, 1])
    # --plots: per output, a figure per frequency, the H_1 map and one run's spectrum (drawn, not rasterised)
    assert [name for name, _ in result._figures()] == [
        f"{name}_{output}.png" for output in ("y", "acc2") for name in
        ("hosidf_vs_amplitude_f000", "hosidf_vs_amplitude_f001", "hosidf_h1_map", "spectrum_b3_a0.5_r0")]
    # the page of one frequency: per output, the H_1 map and the figure of the frequency (their axes' texts)
    monkeypatch.setattr(vector, "svg", _axis_texts)
    small = nlsid.hosidf(nlsid.Recording(_runs(np.random.default_rng(5), LINES[:1]), {}, None), harmonics=3)
    page = render(small.write(tmp_path / "small.h5", provenance={}))
    assert page.summary()["figures"] == [f"{name}_{output}" for output in ("y", "acc2")
                                         for name in ("hosidf_h1_map", "hosidf_vs_amplitude_f000")]
    assert page.headline.startswith("HOSIDFs to 2 outputs; harmonics above their noise bound to y: k = 3")
    assert "acc2: k = 2" in page.headline
    assert all("(m/s^2/N)" in item.svg for item in page.figures)  # each output's unit per unit of the force
    for item, output in zip(page.figures, ("y", "y", "acc2", "acc2")):
        assert f" to {output}" in item.svg, item.svg  # titled by their output
    assert [row["output"] for row in page.numbers["outputs"]] == ["y", "acc2"]


def test_several_inputs_sweep_and_model_are_refused_in_one_line(result, tmp_path, run_cli):
    runs = _runs(np.random.default_rng(1))
    with pytest.raises(InputError, match="has outputs y, acc2: the linearity cost"):
        nlsid.hosidf(nlsid.Recording(runs, {}, None), sweep="K_fc")
    two_inputs = [Run(run.run_id, FS, "sine", run.u, y=run.y, period=N, transient_periods=1, level=run.level,
                      frequency=run.frequency, channels={"u2": run.u}, inputs=("u", "u2")) for run in runs[:2]]
    path = nlsid.Recording(two_inputs, {}, None).write(tmp_path / "two.h5")
    out = run_cli("hosidf", path, "-o", tmp_path / "h.h5")
    out.assert_one_line_error(f"{path}:/runs/b3_a0.5_r0: has inputs u, u2: a HOSIDF is a single-input concept")
    verdict = run_cli("info", path, "--json").json()["stages"]["hosidf"]
    assert not verdict["feeds"] and verdict["reason"] in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.h5"]


def test_cli_and_info_take_one_input_and_two_outputs(run_cli, tmp_path):
    path = nlsid.Recording(_runs(np.random.default_rng(2), LINES[:1]), {}, None).write(tmp_path / "rec.h5")
    assert run_cli("info", path, "--json").json()["stages"]["hosidf"]["feeds"]
    out = run_cli("hosidf", path, "-o", tmp_path / "h.h5", "--harmonics", "3", "--json")
    assert out.exit_code == 0, out.stderr
    summary = out.json()
    assert [row["output"] for row in summary["outputs"]] == ["y", "acc2"]
    assert summary["outputs"][0]["significant_cells_per_harmonic"] == summary["grid"]["significant_cells_per_harmonic"]
    text = run_cli("hosidf", path, "-o", tmp_path / "h2.h5", "--harmonics", "3")
    assert text.exit_code == 0 and "output acc2: cells where the harmonic clears its noise bound" in text.stderr
