"""The fleet page ``FLEET/fleet.html``: one self-contained HTML page of a batch.

In order: the counts (recordings, ok, failed checks, bad inputs, errors); the count per cause;
the chosen parameter against recording time (inline SVG, one line per machine, each point's
recording in its tooltip), with the drift table (slope per day, its standard error, p-value;
drifting machines first and marked); the results table, sortable by clicking a column header;
the failed recordings with their one-line errors.

Like the report pages (:mod:`nlsid.report.html`), the page needs nothing but itself: inline CSS,
no external resource. Unlike them, the figure is inline SVG (not a PNG) and the page carries one
small inline script, the table sort (the page reads fine without it). Text from files is
HTML-escaped.
"""

from __future__ import annotations

import html
import math
from datetime import datetime, timezone
from pathlib import Path
from urllib.parse import quote

from .results import DIFFER, NOT_RECORDED, cause_key, cause_text, count_causes, counts, parameter_unit, series

_SORT_SCRIPT = """
document.querySelectorAll('table.sortable').forEach(function (table) {
  table.querySelectorAll('th').forEach(function (th, column) {
    th.addEventListener('click', function () {
      var body = table.tBodies[0], rows = Array.prototype.slice.call(body.rows);
      var down = th.getAttribute('data-order') !== 'up';
      table.querySelectorAll('th').forEach(function (h) { h.removeAttribute('data-order'); });
      th.setAttribute('data-order', down ? 'up' : 'down');
      function key(row) {
        var cell = row.cells[column], v = cell.getAttribute('data-v');
        return v !== null ? parseFloat(v) : cell.textContent.trim().toLowerCase();
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (typeof x === 'number' && typeof y === 'number') { if (isNaN(x)) return 1; if (isNaN(y)) return -1; }
        return (x < y ? -1 : x > y ? 1 : 0) * (down ? 1 : -1);
      });
      rows.forEach(function (row) { body.appendChild(row); });
    });
  });
});
"""

_EXTRA_CSS = """
main { max-width: 1200px; }
table.sortable th { cursor: pointer; user-select: none; }
table.sortable th[data-order=up]::after { content: " \\25B2"; }
table.sortable th[data-order=down]::after { content: " \\25BC"; }
.counts span { display: inline-block; margin-right: 18px; }
.bad { color: #a61b1b; font-weight: 600; }
tr.drifts td { background: #fff1f0; }
table.sortable td { text-align: left; }
table.sortable td[data-v] { text-align: right; }
table.sortable td.text { min-width: 220px; max-width: 420px; font-size: 12.5px; }
"""


def _e(text) -> str:
    return html.escape("" if text is None else str(text), quote=True)


def _num(value, spec: str = ".4g") -> tuple[str, str]:
    """Cell text and its sort value."""
    if value is None:
        return "-", "NaN"
    return format(value, spec), repr(float(value))


_PALETTE = ("#1f5f99", "#d3542c", "#2e8b57", "#8e44ad", "#c29100", "#17a2b8", "#7f7f7f", "#b5179e", "#6b8e23", "#a0522d")


def _ticks(low: float, high: float, count: int = 5) -> list[float]:
    """About ``count`` round values covering [low, high] (steps of 1, 2 or 5 times a power of ten)."""
    span = high - low
    raw = span / max(count - 1, 1)
    power = 10 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 5, 10) if m * power >= raw)
    first = math.ceil(low / step) * step
    return [first + i * step for i in range(int((high - first) / step + 1e-9) + 1)]


def _tick_label(value: float, step: float) -> str:
    """A tick's value with the digits its step needs, so that neighbouring ticks never read alike
    (0.5001, 0.5002, ... where ``.4g`` wrote 0.5 three times)."""
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    if abs(value) < 1e6 and decimals <= 6:
        return f"{value:.{decimals}f}"
    digits = max(1, math.floor(math.log10(max(abs(value), step))) - math.floor(math.log10(step) + 1e-9) + 1)
    return f"{value:.{digits}g}"


SINGLE_MOMENT = 60.0  # s either side of an axis whose recordings share one moment


