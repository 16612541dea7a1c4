"""How an excitation level of a BLA is named wherever it is shown: ``level 2 (rms 0.4 N)``.

The levels of a ``bla`` result are numbered from 0 in the order it finds them: the multisine
levels by rising level, then the levels of arbitrary runs (:mod:`nlsid.fit.bla_source`). That
index is what ``fit BLA --level`` takes, so it is the level's name in every table, page, figure
and message, with the rms of the input u it was measured at (and u's unit where it was recorded)
beside it. The runs' own ``level`` attribute (a design's nominal rms, say 1, 2, 4) stays in the
summaries and ``--json`` but is not used as a name: an option never takes it.

Examples
--------
>>> level_name(2, 0.4, "N")
'level 2 (rms 0.4 N)'
>>> level_name(0, 1.0000077)
'level 0 (rms 1)'
>>> level_name(1, None)
'level 1'
"""

from __future__ import annotations

import math


def level_name(index: int, u_rms: float | None, unit: str | None = None) -> str:
    """``level INDEX (rms U_RMS UNIT)``: the index ``--level`` takes, the input's rms (3 significant
    digits) and its unit where it is recorded; ``level INDEX`` alone where the rms is unknown."""
    if u_rms is None or not math.isfinite(u_rms):
        return f"level {index}"
    return f"level {index} (rms {u_rms:.3g}{f' {unit}' if unit else ''})"


def level_summary(index: int, u_rms: float | None) -> dict:
    """The level as ``--json`` and the fit report give it: ``{"index": INDEX, "rms": U_RMS}`` (rms null where unknown)."""
    return {"index": int(index), "rms": None if u_rms is None or not math.isfinite(u_rms) else float(u_rms)}
