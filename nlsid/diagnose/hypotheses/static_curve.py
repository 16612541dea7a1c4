"""Static curves f(x) that enter linearly in their parameters, for the block between two filters:
a polynomial and a piecewise-linear curve, each a set of basis functions of x and the block config
of a parameter vector.

- :class:`Polynomial` of degree P: f(x) = sum_{p=1..P} a_p x^p (no constant: it would trade
  against the output offset through the second filter's DC gain).
- :class:`PiecewiseLinear` through K fixed knots t_0 < ... < t_{K-1} (at quantiles of x): f is the
  linear interpolation of its values y_j at the knots, continued beyond the first and last knot by
  the first and last segment (the ``piecewise_linear`` block's law), so f = sum_j y_j h_j(x) with
  the hat functions h_j. The hats sum to one everywhere, so the value at the central knot is fixed
  at 0 (the constant is the output offset's, as above) and the others are the parameters. A
  saturating curve, which a polynomial follows only with a high degree and wild extrapolation, is
  a few straight segments.

:func:`reading` says what a fitted curve is: saturating or expanding, symmetric or asymmetric.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SATURATING = 0.8   # end slope below this times the central slope: saturating (above its inverse: expanding)
ASYMMETRIC = 0.1   # even part above this share of the nonlinear part's rms: asymmetric


@dataclass(frozen=True)
class Polynomial:
    degree: int

    @property
    def names(self) -> list[str]:
        return [f"a{p}" for p in range(1, self.degree + 1)]

    def basis(self, x: np.ndarray) -> np.ndarray:
        """(P, n): x, x^2, ..., x^P."""
        return np.cumprod(np.broadcast_to(x, (self.degree, x.size)), axis=0)

    def values(self, theta: np.ndarray) -> dict[str, float]:
        """The curve's numbers by name, for the parameters theta: a_1 .. a_P."""
        return {n: float(v) for n, v in zip(self.names, theta)}

    def paths(self) -> dict[str, str]:
        return {f"a{p}": f"model.nonlinear.coefficients[{p}]" for p in range(1, self.degree + 1)}

    def describe(self) -> str:
        return f"a polynomial of degree {self.degree}"


@dataclass(frozen=True)
class PiecewiseLinear:
    knots: tuple[float, ...]

    @classmethod
    def at_quantiles(cls, x: np.ndarray, count: int) -> "PiecewiseLinear":
        """``count`` knots at equally spaced quantiles of x, from its 0.5th to its 99.5th percentile."""
        return cls(tuple(float(q) for q in np.quantile(x, np.linspace(0.005, 0.995, count))))

    @property
    def central(self) -> int:
        return len(self.knots) // 2

    @property
    def names(self) -> list[str]:
        return [f"y[{j}]" for j in range(len(self.knots)) if j != self.central]

    def basis(self, x: np.ndarray) -> np.ndarray:
        """(K - 1, n): the hat functions h_j(x) of every knot but the central one."""
        t = np.asarray(self.knots)
        i, w = _segment(t, x)
        hats = np.zeros((t.size, x.size))
        columns = np.arange(x.size)
        hats[i, columns] = 1 - w
        hats[i + 1, columns] += w
        return np.delete(hats, self.central, axis=0)

    def values(self, theta: np.ndarray) -> dict[str, float]:
        """The curve's numbers by name, for the parameters theta: the knots x[j] and the values y[j]
        (y at the central knot 0)."""
        y = np.insert(np.asarray(theta, float), self.central, 0.0)
        return {**{f"x[{j}]": float(t) for j, t in enumerate(self.knots)},
                **{f"y[{j}]": float(v) for j, v in enumerate(y)}}

    def paths(self) -> dict[str, str]:
        return {name: f"model.nonlinear.{name}" for name in self.names}

    def describe(self) -> str:
        return f"a piecewise-linear curve through {len(self.knots)} knots"


def block(values: dict[str, float]) -> dict:
    """The block config of a curve's numbers (:meth:`Polynomial.values`, :meth:`PiecewiseLinear.values`)."""
    def listed(prefix: str) -> list[float]:
        return [float(values[f"{prefix}[{j}]"]) for j in range(sum(1 for k in values if k.startswith(f"{prefix}[")))]
    if "x[0]" in values:
        return {"type": "piecewise_linear", "x": listed("x"), "y": listed("y")}
    degree = max(int(k[1:]) for k in values if k[0] == "a" and k[1:].isdigit())
    return {"type": "polynomial", "coefficients": [0.0] + [float(values[f"a{p}"]) for p in range(1, degree + 1)]}


def _segment(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index i of the segment (t_i, t_{i+1}) of each x (the end segments continued beyond the
    knots) and the position w = (x - t_i) / (t_{i+1} - t_i) in it."""
    i = np.clip(np.searchsorted(t, x) - 1, 0, t.size - 2)
    return i, (x - t[i]) / (t[i + 1] - t[i])


def curve(block: dict):
    """f as a function of arrays, from its block config."""
    if block["type"] == "polynomial":
        return np.polynomial.Polynomial(block["coefficients"])
    t, y = np.asarray(block["x"], float), np.asarray(block["y"], float)

    def f(x):
        i, w = _segment(t, np.asarray(x, float))
        return y[i] + (y[i + 1] - y[i]) * w
    return f


def end_slope_ratio(block: dict, x_range: tuple[float, float]) -> tuple[float, float]:
    """The slopes of f at the two ends of x's range over its slope at the centre, smaller first."""
    lo, hi = x_range
    grid = np.linspace(lo, hi, 201)
    slope = np.gradient(curve(block)(grid), grid)
    centre = abs(slope[100]) or 1e-300
    ends = sorted((abs(slope[2]) / centre, abs(slope[-3]) / centre))
    return ends[0], ends[1]


def reading(block: dict, x_range: tuple[float, float]) -> str:
    """Saturating / expanding (:func:`end_slope_ratio` against SATURATING) and symmetric /
    asymmetric (the even part of f(x) - f(0) - f'(0) x on the symmetric part of x's range)."""
    lo, hi = x_range
    f = curve(block)
    low, high = end_slope_ratio(block, x_range)
    words = ["saturating" if low < SATURATING else "expanding" if high > 1 / SATURATING else "nearly linear"]
    m = min(-lo, hi)
    if m > 0:
        grid = np.linspace(-m, m, 201)
        h = 1e-3 * m
        g = f(grid) - f(0.0) - (f(h) - f(-h)) / (2 * h) * grid
        even = 0.5 * (g + g[::-1])
        nonlinear = math.sqrt(float(np.mean(g**2)))
        words.append("asymmetric" if nonlinear > 0 and math.sqrt(float(np.mean(even**2))) > ASYMMETRIC * nonlinear
                     else "symmetric")
    return (f"{', '.join(words)} static curve (slopes at the ends of x's range {low:.2f} and {high:.2f} times "
            "the slope at its centre)")