def svg_figure(rows: list[dict], parameter: str, drifting: set[str]) -> str | None:
    """The parameter against recording time as inline SVG: one line per machine, error bars of
    one standard error, each point's recording, value and error in its tooltip."""
    data = series(rows, parameter)
    if not data:
        return None
    width, height, left, right, top, bottom = 900, 360, 86, 190, 16, 52
    points = [p for values in data.values() for p in values]
    t0 = min(p[0] for p in points).timestamp()
    t1 = max(p[0] for p in points).timestamp()
    if t1 == t0:  # one moment: a short axis around it, not a day
        t0, t1 = t0 - SINGLE_MOMENT, t1 + SINGLE_MOMENT
    lows = [p[1] - (p[2] or 0.0) for p in points]
    highs = [p[1] + (p[2] or 0.0) for p in points]
    y0, y1 = min(lows), max(highs)
    pad = (y1 - y0) * 0.08 or abs(y1) * 0.05 or 1.0
    y0, y1 = y0 - pad, y1 + pad

    def x(moment) -> float:
        return left + (moment.timestamp() - t0) / (t1 - t0) * (width - left - right)

    def y(value: float) -> float:
        return top + (y1 - value) / (y1 - y0) * (height - top - bottom)

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" width="100%" role="img" '
           f'aria-label="{_e(parameter)} against recording time" font-family="sans-serif" font-size="12">',
           f'<rect x="{left}" y="{top}" width="{width - left - right}" height="{height - top - bottom}" fill="none" stroke="#999"/>']
    ticks = _ticks(y0, y1)
    step = ticks[1] - ticks[0] if len(ticks) > 1 else abs(y1 - y0) or 1.0
    for value in ticks:
        yy = y(value)
        out.append(f'<line x1="{left}" x2="{width - right}" y1="{yy:.1f}" y2="{yy:.1f}" stroke="#e3e7ec"/>'
                   f'<text x="{left - 6}" y="{yy + 4:.1f}" text-anchor="end">{_tick_label(value, step)}</text>')
    span = t1 - t0
    for i in range(5):
        moment = datetime.fromtimestamp(t0 + i * span / 4, timezone.utc)
        xx = x(moment)
        label = moment.strftime("%Y-%m-%d" if span >= 4 * 86400 else "%m-%d %H:%M" if span >= 3600 else "%H:%M:%S")
        out.append(f'<line x1="{xx:.1f}" x2="{xx:.1f}" y1="{height - bottom}" y2="{height - bottom + 5}" stroke="#999"/>'
                   f'<text x="{xx:.1f}" y="{height - bottom + 18}" text-anchor="middle">{label}</text>')
    # ids as the report pages' axis labels carry (nlsid.report.vector): the browser tests find the units by them
    out.append(f'<text id="drift-x-label" x="{(left + width - right) / 2:.0f}" y="{height - 8}" text-anchor="middle">'
               'recorded (UTC)</text>'
               f'<text id="drift-y-label" x="16" y="{(top + height - bottom) / 2:.0f}" text-anchor="middle" '
               f'transform="rotate(-90 16 {(top + height - bottom) / 2:.0f})">{_e(parameter)} ({_e(parameter_unit(rows, parameter))})</text>')
    for index, (machine, values) in enumerate(data.items()):
        color = _PALETTE[index % len(_PALETTE)]
        thick = machine in drifting
        path = " ".join(f"{x(p[0]):.1f},{y(p[1]):.1f}" for p in values)
        out.append(f'<g class="machine"><polyline points="{path}" fill="none" stroke="{color}" '
                   f'stroke-width="{3 if thick else 1.3}"/>')
        for moment, value, std, name in values:
            xx, yy = x(moment), y(value)
            if std:
                out.append(f'<line x1="{xx:.1f}" x2="{xx:.1f}" y1="{y(value - std):.1f}" y2="{y(value + std):.1f}" '
                           f'stroke="{color}"/>')
            error = f" ± {std:.2g}" if std else ""
            out.append(f'<circle cx="{xx:.1f}" cy="{yy:.1f}" r="{4 if thick else 3}" fill="{color}">'
                       f"<title>{_e(name)}: {value:.6g}{error} ({moment.isoformat()})</title></circle>")
        ly = top + 14 + 18 * index
        label = (machine or "(no machine)") + (" (drifts)" if thick else "")
        out.append(f'<line x1="{width - right + 14}" x2="{width - right + 36}" y1="{ly - 4}" y2="{ly - 4}" '
                   f'stroke="{color}" stroke-width="{3 if thick else 1.5}"/>'
                   f'<text x="{width - right + 42}" y="{ly}" font-weight="{"bold" if thick else "normal"}">{_e(label)}</text></g>')
    out.append("</svg>")
    return "".join(out)


