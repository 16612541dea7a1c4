"""One self-contained HTML page: the verdict first, then the evidence figures, then the numbers.

The page needs nothing but itself: the CSS is inline, every figure is a PNG embedded as a base64
``data:`` URI, there is no script and no external resource (no fonts, no stylesheets, no images by
address), so it can be mailed to a colleague and opened offline. Every piece of text that comes from
a file (run ids, parameter names, warnings, provenance) is HTML-escaped.

A renderer builds a :class:`Page` from a result file; :func:`render_html` turns it into the text.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass, field

_CSS = """
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
figure { margin: 18px 0 26px; }
figure img { display: block; max-width: 100%; height: auto; margin: 0 auto; border: 1px solid var(--line); }
figcaption { color: var(--muted); font-size: 13.5px; margin-top: 6px; }
figcaption b { color: var(--ink); }
table { border-collapse: collapse; margin: 8px 0 22px; font-size: 13.5px; width: 100%; }
caption { text-align: left; font-weight: 600; padding: 4px 0 6px; }
th, td { border-bottom: 1px solid var(--line); padding: 4px 8px; text-align: right; white-space: nowrap; }
th { background: var(--panel); font-weight: 600; }
th:first-child, td:first-child { text-align: left; }
td.text { text-align: left; white-space: normal; }
p.note { color: var(--muted); font-size: 13px; }
footer { margin-top: 36px; color: var(--muted); font-size: 12px; border-top: 1px solid var(--line);
         padding-top: 8px; }
"""


@dataclass(frozen=True)
class Figure:
    """A PNG figure with a caption (first sentence in bold) and an alternative text."""

    png: bytes
    caption: str
    alt: str


@dataclass(frozen=True)
class Table:
    """A table of numbers: ``rows`` are already formatted strings (see :func:`number`)."""

    caption: str
    header: list[str]
    rows: list[list[str]]
    note: str = ""


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

    def summary(self) -> dict:
        """The machine-readable content of the page (``nlsid report --json``)."""
        return {"kind": self.kind, "title": self.title, "source": self.source, "headline": self.headline,
                "findings": list(self.findings), "warnings": list(self.warnings),
                "figures": [item.alt for item in self.figures], "numbers": self.numbers}


def number(value, spec: str = ".3g") -> str:
    """Format a number for a table; ``-`` for a missing (None or NaN) value."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return format(value, spec)


def png(figure, dpi: int = 110) -> bytes:
    """A matplotlib figure as PNG bytes."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _figure(item: Figure, index: int) -> str:
    data = base64.b64encode(item.png).decode("ascii")
    first, _, rest = item.caption.partition(". ")
    if rest:
        caption = f"<b>Figure {index}. {_e(first)}.</b> {_e(rest)}"
    else:
        caption = f"<b>Figure {index}.</b> {_e(item.caption)}"
    return (f'<figure id="figure-{index}"><img src="data:image/png;base64,{data}" alt="{_e(item.alt)}">'
            f"<figcaption>{caption}</figcaption></figure>")


def _table(item: Table) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in item.header)
    body = "".join("<tr>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>" for row in item.rows)
    note = f'<p class="note">{_e(item.note)}</p>' if item.note else ""
    return (f"<table><caption>{_e(item.caption)}</caption><thead><tr>{head}</tr></thead>"
            f"<tbody>{body}</tbody></table>{note}")


def _provenance(provenance: dict) -> str:
    if not provenance:
        return ""
    def text(value) -> str:
        if isinstance(value, dict):
            return "; ".join(f"{k} (SHA-256 {v})" for k, v in value.items()) or "-"
        return str(value)

    rows = "".join(f'<tr><td>{_e(key)}</td><td class="text">{_e(text(value))}</td></tr>'
                   for key, value in sorted(provenance.items()))
    return f'<h2>Provenance</h2><table class="provenance"><tbody>{rows}</tbody></table>'


def render_html(page: Page, generator: str) -> str:
    """The complete HTML document of ``page``; ``generator`` names the tool (shown in the footer)."""
    findings = "".join(f"<li>{_e(f)}</li>" for f in page.findings)
    warnings = ""
    if page.warnings:
        items = "".join(f"<li>{_e(w)}</li>" for w in page.warnings)
        warnings = f'<div class="warnings" id="warnings"><b>Warnings of the analysis</b><ul>{items}</ul></div>'
    figures = "".join(_figure(item, i + 1) for i, item in enumerate(page.figures))
    tables = "".join(_table(item) for item in page.tables)
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(page.title)}</title><style>{_CSS}</style></head><body><main>"
        f'<header><div class="kind">{_e(page.kind)}</div><h1>{_e(page.title)}</h1>'
        f'<div class="source">{_e(page.source)}</div></header>'
        f'<section id="verdict"><p class="headline">{_e(page.headline)}</p><ul>{findings}</ul></section>'
        f"{warnings}"
        + (f'<h2>Evidence</h2><section id="figures">{figures}</section>' if figures else "")
        + (f'<h2>Numbers</h2><section id="numbers">{tables}</section>' if tables else "")
        + _provenance(page.provenance)
        + f"<footer>Generated by {_e(generator)}.</footer></main></body></html>\n"
    )
