"""One self-contained HTML page: the verdict first, then the evidence figures, then the numbers.

Findings an engineer need not read to decide (numerical settings, side estimates, optimiser notes)
sit under the verdict in a collapsed ``<details>`` element (``id="details"``), one click away.

The page needs nothing but itself: the CSS is inline, every figure is inline SVG (its text is text:
it zooms and can be searched) with its data as a CSV ``data:`` link, there is no script and no
external resource (no fonts, no stylesheets, no images by address), so it can be mailed to a
colleague and opened offline. Every piece of text that comes from a file (run ids, parameter
names, warnings, provenance) is HTML-escaped. Tables wrap their text, so that nothing runs off
the page at any window width, and a table whose columns cannot shrink to the text column (many
numbers side by side in a narrow window) scrolls sideways in a box of its own (class ``scroll``)
rather than widening the page; the sources cited on the page are listed in full at its end.

A renderer builds a :class:`Page` from a result file; :func:`render_html` turns it into the text.
"""

from __future__ import annotations

import html
import math
import re
import urllib.parse
from dataclasses import dataclass, field

from nlsid.citations import cited

#: The page style, shared by every page nlsid writes (the fleet page adds its own rules after it).
CSS = """
:root { --ink: #1d2733; --muted: #5b6875; --line: #d8dee5; --accent: #1f5f99; --panel: #f5f7fa; }
* { box-sizing: border-box; }
body { margin: 0; font: 15px/1.5 -apple-system, "Segoe UI", Roboto, "DejaVu Sans", Arial, sans-serif;
       color: var(--ink); background: #fff; }
main { max-width: 980px; margin: 0 auto; padding: 28px 32px 48px; }
header { border-bottom: 3px solid var(--accent); padding-bottom: 10px; margin-bottom: 18px; }
header .kind { color: var(--accent); font-weight: 600; letter-spacing: .06em; text-transform: uppercase;
               font-size: 12px; }
h1 { font-size: 24px; margin: 2px 0 4px; }
header .source { color: var(--muted); font-size: 13px; word-break: break-all; }
h2 { font-size: 18px; margin: 30px 0 10px; border-bottom: 1px solid var(--line); padding-bottom: 4px; }
#verdict { background: var(--panel); border-left: 6px solid var(--accent); padding: 14px 18px;
           border-radius: 4px; }
#verdict .headline { font-size: 19px; font-weight: 650; margin: 0 0 6px; }
#verdict ul { margin: 6px 0 0; padding-left: 20px; }
.warnings { background: #fff8e6; border-left: 6px solid #d39b00; padding: 10px 16px; border-radius: 4px;
            margin-top: 14px; font-size: 14px; }
.warnings ul { margin: 4px 0 0; padding-left: 20px; }
main { overflow-wrap: break-word; }
figure { margin: 18px 0 26px; }
figure svg { display: block; max-width: 100%; height: auto; margin: 0 auto; border: 1px solid var(--line); }
figcaption { color: var(--muted); font-size: 13.5px; margin-top: 6px; }
figcaption b { color: var(--ink); }
figcaption a.data { white-space: nowrap; }
table { border-collapse: collapse; margin: 8px 0 22px; font-size: 13.5px; width: 100%; }
.scroll { overflow-x: auto; margin: 8px 0 22px; }
.scroll > table { margin: 0; }
caption { text-align: left; font-weight: 600; padding: 4px 0 6px; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 8px; text-align: right; vertical-align: top; }
th { background: var(--panel); font-weight: 600; }
th:first-child, td:first-child { text-align: left; }
td.text, th.text { text-align: left; }
table.provenance td.text { overflow-wrap: anywhere; }
p.note { color: var(--muted); font-size: 13px; }
details#details { margin-top: 10px; padding: 6px 18px; border: 1px solid var(--line); border-radius: 4px;
                  font-size: 14px; }
details#details summary { cursor: pointer; color: var(--muted); font-weight: 600; }
details#details ul { margin: 6px 0 4px; padding-left: 20px; }
ol.references { font-size: 13px; padding-left: 22px; }
footer { margin-top: 36px; color: var(--muted); font-size: 12px; border-top: 1px solid var(--line);
         padding-top: 8px; }
"""


@dataclass(frozen=True)
class Figure:
    """A figure: its ``<svg>`` element, the CSV of the data it draws (:mod:`nlsid.report.vector`),
    a caption (first sentence in bold) and an alternative text (also its name)."""

    svg: str
    csv: str
    caption: str
    alt: str


@dataclass(frozen=True)
class Table:
    """A table of numbers: ``rows`` are already formatted strings (see :func:`number`), one per
    column of ``header``; the columns listed in ``text`` hold words (left-aligned)."""

    caption: str
    header: list[str]
    rows: list[list[str]]
    note: str = ""
    text: tuple[int, ...] = ()

    def __post_init__(self):
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(f"table '{self.caption}': a row of {len(row)} cells under {len(self.header)} headers")


@dataclass
class Page:
    """What a report shows, in order: the verdict, the figures, the tables, the provenance.

    ``numbers`` holds the page's numbers in machine-readable form (plain values, lists, dicts and
    numpy arrays or scalars; non-finite floats mean "not available").
    """

    kind: str
    title: str
    source: str
    headline: str
    findings: list[str]
    figures: list[Figure] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    provenance: dict = field(default_factory=dict)
    numbers: dict = field(default_factory=dict)
    #: said once under the title, e.g. which units the recording did not carry (:mod:`nlsid.report.units`)
    note: str = ""
    #: findings behind the verdict, collapsed under it: settings, side estimates, optimiser notes
    details: list[str] = field(default_factory=list)
    details_title: str = "Details"

    def summary(self) -> dict:
        """The machine-readable content of the page (``nlsid report --json``)."""
        return {"kind": self.kind, "title": self.title, "source": self.source, "headline": self.headline,
                "findings": list(self.findings), "details": list(self.details), "warnings": list(self.warnings),
                "figures": [item.alt for item in self.figures], "numbers": self.numbers}


