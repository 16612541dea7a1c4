"""The numerical-precision floor: when a noise level or a residual counts as zero.

A noise-free recording (a simulation without ``disturbances``) repeats from period to period up
to rounding, and a model compared with its own noise-free simulation leaves a residual of zero up
to rounding. Such a level is not noise to test against: it is *zero within numerical precision*.

A power ``p`` counts as zero next to a reference power ``ref`` of the signal it belongs to (the
measured output's power over the same runs) when

    p <= PRECISION**2 * ref,    PRECISION = 1e-9 (amplitude, -180 dB in power).

Why 1e-9: double precision rounds at 1.1e-16, and the simulator's exact discretisations agree
with independent computations to about 1e-13 of the signal (``docs/commands.md``, numerical
method), also with a free mass's integrator accumulating rounding; any measured noise is far
above 1e-9 of the signal (a 24-bit converter's quantisation step is 6e-8 of its full scale, data
stored as float32 carry 6e-8 of rounding). So a level below the floor is rounding, one above it
is a property of the data.
"""

from __future__ import annotations

import math

PRECISION = 1e-9
PRECISION_DB = 20 * math.log10(PRECISION)  # -180 dB: the floor as a power ratio in dB


def negligible(power: float, reference: float) -> bool:
    """True when ``power`` is zero within numerical precision next to ``reference`` (module docstring).

    A NaN ``power`` is unknown, never negligible; a zero reference makes only a zero power negligible.
    """
    if not math.isfinite(power):
        return False
    return power <= PRECISION**2 * max(reference, 0.0) if math.isfinite(reference) else False
