"""Nonlinear blocks: static maps and the backlash (play) operator.

They serve as the nonlinear blocks of block-structured models (Wiener, Hammerstein, LPL) and as the
``input_nonlinearity`` / ``output_nonlinearity`` of a plant. Static maps y = f(x), sample by sample:

* ``polynomial``: y = sum_p a_p x^p, p = 0 .. P (seed 002, Eq. 1, with an optional a_0).
* ``saturation``: y = min(max(x, lower), upper).
* ``deadzone``: y = x - upper for x > upper, x - lower for x < lower, 0 in between.
* ``piecewise_linear``: straight lines through the points (x_i, y_i), continued beyond the first and
  last point by the first and last segment.

``backlash`` is a block with memory (the play operator of width w): the output stays where it is
while |x - y| <= w/2 and otherwise is dragged along, y[k] = x[k] -+ w/2. It starts at y = 0
(the play centred on the first input when |x[0]| <= w/2). On a sampled signal held between
samples (a DAC's zero-order hold) the play operator's output is itself held, so evaluating it at
the samples is exact.

The laws are implemented in :func:`nlsid.simulate.kernels.block` (the kernel's module, so that
numba's on-disk cache stays current) and applied to a signal by
:func:`nlsid.simulate.engine.apply_static`; this module encodes a block config for them.

Kinds and parameter vectors:

    0 identity []      1 polynomial [a_0, ..., a_P]      2 saturation [lower, upper]
    3 deadzone [lower, upper]      4 piecewise_linear [x_0 .. x_{n-1}, y_0 .. y_{n-1}]
    5 backlash [w / 2]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

IDENTITY, POLYNOMIAL, SATURATION, DEADZONE, PIECEWISE_LINEAR, BACKLASH = range(6)


def encode(config) -> tuple[int, np.ndarray]:
    """(kind, parameter vector) of a block config (:mod:`nlsid.io.model_config`); None is the identity."""
    if config is None:
        return IDENTITY, np.zeros(0)
    kind, values = {
        "polynomial": (POLYNOMIAL, lambda c: c.coefficients),
        "saturation": (SATURATION, lambda c: [c.lower, c.upper]),
        "deadzone": (DEADZONE, lambda c: [c.lower, c.upper]),
        "piecewise_linear": (PIECEWISE_LINEAR, lambda c: [*c.x, *c.y]),
        "backlash": (BACKLASH, lambda c: [0.5 * c.width]),
    }[config.type]
    return kind, np.array(values(config), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class StaticBlock:
    """A nonlinear block of a block structure: its kind and parameter vector (:func:`encode`)."""

    kind: int
    params: np.ndarray

    @property
    def memory(self) -> bool:
        """Whether its output depends on the input's history (the backlash; :func:`nlsid.simulate.engine.hysteretic`)."""
        return self.kind == BACKLASH


def static_block(config) -> StaticBlock:
    """The block of ``config`` (a backlash starts from y = 0 each time it is applied)."""
    return StaticBlock(*encode(config))
