"""``nlsid report``: one self-contained HTML page of a result (diagnosis/, bla.h5, hosidf.h5, model.yaml)."""

from __future__ import annotations

import click

from nlsid import __version__
from nlsid.io.atomic import check_writable, write_text_atomic

from .common import StageCommand, emit_json, force_option, json_option, settings


@click.command(cls=StageCommand)
@click.argument("source", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="The HTML page to write.")
@force_option
@json_option
def report(source: str, output: str, force: bool, as_json: bool) -> dict:
    """Render a diagnosis, BLA, HOSIDF or model as one self-contained HTML page.

    The page opens with the verdict, then the evidence figures with captions, then the tables of
    numbers, the references and the provenance. Figures are inline vector graphics (their text is
    searchable), each with its data as a CSV link, and every axis carries the recording's units;
    the page is one file that opens offline and can be mailed as it is. With --json, the verdict
    and the numbers are also printed to stdout.

    Examples:

    \b
      nlsid report diagnosis/ -o report.html
      nlsid report bla.h5 -o bla_report.html
      nlsid report hosidf.h5 -o hosidf_report.html --json
      nlsid report configs/model_resonance.yaml -o model.html
    """
    from nlsid.report.html import render_html
    from nlsid.report.render import render

    check_writable(output, force)
    page = render(source)
    write_text_atomic(output, render_html(page, f"nlsid {__version__} report"), force=force)
    summary = {"output": output, **page.summary()}
    if as_json:
        emit_json(summary)
        return summary
    console = settings().console
    console.print(page.headline, style="bold", markup=False)
    console.print(f"{len(page.figures)} figures, {len(page.tables)} tables -> {output}", markup=False)
    return summary
