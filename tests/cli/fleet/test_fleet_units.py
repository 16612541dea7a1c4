"""The units of the fleet outputs: each parameter's unit as the diagnosis summary or the fit report
states it, in ``results.csv`` (``unit(P)``), ``results.jsonl`` and the figure's axis.

The units asserted are those of dimensional analysis for a mass-spring-damper driven by a force
u in N whose position y is in m (``m p'' + c p' + k p + k3 p^3 = u``): the cubic spring's k3 in
N/m^3, the mass in kg (N s^2/m), a gain of N per N a pure number."""

from __future__ import annotations

import csv
import io

from nlsid.cli.fleet.fleet_page import svg_figure
from nlsid.cli.fleet.outputs import diagnosis_fields, fit_parameters
from nlsid.cli.fleet.results import csv_text, parameter_unit, unit_suffix

MOMENTS = ("2026-01-01T00:00:00+00:00", "2026-01-02T00:00:00+00:00")


def summary(units: dict | None) -> dict:
    """A diagnosis summary (docs/formats.md) naming the cubic spring, with or without ``units``."""
    hypothesis = {"name": "cubic_stiffness", "title": "cubic spring", "main_parameter": "k3",
                  "unit": "N/m^3" if units else "", "values": {"k3": 6000.0, "mass": 1.01},
                  "std": {"k3": 12.0, "mass": 0.002}}
    if units is not None:
        hypothesis["units"] = units
    return {"verdict": {"status": "explained", "winner": "cubic_stiffness"}, "hypotheses": [hypothesis]}


def row(parameters: dict, name: str = "rec", recorded: str = MOMENTS[0]) -> dict:
    return {"name": name, "recording": f"{name}.h5", "machine": "m1", "recorded": recorded,
            "recorded_from": "attribute", "status": "ok", "run": "ran", "verdict": None, "causes": [],
            "parameters": parameters, "gain_db": None, "above_floor_db": None, "floor_of": None, "seconds": 1.0,
            "error": None, "headline": None, "output": name}


def test_each_value_of_a_cause_keeps_its_unit():
    fields = diagnosis_fields(summary({"k3": "N/m^3", "mass": "kg"}))
    assert fields["parameters"]["cubic_stiffness.k3"]["unit"] == "N/m^3"
    assert fields["parameters"]["cubic_stiffness.mass"]["unit"] == "kg"
    # y's unit not recorded: the summary says null for each, and its main `unit` is empty
    bare = diagnosis_fields(summary({"k3": None, "mass": None}))
    assert {p["unit"] for p in bare["parameters"].values()} == {None}
    # a summary without `units` (an earlier nlsid): the main parameter's `unit` only
    old = diagnosis_fields(summary(None))
    assert old["parameters"]["cubic_stiffness.k3"]["unit"] is None  # "" there is "none derived"


def test_results_csv_has_a_unit_column_per_parameter():
    report = {"parameters": {"model.mass": {"value": 1.0, "std": 0.01, "unit": "kg"},
                             "model.gain": {"value": 1.0, "std": 0.01, "unit": ""},
                             "a1": {"value": -0.9, "std": 0.001}}}
    parameters = fit_parameters(report, None, set())
    table = list(csv.DictReader(io.StringIO(csv_text([row(parameters)]))))
    assert (table[0]["unit(model.mass)"], table[0]["unit(model.gain)"], table[0]["unit(a1)"]) == ("kg", "1", "")
    header = next(csv.reader(io.StringIO(csv_text([row(parameters)]))))
    assert header[-3:] == ["model.mass", "std(model.mass)", "unit(model.mass)"]


def test_the_axis_says_the_unit_none_or_that_recordings_differ():
    def rows(*units):
        return [row({"fc": {"value": 1.0 + i, "std": None, "unit": u}}, f"r{i}", MOMENTS[i % 2])
                for i, u in enumerate(units)]

    assert parameter_unit(rows("N", "N"), "fc") == "N"
    assert parameter_unit(rows("N", None), "fc") == "N"  # the rows that record one
    assert parameter_unit(rows(None, None), "fc") == "unit not recorded"
    assert parameter_unit(rows("", ""), "fc") == "1"
    mixed = rows("N", "kN")
    assert parameter_unit(mixed, "fc") == "units differ: N, kN"
    assert "fc (units differ: N, kN)" in svg_figure(mixed, "fc", set())
    # after a number (the terminal's drift lines): a unit only where one is named
    assert [unit_suffix(label) for label in ("N", "1", "unit not recorded", "units differ: N, kN", None)] == [
        " N", "", "", "", ""]
