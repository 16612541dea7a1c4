"""Figures of a stage's result in a notebook: the PNG figures the command writes, as pyplot figures."""

from __future__ import annotations


def pyplot_figures(pngs: dict[str, bytes]) -> list:
    """One pyplot figure per PNG (titled with its file name), so that a notebook shows the figures
    the command line writes with ``--plots``, pixel for pixel, below the cell."""
    import io

    import matplotlib.image
    import matplotlib.pyplot as plt

    out = []
    for name, png in pngs.items():
        figure, axes = plt.subplots(figsize=(8, 6))
        axes.imshow(matplotlib.image.imread(io.BytesIO(png), format="png"))
        axes.set_axis_off()
        axes.set_title(name)
        out.append(figure)
    return out


def png_bytes(figure, dpi: int) -> bytes:
    """A matplotlib figure as PNG bytes at ``dpi`` (what the command writes as a file)."""
    import io

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()
