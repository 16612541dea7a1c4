"""A matplotlib figure as the report shows it: inline SVG whose text stays text, and its data as CSV.

- SVG from matplotlib's SVG backend with ``svg.fonttype: none``: labels, ticks and legends are
  ``<text>`` elements, so the figure zooms without blur and its words can be searched and copied.
  Element ids are made deterministic (``svg.hashsalt``, no date), and every axis label carries the
  id ``axes<i>-x-label`` / ``axes<i>-y-label`` (made unique per page by :mod:`nlsid.report.html`).
  A cloud of more than :data:`MAX_VECTOR_MARKERS` markers (a residual over a whole period) is
  embedded as an image inside the SVG, as matplotlib's ``rasterized`` does: one element per marker
  would make the page megabytes; the axes, the text and every line stay vector, and the numbers
  are in the CSV.
- CSV of what the figure draws, at the resolution it draws it: per curve (a line or markers in data
  coordinates) a column of x and one of y, headed ``<legend label>: <axis label with its unit>``;
  a panel whose curves all share their x values has one x column, headed by the x label alone;
  a band drawn with :func:`band` gives x, its lower and its upper edge. A point whose x is NaN
  is a break in a curve (where a wrapped phase jumps), not data, and is left out. Columns of different
  lengths are padded with empty cells; an empty cell is also a value the figure does not show
  (NaN, a level of zero power in dB).

matplotlib is imported inside the functions, so importing this module stays cheap.
"""

from __future__ import annotations

import csv
import io
import math
import re
import textwrap

import numpy as np

from nlsid.report.html import Figure

MAX_VECTOR_MARKERS = 500
RASTER_DPI = 100
_SVG_RC = {"svg.fonttype": "none", "svg.hashsalt": "nlsid"}
_LABEL_RC = {"axes.labelsize": 9, "axes.titlesize": 10}
_CHAR_WIDTH = 0.58  # mean width of a DejaVu Sans character, in units of the font size
_LABEL_ROOM = 0.8  # the part of an axis' length a label may take (the layout shrinks the axes a little)
# matplotlib names its whole fallback list on every text element; the page needs three of them
_FONT = re.compile(r"font-family: [^;\"]*")
_SHORT_FONT = "font-family: 'DejaVu Sans', Arial, sans-serif"


def new_figure(rows: int = 1, cols: int = 1, width: float = 8.0, height: float = 3.0):
    """An off-screen figure of ``rows`` x ``cols`` panels (``height`` inches each row) and its axes,
    with labels a size smaller than matplotlib's default, so that a label with its unit fits its panel."""
    import matplotlib
    from matplotlib.figure import Figure as MplFigure

    figure = MplFigure(figsize=(width, height * rows), layout="constrained")
    with matplotlib.rc_context(_LABEL_RC):
        axes = [figure.add_subplot(rows, cols, i + 1) for i in range(rows * cols)]
    return figure, axes


def fit_labels(figure) -> None:
    """Break every axis label longer than its axis into lines at spaces ("|G| (dB re 1 y/N, unit of
    y not recorded)" beside a short panel), so that no label runs past the figure's edge."""
    width, height = figure.get_size_inches() * 72
    for axis in figure.axes:
        box = axis.get_position()
        for label, length in ((axis.xaxis.label, box.width * width), (axis.yaxis.label, box.height * height)):
            text = label.get_text().replace("\n", " ")
            chars = max(12, int(_LABEL_ROOM * length / (_CHAR_WIDTH * label.get_fontsize())))
            label.set_text(textwrap.fill(text, chars))


def band(axis, x, low, high, label: str, **style):
    """``axis.fill_between(x, low, high)`` that keeps its edges for the figure's CSV."""
    collection = axis.fill_between(x, low, high, label=label, **style)
    x, low, high = (np.asarray(values, dtype=float) for values in (x, low, high))
    drawn = ~np.isnan(x)  # a NaN x breaks the band (a phase wrap): not a point of its data
    collection.nlsid_band = (label, x[drawn], low[drawn], high[drawn])
    return collection


def _curves(axis) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(prefix, x, y) of the lines of ``axis`` in data coordinates (not an axvline across it)."""
    out = []
    for line in axis.get_lines():
        if line.get_transform() == axis.transData:
            name = line.get_label()
            x, y = np.asarray(line.get_xdata(), dtype=float), np.asarray(line.get_ydata(), dtype=float)
            drawn = ~np.isnan(x)  # a NaN x is a break in the curve (a phase wrap), not a point
            out.append(("" if name.startswith("_") else f"{name}: ", x[drawn], y[drawn]))
    return out


def columns(figure) -> list[tuple[str, np.ndarray]]:
    """The (header, values) columns of the data ``figure`` draws, panel by panel (module docstring)."""
    out = []
    for axis in figure.axes:
        x_name, y_name = (name.replace("\n", " ") for name in (axis.get_xlabel(), axis.get_ylabel()))
        curves = _curves(axis)
        shared = len(curves) > 1 and all(np.array_equal(x, curves[0][1], equal_nan=True) for _, x, _ in curves)
        if shared:
            out.append((x_name, curves[0][1]))
        for prefix, x, y in curves:
            out += ([] if shared else [(f"{prefix}{x_name}", x)]) + [(f"{prefix}{y_name}", y)]
        for collection in axis.collections:
            if hasattr(collection, "nlsid_band"):
                name, x, low, high = collection.nlsid_band
                out += [(f"{name}: {x_name}", x), (f"{name}, lower: {y_name}", low),
                        (f"{name}, upper: {y_name}", high)]
    return out


def _cell(value: float) -> str:
    return format(value, ".7g") if math.isfinite(value) else ""


def figure_csv(figure) -> str:
    """The CSV text of :func:`columns`: a header row, then one row per point."""
    found = columns(figure)
    rows = max((values.size for _, values in found), default=0)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([name for name, _ in found])
    for i in range(rows):
        writer.writerow([_cell(values[i]) if i < values.size else "" for _, values in found])
    return buffer.getvalue()


def svg(figure) -> str:
    """The ``<svg>`` element of ``figure`` (no XML prolog), its text as text."""
    import matplotlib

    fit_labels(figure)
    for index, axis in enumerate(figure.axes):
        axis.xaxis.label.set_gid(f"axes{index}-x-label")
        axis.yaxis.label.set_gid(f"axes{index}-y-label")
        for line in axis.get_lines():
            if line.get_marker() not in ("None", "", None) and np.size(line.get_xdata()) > MAX_VECTOR_MARKERS:
                line.set_rasterized(True)
    buffer = io.StringIO()
    with matplotlib.rc_context(_SVG_RC):
        figure.savefig(buffer, format="svg", dpi=RASTER_DPI, metadata={"Date": None})
    text = buffer.getvalue()
    return _FONT.sub(_SHORT_FONT, text[text.index("<svg"):])


def figure(mpl_figure, caption: str, alt: str) -> Figure:
    """The report :class:`~nlsid.report.html.Figure` of a matplotlib figure."""
    return Figure(svg(mpl_figure), figure_csv(mpl_figure), caption, alt)
