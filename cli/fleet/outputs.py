"""What a recording's outputs say, for the results table: the verdict, the causes with their
parameters and standard errors, the gain and the distance to the noise floor (from the last
``diagnose`` step's ``summary.json``), the parameters of ``fit`` reports, and the last headline.

Each parameter carries its unit as the output states it (``summary.json`` ``hypotheses[].units``,
the fit report's ``parameters[].unit``, derived by :mod:`nlsid.models.parameter_units` from the
recording's units): a text, ``""`` for a pure number, None where none is stated (a transfer
function's coefficients, a signal without a recorded unit).

Parameter names (the columns of ``results.csv`` and ``--param``):

- a cause named by ``diagnose``: ``<hypothesis>.<parameter>``, e.g. ``coulomb.fc``;
- a ``fit`` report (``<model>.fit.json``): its ``parameters`` keys, e.g.
  ``model.nonlinearities[0].fc`` (``--model`` fits) or ``a1``, ``b0`` (transfer functions); when an
  earlier fit of the same recording already gave that name, ``<report file stem>:<key>``.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from pathlib import Path


def _read_json(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _finite(value):
    return value if isinstance(value, (int, float)) and value == value and abs(value) != float("inf") else None


def fallback_facts(recording: Path) -> dict:
    """``recorded`` from the file's modification time (None when the file is gone)."""
    try:
        moment = datetime.fromtimestamp(recording.stat().st_mtime, timezone.utc).isoformat(timespec="seconds")
    except OSError:
        moment = None
    return {"recorded": moment, "recorded_from": "mtime" if moment else None, "machine": None}


def _unit(text) -> str | None:
    """A recorded unit: a text (``""`` a pure number), None where the output states none."""
    return text if isinstance(text, str) else None


def value_units(hypothesis: dict) -> dict[str, str | None]:
    """The unit of each estimated value of a ``summary.json`` hypothesis: its ``units`` (null where
    unknown); a summary without them gives the main parameter its ``unit`` (an empty ``unit`` there
    means none was derived, not a pure number)."""
    stated = hypothesis.get("units")
    values = hypothesis.get("values") or {}
    if isinstance(stated, dict):
        return {key: _unit(stated.get(key)) for key in values}
    main = hypothesis.get("main_parameter")
    return {key: (hypothesis.get("unit") or None) if key == main else None for key in values}


def diagnosis_fields(summary: dict) -> dict:
    """Verdict, causes, their parameters, gain and distance to the floor of a diagnosis summary."""
    verdict = summary.get("verdict") or {}
    status = verdict.get("status")
    names = [verdict["winner"]] if verdict.get("winner") else (list(verdict.get("tied") or []) if status == "ambiguous" else [])
    hypotheses = {h.get("name"): h for h in summary.get("hypotheses") or [] if isinstance(h, dict)}
    causes, parameters = [], {}
    for name in names:
        h = hypotheses.get(name, {})
        values, std = h.get("values") or {}, h.get("std") or {}
        units = value_units(h)
        causes.append({"name": name, "title": h.get("title", name), "main_parameter": h.get("main_parameter"),
                       "unit": units.get(h.get("main_parameter")), "units": units, "values": values, "std": std})
        for key, value in values.items():
            parameters[f"{name}.{key}"] = {"value": _finite(value), "std": _finite(std.get(key)), "unit": units.get(key),
                                           "source": "diagnose"}
    gain = summary.get("gain") or None
    original = summary.get("original") or {}
    return {
        "verdict": status,
        "causes": causes,
        "parameters": parameters,
        "gain_db": _finite(gain.get("gain_db")) if gain else None,
        "above_floor_db": _finite(gain.get("extended_above_floor_db") if gain else original.get("above_floor_db")),
        "floor_of": "extended" if gain else ("original" if original else None),
        "headline": summary.get("headline"),
    }


def fit_parameters(report: dict, report_path: Path, taken: set[str]) -> dict:
    out = {}
    for key, entry in (report.get("parameters") or {}).items():
        if not isinstance(entry, dict):
            continue
        name = key if key not in taken else f"{report_path.name.removesuffix('.fit.json')}:{key}"
        out[name] = {"value": _finite(entry.get("value")), "std": _finite(entry.get("std")),
                     "unit": _unit(entry.get("unit")), "source": "fit"}
    return out


def row_of(done: list[dict], facts: dict | None, recording: Path) -> dict:
    """The table fields of a recording from the outputs of the steps that ran (``done``: dicts with
    the ``nlsid run`` step, its exit ``code`` and ``headline``)."""
    row = dict(facts or fallback_facts(recording))
    row.update(verdict=None, causes=[], parameters={}, gain_db=None, above_floor_db=None, floor_of=None, headline=None)
    parameters: dict = {}
    for item in done:
        step, code = item["step"], item["code"]
        if code not in (0, 1):
            continue
        stage = step.args[0]
        if stage == "diagnose":
            summary = _read_json(step.output / "summary.json")
            if summary is not None and summary.get("nlsid_format") == "diagnosis":
                fields = diagnosis_fields(summary)
                parameters = {k: v for k, v in parameters.items() if v["source"] != "diagnose"}
                parameters.update(fields.pop("parameters"))
                row.update(fields)
        elif stage == "fit":
            from nlsid.io.fit_file import report_path

            path = report_path(step.output)
            report = _read_json(path)
            if report is not None and report.get("nlsid_format") == "fit":
                parameters.update(fit_parameters(report, path, set(parameters)))
        if item.get("headline"):
            row["headline"] = item["headline"]
    row["parameters"] = parameters
    return row
