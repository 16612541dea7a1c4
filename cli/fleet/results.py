"""The results of a batch: one row per recording (``results.csv``, ``results.jsonl``), the count
per cause, and the drift of a chosen parameter per machine.

Layouts in docs/formats.md ("The batch folder"). A row comes from the recording's task record
(``FLEET/<name>/task.json``): the record of this run, or the stored one of an up-to-date recording.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections import Counter
from datetime import datetime
from pathlib import Path

STATUS_KEYS = {"ok": "ok", "check failed": "check_failed", "bad input": "bad_input", "error": "errors"}
FIXED_COLUMNS = ("name", "recording", "machine", "recorded", "recorded_from", "status", "run", "verdict", "causes",
                 "cause_parameters", "gain_db", "above_floor_db", "floor_of", "seconds", "error", "headline", "output")
DRIFT_ALPHA = 0.001  # a machine drifts when its slope's two-sided p-value is below this (as diagnose's tests)


def table_row(record: dict, recording, run: str) -> dict:
    """The results row of a recording from its task record; ``run`` is ``ran`` or ``up to date``."""
    from .outputs import fallback_facts

    row = dict(record.get("row") or {})
    if not row.get("recorded"):
        row.update(fallback_facts(recording.path))
    machine = row.get("machine") or recording.machine_from_name
    return {
        "name": recording.name, "recording": str(recording.path), "machine": machine,
        "recorded": row.get("recorded"), "recorded_from": row.get("recorded_from"),
        "status": record.get("status", "error"), "run": run, "verdict": row.get("verdict"),
        "causes": row.get("causes") or [], "parameters": row.get("parameters") or {},
        "gain_db": row.get("gain_db"), "above_floor_db": row.get("above_floor_db"), "floor_of": row.get("floor_of"),
        "seconds": record.get("seconds"), "error": record.get("error"), "headline": row.get("headline"),
        "output": record.get("output") or str(recording.path), "steps": record.get("steps") or [],
    }


def _number(value, spec: str = ".4g") -> str:
    return "" if value is None else format(value, spec)


def cause_text(causes: list[dict]) -> str:
    """``coulomb: fc = 0.4999 ± 1.4e-06 N`` per cause (main parameter first), each value with its
    unit where one is recorded, joined by ``; ``."""
    parts = []
    for cause in causes:
        values, std = cause.get("values") or {}, cause.get("std") or {}
        units = cause.get("units") or {cause.get("main_parameter"): cause.get("unit")}
        keys = sorted(values, key=lambda k: (k != cause.get("main_parameter"), k))
        items = []
        for key in keys:
            unit = f" {units[key]}" if units.get(key) else ""
            error = f" ± {_number(std.get(key), '.2g')}" if std.get(key) is not None else ""
            items.append(f"{key} = {_number(values[key])}{error}{unit}")
        parts.append(f"{cause['name']}: {', '.join(items)}" if items else cause["name"])
    return "; ".join(parts)


def parameter_names(rows: list[dict]) -> list[str]:
    return sorted({name for row in rows for name in row["parameters"]})


def csv_text(rows: list[dict]) -> str:
    """``results.csv``: the fixed columns, then ``P``, ``std(P)`` and ``unit(P)`` for every
    parameter P found (the unit as the row's output states it, :func:`unit_cell`)."""
    names = parameter_names(rows)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([*FIXED_COLUMNS, *[c for name in names for c in (name, f"std({name})", f"unit({name})")]])
    for row in rows:
        flat = dict(row, causes="|".join(c["name"] for c in row["causes"]), cause_parameters=cause_text(row["causes"]))
        cells = ["" if flat.get(c) is None else flat[c] for c in FIXED_COLUMNS]
        for name in names:
            entry = row["parameters"].get(name) or {}
            cells += [_repr(entry.get("value")), _repr(entry.get("std")), unit_cell(entry.get("unit"))]
        writer.writerow([_repr(c) if isinstance(c, float) else c for c in cells])
    return buffer.getvalue()


PURE_NUMBER = "1"  # the unit cell of a pure number (a gain of N per N), as SI writes it
NOT_RECORDED = "unit not recorded"
DIFFER = "units differ: "


def unit_cell(unit: str | None) -> str:
    """A unit as ``results.csv`` writes it: the text, ``1`` for a pure number, empty where none
    is recorded."""
    if unit is None:
        return ""
    return unit or PURE_NUMBER


def parameter_unit(rows: list[dict], parameter: str) -> str:
    """The unit of a parameter across the rows that have it, as the fleet figure's axis states it:
    the one unit they record (``1`` for a pure number), ``unit not recorded`` where none does, and
    ``units differ: A, B`` where rows record different ones (recordings of other units)."""
    units = {(row.get("parameters") or {}).get(parameter, {}).get("unit") for row in rows
             if parameter in (row.get("parameters") or {})}
    units.discard(None)
    if not units:
        return NOT_RECORDED
    texts = sorted(unit_cell(u) for u in units)
    return texts[0] if len(texts) == 1 else DIFFER + ", ".join(texts)


def unit_suffix(label: str | None) -> str:
    """`` N`` after a number where :func:`parameter_unit` names one unit; nothing for a pure
    number, a unit not recorded or units that differ."""
    if not label or label in (PURE_NUMBER, NOT_RECORDED) or label.startswith(DIFFER):
        return ""
    return f" {label}"


def _repr(value) -> str:
    return "" if value is None else repr(float(value))


def jsonl_text(rows: list[dict]) -> str:
    from nlsid.io.result_file import json_safe

    return "".join(json.dumps(json_safe(row), sort_keys=True) + "\n" for row in rows)


def cause_key(row: dict) -> str:
    """What a row counts as in the count per cause."""
    if row["status"] in ("bad input", "error"):
        return row["status"]
    verdict = row["verdict"]
    if verdict is None:
        return "no diagnosis"
    if verdict in ("explained", "partly_explained") and row["causes"]:
        return row["causes"][0]["name"]
    return {"no_discrepancy": "no discrepancy", "ambiguous": "ambiguous", "unexplained": "unexplained"}.get(verdict, verdict)


def count_causes(rows: list[dict]) -> dict[str, int]:
    counts = Counter(cause_key(row) for row in rows)
    return dict(sorted(counts.items(), key=lambda item: (-item[1], item[0])))


def default_parameter(rows: list[dict]) -> str | None:
    """The main parameter of the most frequent named cause, else the most frequent parameter."""
    mains = Counter(f"{c['name']}.{c['main_parameter']}" for row in rows for c in row["causes"][:1] if c.get("main_parameter"))
    present = {name for row in rows for name in row["parameters"]}
    for name, _ in sorted(mains.items(), key=lambda item: (-item[1], item[0])):
        if name in present:
            return name
    counts = Counter(name for row in rows for name in row["parameters"])
    return sorted(counts.items(), key=lambda item: (-item[1], item[0]))[0][0] if counts else None


def series(rows: list[dict], parameter: str) -> dict[str, list[tuple[datetime, float, float | None, str]]]:
    """Per machine: (recorded, value, std, name) of the rows that have the parameter, in time order."""
    out: dict[str, list] = {}
    for row in rows:
        entry = row["parameters"].get(parameter)
        if not entry or entry.get("value") is None or not row.get("recorded"):
            continue
        moment = datetime.fromisoformat(row["recorded"])
        out.setdefault(row["machine"], []).append((moment, entry["value"], entry.get("std"), row["name"]))
    return {machine: sorted(points) for machine, points in sorted(out.items())}


def drift(rows: list[dict], parameter: str | None) -> list[dict]:
    """Per machine: the least-squares slope of the parameter against recording time (per day),
    its standard error from the scatter about the line, and the two-sided p-value of a t test
    (n - 2 degrees of freedom); ``drifts`` when p < DRIFT_ALPHA. Machines with fewer than three
    recordings, or all recorded at one time, get no slope."""
    if parameter is None:
        return []
    from scipy.special import stdtr

    out = []
    for machine, points in series(rows, parameter).items():
        days = [(p[0] - points[0][0]).total_seconds() / 86400.0 for p in points]
        values = [p[1] for p in points]
        entry = {"machine": machine, "recordings": len(points), "first": points[0][0].isoformat(),
                 "last": points[-1][0].isoformat(), "first_value": values[0], "last_value": values[-1],
                 "mean": sum(values) / len(values), "slope_per_day": None, "slope_std": None, "p_value": None,
                 "change_over_span": None, "drifts": False}
        n = len(points)
        mean_t = sum(days) / n
        sxx = sum((t - mean_t) ** 2 for t in days)
        if n >= 3 and sxx > 0:
            mean_v = entry["mean"]
            slope = sum((t - mean_t) * (v - mean_v) for t, v in zip(days, values)) / sxx
            residual = [v - mean_v - slope * (t - mean_t) for t, v in zip(days, values)]
            s2 = sum(r * r for r in residual) / (n - 2)
            std = math.sqrt(s2 / sxx)
            if std > 0:
                p = float(2 * stdtr(n - 2, -abs(slope) / std))
            else:
                p = 0.0 if slope != 0 else 1.0
            entry.update(slope_per_day=slope, slope_std=std, p_value=p, change_over_span=slope * (days[-1] - days[0]),
                         drifts=p < DRIFT_ALPHA)
        out.append(entry)
    return sorted(out, key=lambda e: (not e["drifts"], e["p_value"] if e["p_value"] is not None else 2.0, e["machine"]))


def counts(rows: list[dict]) -> dict[str, int]:
    out = {key: 0 for key in STATUS_KEYS.values()}
    for row in rows:
        out[STATUS_KEYS.get(row["status"], "errors")] += 1
    return out


def write_results(fleet: Path, rows: list[dict]) -> dict[str, Path]:
    from nlsid.io.atomic import write_text_atomic

    files = {"csv": fleet / "results.csv", "jsonl": fleet / "results.jsonl"}
    write_text_atomic(files["csv"], csv_text(rows), force=True)
    write_text_atomic(files["jsonl"], jsonl_text(rows), force=True)
    return files
