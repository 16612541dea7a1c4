"""``nlsid design``: excitation signals from a config (being written)."""
import click


@click.command()
def design() -> None:
    """Design excitation signals."""
