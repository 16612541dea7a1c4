"""The report's figures as an engineer reads them: phase within +-180 degrees, log frequency axes
for bands of a decade or more, the spectrum's axis on the excited band, the model's numerical
floor not drawn as data, legends beside the data, and units said once per page.

Each figure is drawn from data built here, and the properties are asserted on its matplotlib
Axes against numbers of that data (the band's edges, the filter's phase from scipy.signal.freqz).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from generators.bla_cases import odd_random_bins, runs_of_level

from nlsid.analysis.levels import analyse_runs
from nlsid.report import bla_plots, diagnosis_plots, hosidf_plots
from nlsid.report.axes import BELOW_NOISE, NUMERICAL_FLOOR
from nlsid.report.html import Page, render_html
from nlsid.report.units import Units
from nlsid.report.vector import figure as report_figure

FS, N = 1024.0, 1024
B, A = signal.butter(4, 5.0, fs=FS)  # -80 dB at 60 Hz: the upper lines of the band are noise


@pytest.fixture(scope="module")
def levels():
    """Two levels of a 4th-order low-pass (5 Hz) excited on odd random lines of 1-60 Hz, 0.01 noise on y."""
    rng = np.random.default_rng(5)
    bins = odd_random_bins(1, 61, 3, rng)
    runs = []
    for level in (0.5, 1.0):
        for run in runs_of_level(3, N, bins, level, lambda u: signal.lfilter(B, A, u), 2, rng, fs=FS,
                                 noise_y=0.01, level=level):
            run.run_id = f"L{level:g}_{run.run_id}"
            runs.append(run)
    found, _ = analyse_runs([(run, run.run_id) for run in runs])
    return found, bins


def _drawn(figure):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(figure).draw()
    return figure


def _legends_clear_of_data(figure) -> None:
    """Every legend's box lies outside its panel's data area (their pixel boxes do not overlap)."""
    renderer = figure.canvas.get_renderer()
    found = 0
    for axis in figure.axes:
        legend = axis.get_legend()
        if legend is None:
            continue
        found += 1
        box, data = legend.get_window_extent(renderer), axis.get_window_extent(renderer)
        overlap_x = min(box.x1, data.x1) - max(box.x0, data.x0)
        overlap_y = min(box.y1, data.y1) - max(box.y0, data.y0)
        assert overlap_x <= 0 or overlap_y <= 0, (axis.get_ylabel(), box, data)
    assert found


def test_bla_phase_stays_within_180_degrees_and_matches_the_filter(levels):
    found, bins = levels
    level = found[-1]
    figure = _drawn(bla_plots.bla_figure(level, Units({"u": "N", "y": "m"})))
    magnitude, phase = figure.axes
    assert magnitude.get_xscale() == phase.get_xscale() == "log"  # 1 to 60 Hz: more than a decade
    assert phase.get_ylim() == (-180.0, 180.0)
    (line,) = [line for line in phase.get_lines() if line.get_label() == "phase of G_BLA"]
    x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
    points = ~np.isnan(y)
    assert np.all(np.abs(y[points]) <= 180.0)
    np.testing.assert_allclose(x[points], bins * FS / N)  # every excited line drawn, none added
    # Where the filter passes (|G| > 0.5), the noise (0.01 against an output of ~0.3 per line and
    # 6 averaged periods) moves the phase by well under a degree: 5 degrees of tolerance.
    _, true = signal.freqz(B, A, worN=bins * FS / N, fs=FS)
    passed = np.abs(true) > 0.5
    assert passed.sum() >= 2
    error = (y[points][passed] - np.degrees(np.angle(true[passed])) + 180.0) % 360.0 - 180.0
    assert np.max(np.abs(error)) < 5.0
    # the filter's phase passes -180 degrees (4th order: to -360), so the curve wraps at least once,
    # and is broken there rather than drawn across the panel
    assert np.isnan(y).any()
    assert np.all(np.abs(np.diff(y)[np.isfinite(np.diff(y))]) <= 180.0)
    _legends_clear_of_data(figure)


def test_output_spectrum_axis_holds_the_excited_band(levels):
    found, bins = levels
    figure = _drawn(bla_plots.spectrum_figure(found[-1], Units({"u": "N", "y": "m"})))
    (axis,) = figure.axes
    low, high = bins.min() * FS / N, bins.max() * FS / N
    assert axis.get_xscale() == "log"
    left, right = axis.get_xlim()
    assert left <= low and high <= right <= 2 * high < FS / 2  # the band plus a margin, not 0 .. fs/2
    _legends_clear_of_data(figure)


def test_levels_figure_is_logarithmic_with_the_legend_outside(levels):
    figure = _drawn(bla_plots.levels_figure(levels[0], Units({"u": "N", "y": "m"})))
    assert figure.axes[0].get_xscale() == "log"
    _legends_clear_of_data(figure)


def _diagnosis_level(f: np.ndarray) -> dict:
    s = 2j * np.pi * f
    G = 1.0 / (s**2 / 400.0 + s / 20.0 + 1.0) * np.exp(-0.03 * s)  # the delay wraps the phase several times
    return {"frequency": f, "G": G, "G_model": G * 1.02, "radius": 0.05 * np.abs(G),
            "outside": np.zeros(f.size, dtype=np.int8)}


@pytest.mark.parametrize("f, scale", [(np.linspace(1.5, 60.0, 40), "log"), (np.linspace(20.0, 60.0, 40), "linear")])
def test_diagnosis_bla_axes(f, scale):
    figure = _drawn(diagnosis_plots.model_vs_bla(_diagnosis_level(f), Units({"u": "N", "y": "m"})))
    magnitude, phase = figure.axes
    assert magnitude.get_xscale() == phase.get_xscale() == scale  # log from a decade up (60 / 1.5 = 40, 3)
    assert phase.get_ylim() == (-180.0, 180.0)
    for line in phase.get_lines():
        y = np.asarray(line.get_ydata(), float)
        assert np.all(np.abs(y[~np.isnan(y)]) <= 180.0)
    _legends_clear_of_data(figure)


def test_diagnosis_spectrum_masks_the_model_numerical_floor():
    # Lines of 1 Hz up to fs/2 = 512 Hz; excited odd lines 3..59 Hz at power 1 (0 dB); the model
    # puts 1e-4 on the odd detection lines (a prediction) and 1e-17 (-170 dB, round-off) on the even.
    f = np.arange(1.0, 513.0)
    kind = np.full(f.size, -1)
    k = f.astype(int)
    from nlsid.analysis.lines import EVEN, EXCITED, ODD

    kind[(k % 2 == 1) & (k % 4 == 3) & (k < 60)] = EXCITED
    kind[(k % 2 == 1) & (k % 4 == 1)] = ODD
    kind[k % 2 == 0] = EVEN
    y_power = np.where(kind == EXCITED, 1.0, 1e-6)
    model = np.where(kind == EXCITED, 1.0, np.where(kind == ODD, 1e-4, 1e-17))
    level = {"frequency": f, "kind": kind, "in_band": (k < 60).astype(np.int8), "y_power": y_power,
             "model_power": model, "noise": np.full(f.size, 1e-8)}
    figure = _drawn(diagnosis_plots.spectrum(level, Units({"u": "N", "y": "m"})))
    (axis,) = figure.axes
    # the largest excited power is 1 and the noise 1e-8: the floor is the lower of 1e-9 x 1 and
    # 1e-3 x 1e-8 (-110 dB); the -170 dB lines are under it, the odd lines' -40 dB above
    floor_db = 10 * np.log10(min(NUMERICAL_FLOOR * 1.0, BELOW_NOISE * 1e-8))
    assert floor_db == pytest.approx(-110.0)
    (drawn,) = [line for line in axis.get_lines() if line.get_label() == "model"]
    y = np.asarray(drawn.get_ydata(), float)
    assert np.nanmin(y) >= floor_db - 1e-9  # no model point below the floor
    assert np.sum(np.isfinite(y)) == np.sum(kind == EXCITED) + np.sum(kind == ODD)  # the -170 dB lines left out
    floors = [line for line in axis.get_lines() if "numerical floor" in line.get_label()]
    assert len(floors) == 1 and np.allclose(floors[0].get_ydata(), floor_db)
    assert axis.get_xscale() == "log"  # 3 to 59 Hz
    assert axis.get_xlim()[1] <= 59 * 1.5 + 1e-9  # not up to 512 Hz
    _legends_clear_of_data(figure)


class _Grid:
    """The part of a HOSIDFGrid the figures read: H_k = a^(k-1) / (1 + j f / 10) at every cell."""

    harmonics = 3

    def __init__(self):
        self.frequencies = np.array([1.0, 3.0, 10.0, 30.0])
        self.levels = np.array([0.5, 1.0, 2.0])

    def field(self, name: str) -> np.ndarray:
        f, a = self.frequencies[:, None, None], self.levels[None, :, None]
        k = np.arange(self.harmonics + 1)[None, None, :]
        H = a ** (k - 1.0) / (1 + 1j * f / 10.0) + 0j
        if name.endswith("_var_repeats") or name.endswith("_var_periods"):
            return np.full(H.shape, 1e-6 + 0j)
        return H


def test_hosidf_legends_leave_the_points_free():
    units = Units({"u": "N", "y": "m"})
    figure = _drawn(hosidf_plots.first_hosidf_figure(_Grid(), units))
    assert figure.axes[1].get_ylim() == (-180.0, 180.0)
    _legends_clear_of_data(figure)
    _legends_clear_of_data(_drawn(hosidf_plots.versus_amplitude_figure(_Grid(), 0, units)))


def test_unit_not_recorded_is_said_once_per_page():
    units = Units({"u": "N"})  # y has no unit, as in the sample recording
    drawn = units.for_figures()
    f = np.linspace(1.5, 60.0, 40)
    figures = [report_figure(diagnosis_plots.model_vs_bla(_diagnosis_level(f), drawn), "BLA. c", "bla"),
               report_figure(diagnosis_plots.bla_vs_level([dict(_diagnosis_level(f), level=1.0)], drawn),
                             "Levels. c", "levels")]
    page = Page(kind="k", title="t", source="s", headline="h", findings=[], figures=figures,
                note=units.missing_note("u", "y"))
    text = render_html(page, "test")
    assert text.count("not recorded") == 1 and 'id="units-note"' in text
    assert "Unit of y not recorded" in text
    assert "dB re 1 y/N" in text  # the figures still name what the level is relative to
    assert Units({"u": "N", "y": "m"}).missing_note("u", "y") == ""