def render_page(rows: list[dict], summary: dict, parameter: str | None, drift: list[dict], titles: dict[str, str]) -> str:
    """The page's HTML text. ``titles`` maps hypothesis names to their titles (for the causes)."""
    from nlsid.report.html import CSS

    tally = counts(rows)
    head = (f'<div class="counts"><span><b>{len(rows)}</b> recordings</span><span>{tally["ok"]} ok</span>'
            f'<span class="{"bad" if tally["check_failed"] else ""}">{tally["check_failed"]} failed checks</span>'
            f'<span class="{"bad" if tally["bad_input"] else ""}">{tally["bad_input"]} bad inputs</span>'
            f'<span class="{"bad" if tally["errors"] else ""}">{tally["errors"]} errors</span>'
            f'<span>{summary["ran"]} ran, {summary["up_to_date"]} up to date</span></div>')

    cause_rows = "".join(f"<tr><td>{_e(titles.get(k, k))}</td><td>{n}</td></tr>" for k, n in count_causes(rows).items())
    causes = ('<h2>Count per cause</h2><div class="scroll"><table><thead><tr><th>cause</th><th>recordings</th></tr>'
              f"</thead><tbody>{cause_rows}</tbody></table></div>")

    drifting = {d["machine"] for d in drift if d["drifts"]}
    if parameter is None:
        trend = '<h2>Parameter over time</h2><p class="note">No recording has a parameter (no cause was named and no fit ran).</p>'
    else:
        picture = svg_figure(rows, parameter, drifting)
        figure = ""
        if picture is not None:
            figure = (f'<figure id="drift">{picture}'
                      f"<figcaption><b>{_e(parameter)} against recording time, per machine.</b> Error bars: the "
                      "standard errors of the estimates; thick lines: machines whose least-squares slope differs "
                      "from zero at p &lt; 0.001.</figcaption></figure>")
        lines = []
        for d in drift:
            cells = [_e(d["machine"] or "(no machine)"), str(d["recordings"]), _num(d["first_value"])[0],
                     _num(d["last_value"])[0], _num(d["slope_per_day"])[0], _num(d["slope_std"], ".2g")[0],
                     _num(d["change_over_span"])[0], _num(d["p_value"], ".2g")[0], "drifts" if d["drifts"] else ""]
            lines.append(f'<tr class="{"drifts" if d["drifts"] else ""}">' + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
        unit = parameter_unit(rows, parameter)
        scale = unit if unit == NOT_RECORDED or unit.startswith(DIFFER) else f"values in {unit}, slopes in {unit} per day"
        table = ('<div class="scroll"><table><caption>Drift per machine (least-squares line against time; '
                 f"{_e(scale)})</caption><thead><tr>"
                 "<th>machine</th><th>recordings</th><th>first</th><th>last</th><th>slope per day</th><th>std</th>"
                 "<th>change over span</th><th>p</th><th></th></tr></thead><tbody>" + "".join(lines)
                 + "</tbody></table></div>")
        if not drift:
            table = f'<p class="note">No recording has the parameter {_e(parameter)}.</p>'
        trend = f"<h2>{_e(parameter)} over time</h2>{figure}{table}"

    header = ["recording", "machine", "recorded", "status", "verdict", "causes", "gain dB", "above floor dB", "seconds",
              *([f"{parameter} ({parameter_unit(rows, parameter)})", "std"] if parameter else []), "error"]
    body = []
    for row in rows:
        link = _link(row)
        entry = row["parameters"].get(parameter) if parameter else None
        cells = [f"<td>{link}</td>", f"<td>{_e(row['machine'])}</td>",
                 f'<td title="from the {"attribute recorded" if row["recorded_from"] == "attribute" else "file modification time"}">'
                 f"{_e(row['recorded'])}{'' if row['recorded_from'] == 'attribute' else ' (mtime)'}</td>",
                 f'<td class="{"bad" if row["status"] != "ok" else ""}">{_e(row["status"])}</td>',
                 f"<td>{_e(cause_key(row) if row['status'] in ('ok', 'check failed') else '')}</td>",
                 f'<td class="text">{_e(cause_text(row["causes"]))}</td>']
        for value, spec in ((row["gain_db"], ".1f"), (row["above_floor_db"], ".1f"), (row["seconds"], ".2f")):
            text, key = _num(value, spec)
            cells.append(f'<td data-v="{key}">{text}</td>')
        if parameter:
            for value, spec in (((entry or {}).get("value"), ".5g"), ((entry or {}).get("std"), ".2g")):
                text, key = _num(value, spec)
                cells.append(f'<td data-v="{key}">{text}</td>')
        cells.append(f'<td class="text">{_e(row["error"])}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    results = ('<h2>Results</h2><p class="note">Click a column header to sort.</p><div class="scroll">'
               '<table class="sortable" id="results"><thead><tr>' + "".join(f"<th>{_e(h)}</th>" for h in header) +
               "</tr></thead><tbody>" + "".join(body) + "</tbody></table></div>")

    failed = [row for row in rows if row["status"] != "ok"]
    problems = ""
    if failed:
        items = "".join(f"<li><b>{_e(row['name'])}</b> ({_e(row['status'])}): {_e(row['error'])}</li>" for row in failed)
        problems = f'<h2>Recordings with problems</h2><div class="warnings"><ul>{items}</ul></div>'

    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>Fleet: {_e(summary['output'])}</title><style>{CSS}{_EXTRA_CSS}</style></head><body><main>"
            f'<header><div class="kind">batch</div><h1>Fleet: {len(rows)} recordings</h1>'
            f'<div class="source">pipeline {_e(summary["pipeline"])}; this run: {_e(summary["executor"])}</div></header>'
            f'<section id="verdict">{head}</section>{causes}{trend}{results}{problems}'
            f"<footer>Generated by nlsid {_e(summary['version'])} batch.</footer></main>"
            f"<script>{_SORT_SCRIPT}</script></body></html>\n")


def _link(row: dict) -> str:
    """The recording's name, linked to the first HTML page in its folder (a report step's output)."""
    folder = Path(row["output"])
    pages = sorted(folder.glob("*.html")) if folder.is_dir() else []
    if not pages:
        return _e(row["name"])
    href = quote(f"{row['name']}/{pages[0].name}")
    return f'<a href="{_e(href)}">{_e(row["name"])}</a>'
