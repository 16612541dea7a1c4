"""The fleet page's figure: tick labels that tell neighbouring ticks apart, a short time axis
around recordings made at one moment, the parameter's unit or that it is not recorded."""

from __future__ import annotations

import re

from nlsid.cli.fleet.fleet_page import svg_figure


def rows(values, moments, unit=None):
    out = []
    for i, (value, moment) in enumerate(zip(values, moments)):
        entry = {"value": value, "std": None} | ({"unit": unit} if unit else {})
        out.append({"name": f"rec{i}", "machine": "m1", "recorded": moment, "parameters": {"fc": entry}})
    return out


def labels(svg: str, anchor: str) -> list[str]:
    return re.findall(rf'text-anchor="{anchor}">([^<]*)</text>', svg)


def test_close_values_get_distinct_tick_labels():
    svg = svg_figure(rows([0.50001, 0.50002, 0.50004], ["2026-01-01T10:00:00+00:00", "2026-01-02T10:00:00+00:00",
                                                     "2026-01-03T10:00:00+00:00"]), "fc", set())
    ticks = labels(svg, "end")
    assert len(ticks) >= 3 and len(set(ticks)) == len(ticks), ticks
    assert all(abs(float(t) - 0.5) < 1e-4 for t in ticks)  # .4g wrote each as 0.5


def test_recordings_at_one_moment_get_a_short_time_axis():
    moment = "2026-03-04T05:06:07+00:00"
    svg = svg_figure(rows([1.0, 2.0], [moment, moment]), "fc", set())
    times = [t for t in labels(svg, "middle") if re.fullmatch(r"\d\d:\d\d:\d\d", t)]
    assert times[0] == "05:05:07" and times[-1] == "05:07:07"  # one minute either side, not a day


def test_the_axis_names_the_unit_or_says_it_is_not_recorded():
    moments = ["2026-01-01T00:00:00+00:00", "2026-01-02T00:00:00+00:00"]
    assert "fc (N)" in svg_figure(rows([1.0, 2.0], moments, unit="N"), "fc", set())
    assert "fc (unit not recorded)" in svg_figure(rows([1.0, 2.0], moments), "fc", set())