def number(value, spec: str = ".3g") -> str:
    """Format a number for a table; ``-`` for a missing (None or NaN) value."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return format(value, spec)


def _e(text) -> str:
    return html.escape(str(text), quote=True)


_ID = re.compile(r'(\bid="|xlink:href="#|url\(#)')


def _scoped(svg: str, prefix: str, alt: str) -> str:
    """``svg`` with every id (and reference to one) prefixed, unique on the page, and its alt text."""
    svg = _ID.sub(lambda m: m.group(1) + prefix, svg)
    return svg.replace("<svg ", f'<svg role="img" aria-label="{_e(alt)}" ', 1)


def _csv_link(item: Figure, index: int) -> str:
    """The figure's data as a link to a CSV ``data:`` URL (saved as ``figure-<index>-<alt>.csv``)."""
    url = "data:text/csv;charset=utf-8," + urllib.parse.quote(item.csv, safe=",")
    return f'<a class="data" download="figure-{index}-{_e(item.alt)}.csv" href="{url}">Data (CSV)</a>'


def _figure(item: Figure, index: int) -> str:
    first, _, rest = item.caption.partition(". ")
    if rest:
        caption = f"<b>Figure {index}. {_e(first)}.</b> {_e(rest)}"
    else:
        caption = f"<b>Figure {index}.</b> {_e(item.caption)}"
    return (f'<figure id="figure-{index}">{_scoped(item.svg, f"figure-{index}-", item.alt)}'
            f"<figcaption>{caption} {_csv_link(item, index)}</figcaption></figure>")


def _cells(tag: str, cells: list[str], text: tuple[int, ...]) -> str:
    """One table row's cells (``th`` or ``td``); those of the ``text`` columns of class ``text``."""
    return "".join(f'<{tag} class="text">{_e(c)}</{tag}>' if i in text else f"<{tag}>{_e(c)}</{tag}>"
                   for i, c in enumerate(cells))


def _table(item: Table) -> str:
    head = _cells("th", item.header, item.text)
    body = "".join(f"<tr>{_cells('td', row, item.text)}</tr>" for row in item.rows)
    note = f'<p class="note">{_e(item.note)}</p>' if item.note else ""
    return (f'<div class="scroll"><table><caption>{_e(item.caption)}</caption><thead><tr>{head}</tr></thead>'
            f"<tbody>{body}</tbody></table></div>{note}")


def _provenance(provenance: dict) -> str:
    if not provenance:
        return ""
    def text(value) -> str:
        if isinstance(value, dict):
            return "; ".join(f"{k} (SHA-256 {v})" for k, v in value.items()) or "-"
        return str(value)

    rows = "".join(f"<tr>{_cells('td', [key, text(value)], (1,))}</tr>" for key, value in sorted(provenance.items()))
    head = _cells("th", ["item", "value"], (1,))
    return (f'<h2>Provenance</h2><div class="scroll"><table class="provenance"><thead><tr>{head}</tr></thead>'
            f"<tbody>{rows}</tbody></table></div>")


def _references(body: str) -> str:
    """The full reference of every source ``body`` cites (:mod:`nlsid.citations`)."""
    found = cited(body)
    if not found:
        return ""
    items = "".join(f"<li>{_e(reference)}</li>" for reference in found)
    return f'<h2>References</h2><ol class="references" id="references">{items}</ol>'


def render_html(page: Page, generator: str) -> str:
    """The complete HTML document of ``page``; ``generator`` names the tool (shown in the footer)."""
    findings = "".join(f"<li>{_e(f)}</li>" for f in page.findings)
    warnings = ""
    if page.warnings:
        items = "".join(f"<li>{_e(w)}</li>" for w in page.warnings)
        warnings = f'<div class="warnings" id="warnings"><b>Warnings of the analysis</b><ul>{items}</ul></div>'
    details = ""
    if page.details:
        items = "".join(f"<li>{_e(d)}</li>" for d in page.details)
        details = (f'<details id="details"><summary>{_e(page.details_title)}</summary>'
                   f"<ul>{items}</ul></details>")
    figures = "".join(_figure(item, i + 1) for i, item in enumerate(page.figures))
    tables = "".join(_table(item) for item in page.tables)
    body = (
        f'<header><div class="kind">{_e(page.kind)}</div><h1>{_e(page.title)}</h1>'
        f'<div class="source">{_e(page.source)}</div></header>'
        + (f'<p class="note" id="units-note">{_e(page.note)}</p>' if page.note else "")
        + f'<section id="verdict"><p class="headline">{_e(page.headline)}</p><ul>{findings}</ul></section>'
        f"{details}{warnings}"
        + (f'<h2>Evidence</h2><section id="figures">{figures}</section>' if figures else "")
        + (f'<h2>Numbers</h2><section id="numbers">{tables}</section>' if tables else "")
    )
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(page.title)}</title><style>{CSS}</style></head><body><main>"
        + body + _references(body) + _provenance(page.provenance)
        + f"<footer>Generated by {_e(generator)}.</footer></main></body></html>\n"
    )
