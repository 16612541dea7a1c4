"""The sources the report, the help and the warnings cite, as a reader finds them.

Code docstrings cite the source documents by their file (``seed 000 Fig. 3``, ``book Ex. 92``);
everything a user reads cites them by authors, venue and year, with the figure, equation,
section or exercise: ``Rijlaarsdam et al., ACC 2010, Fig. 3``. :data:`SOURCES` maps each short
citation to its full reference; a report page lists the full reference of every source it cites
(:func:`cited`).
"""

from __future__ import annotations

MOTION_STAGES = "Rijlaarsdam et al., ACC 2010"  # seed 000
SPECTRAL_ANALYSIS = "Rijlaarsdam et al., Automatica 2011"  # seed 002
FRICTION_COMPENSATION = "Rijlaarsdam et al., ACC 2011"  # seed 003
BOOK = "Schoukens, Pintelon and Rolain 2012"  # seed 004, mapped in shared/book-digest.md

SOURCES = {
    MOTION_STAGES: "D. Rijlaarsdam, B. van Loon, P. Nuij and M. Steinbuch, \"Nonlinearities in industrial motion "
                   "stages – detection and classification\", Proceedings of the American Control Conference (ACC), "
                   "2010, pp. 6644–6649.",
    SPECTRAL_ANALYSIS: "D. Rijlaarsdam, P. Nuij, J. Schoukens and M. Steinbuch, \"Spectral analysis of block "
                       "structured nonlinear systems and higher order sinusoidal input describing functions\", "
                       "Automatica (brief paper), 2011.",
    FRICTION_COMPENSATION: "D. Rijlaarsdam, P. Nuij, J. Schoukens and M. Steinbuch, \"Frequency domain based "
                           "friction compensation – industrial application to transmission electron microscopes\", "
                           "Proceedings of the American Control Conference (ACC), 2011.",
    BOOK: "J. Schoukens, R. Pintelon and Y. Rolain, Mastering System Identification in 100 Exercises, IEEE Press "
          "and John Wiley & Sons, 2012.",
}


def cited(text: str) -> list[str]:
    """The full references of the sources cited in ``text``, in the order of :data:`SOURCES`."""
    return [reference for short, reference in SOURCES.items() if short in text]
