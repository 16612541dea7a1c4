"""The poles and zeros of an LTI model split over two filters, G = G2 G1 (up to a gain), for the
Wiener-Hammerstein hypothesis (:mod:`nlsid.diagnose.hypotheses.wiener_hammerstein`).

The roots are taken in sections, a real root or a complex conjugate pair, and each section of the
numerator and of the denominator goes to G1 or G2, a pole pair also as two real poles, one in each
(:func:`choices`, :func:`splits`). A continuous split must leave
both filters proper. A discrete one is made causal by roots at the origin (:func:`realisable`). Each
filter is a ``zpk`` config in the model's domain, whose roots are the numbers the fit engine moves
(:func:`filter_values`, :func:`filter_from`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Factors:
    """An LTI model's roots (gain * prod(x - zeros) / prod(x - poles), x = s or z) in sections:
    a real root (a number) or a conjugate pair ``[re, im]`` (re +- j im, im > 0), as a ``zpk``
    config writes them. A discrete model's roots at the origin (a delay, from the z^-1 form) are
    kept apart as ``origin`` = (zeros at z = 0) - (poles at z = 0)."""

    zeros: tuple
    poles: tuple
    discrete: bool
    origin: int = 0


def sections(roots: np.ndarray) -> tuple:
    """Each real root as a number, each conjugate pair once as [re, im] with im > 0."""
    out = []
    for r in roots:
        if abs(r.imag) <= 1e-9 * max(abs(r), 1.0):
            out.append(float(r.real))
        elif r.imag > 0:
            out.append([float(r.real), float(r.imag)])
    return tuple(out)


def polynomials(model: dict) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of a transfer_function, zpk or state_space config in descending powers of x = s or
    z (a discrete transfer function's z^-1 lists padded to a common length: times z^L)."""
    from scipy.signal import ss2tf, zpk2tf

    if model["type"] == "transfer_function":
        num, den = np.asarray(model["num"], float), np.asarray(model["den"], float)
        if model.get("domain") == "discrete":
            size = max(num.size, den.size)
            num, den = (np.concatenate([c, np.zeros(size - c.size)]) for c in (num, den))
        return num, den
    if model["type"] == "zpk":
        from nlsid.models.lti import roots

        (z, z_scale), (p, p_scale) = roots(model["zeros"]), roots(model["poles"])
        num, den = zpk2tf(z, p, float(model["gain"]) * z_scale / p_scale)
        return np.real(num), np.real(den)
    b, den = ss2tf(np.asarray(model["A"], float), np.asarray(model["B"], float)[:, None],
                   np.asarray(model["C"], float)[None, :], float(model.get("D", 0.0)))
    return b[0], den


def factors(model: dict) -> Factors:
    """The sections of an LTI model config (:class:`Factors`)."""
    discrete = model.get("domain", "continuous") == "discrete"
    num, den = (np.trim_zeros(c, "f") for c in polynomials(model))
    zeros, poles = np.roots(num), np.roots(den)
    origin = 0
    if discrete:
        origin = int(np.sum(zeros == 0) - np.sum(poles == 0))
        zeros, poles = zeros[zeros != 0], poles[poles != 0]
    return Factors(sections(zeros), sections(poles), discrete, origin)


def order(entries) -> int:
    return sum(2 if isinstance(e, list) else 1 for e in entries)


def _real_pair(entry, discrete: bool) -> float:
    """The real root a pole pair turns into when split: its modulus, on the stable real axis."""
    modulus = math.hypot(*entry)
    return modulus if discrete else -modulus


def choices(f: Factors) -> list[list[tuple[tuple, tuple]]]:
    """Per section, where it may go as (part of G1, part of G2): a zero or a real pole to either
    filter; a pole pair to either, or split into two real poles at its modulus, one in each (a
    BLA fit may take two real poles of different filters for one damped pair)."""
    out = [[((z,), ()), ((), (z,))] for z in f.zeros]
    for p in f.poles:
        options = [((p,), ()), ((), (p,))]
        if isinstance(p, list):
            r = _real_pair(p, f.discrete)
            options.append(((r,), (r,)))
        out.append(options)
    return out


def count(f: Factors) -> int:
    return math.prod(len(c) for c in choices(f))


def splits(f: Factors) -> list[tuple[tuple, tuple, tuple, tuple]]:
    """Every (zeros of G1, poles of G1, zeros of G2, poles of G2) of :func:`choices` that keeps
    both filters realisable: proper in s; in z, any (:func:`realisable` adds roots at the origin)."""
    n_z = len(f.zeros)
    out = []
    for picked in itertools.product(*choices(f)):
        z1 = tuple(e for c in picked[:n_z] for e in c[0])
        z2 = tuple(e for c in picked[:n_z] for e in c[1])
        p1 = tuple(e for c in picked[n_z:] for e in c[0])
        p2 = tuple(e for c in picked[n_z:] for e in c[1])
        if f.discrete or (order(z1) <= order(p1) and order(z2) <= order(p2)):
            out.append((z1, p1, z2, p2))
    return out


def realisable(split, origin: int) -> tuple[tuple, tuple, tuple, tuple]:
    """A discrete split made causal: the origin roots z^origin in G1, then each filter's excess of
    zeros over poles e balanced by e poles at z = 0 in it and e zeros at z = 0 in the other (G2 G1
    unchanged: G is proper, so the other's excess stays <= 0)."""
    z1, p1, z2, p2 = split
    z1, p1 = z1 + (0.0,) * max(origin, 0), p1 + (0.0,) * max(-origin, 0)
    for _ in range(2):
        excess = order(z1) - order(p1)
        if excess > 0:
            p1, z2 = p1 + (0.0,) * excess, z2 + (0.0,) * excess
        z1, p1, z2, p2 = z2, p2, z1, p1  # the same for G2, then back
    return z1, p1, z2, p2


def zpk(zeros, poles, gain: float, discrete: bool) -> dict:
    return {"type": "zpk", "domain": "discrete" if discrete else "continuous",
            "zeros": [list(e) if isinstance(e, list) else float(e) for e in zeros],
            "poles": [list(e) if isinstance(e, list) else float(e) for e in poles], "gain": float(gain)}


def z_coefficients(config: dict, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) in z^-1 of a filter config at the sample rate fs: a continuous one by its zero-order
    hold equivalent, as the simulator steps it on a held signal."""
    from scipy.signal import cont2discrete

    num, den = polynomials(config)
    if config["domain"] == "discrete":
        return np.concatenate([np.zeros(den.size - num.size), num]), den  # descending in z, num delayed: z^-1 form
    b, a, _ = cont2discrete((num, den), 1.0 / fs, method="zoh")
    return np.ravel(b), np.ravel(a)


def apply(config: dict, fs: float, x: np.ndarray) -> np.ndarray:
    """The filter on the held signal x sampled at fs, from rest."""
    from scipy.signal import lfilter

    return lfilter(*z_coefficients(config, fs), x)


def stable(config: dict) -> bool:
    """Every pole inside the unit circle (discrete) or the left half plane (continuous)."""
    poles = [complex(*e) if isinstance(e, list) else complex(e) for e in config["poles"]]
    if config["domain"] == "discrete":
        return all(abs(p) < 1 for p in poles)
    return all(p.real < 0 for p in poles)


def describe(config: dict, fs: float) -> str:
    """The filter's poles as natural frequencies in Hz (a discrete pole z by s = fs ln z)."""
    roots = [complex(*e) if isinstance(e, list) else complex(e) for e in config["poles"]]
    roots = [r for r in roots if r != 0]
    if not roots:
        return "without poles"
    if config["domain"] == "discrete":
        roots = [np.log(r) * fs for r in roots]
    hz = sorted(abs(r) / (2 * math.pi) for r in roots)
    return f"poles at {', '.join(f'{v:.4g}' for v in hz)} Hz"


def filter_values(which: str, config: dict) -> dict[str, float]:
    """The filter's numbers by name: ``first.gain``, ``first.poles[0]`` (a real root),
    ``first.poles[1][0]`` and ``first.poles[1][1]`` (re and im of a pair), ..."""
    out = {f"{which}.gain": float(config["gain"])}
    for part in ("zeros", "poles"):
        for i, entry in enumerate(config[part]):
            if isinstance(entry, list):
                out.update({f"{which}.{part}[{i}][0]": entry[0], f"{which}.{part}[{i}][1]": entry[1]})
            else:
                out[f"{which}.{part}[{i}]"] = entry
    return out


def filter_from(values: dict, which: str, domain: str) -> dict:
    """The ``zpk`` config of a filter from its numbers (:func:`filter_values`)."""
    def part(name: str) -> list:
        entries: dict[int, list] = {}
        for key, v in values.items():
            if key.startswith(f"{which}.{name}["):
                entries.setdefault(int(key.split("[")[1][:-1]), []).append((key, float(v)))
        return [[v for _, v in sorted(e)] if len(e) == 2 else e[0][1] for _, e in sorted(entries.items())]
    return {"type": "zpk", "domain": domain, "zeros": part("zeros"), "poles": part("poles"),
            "gain": float(values[f"{which}.gain"])}


def to_sections(config: dict) -> dict[str, list[np.ndarray]]:
    """The filter's roots as section coefficients, ``{"zeros": [...], "poles": [...]}``: each
    entry's monic polynomial but its leading 1, a real root r as [-r], a pair re +- j im as
    [-2 re, re^2 + im^2]. Unlike (re, im), these move a pair continuously into two real roots."""
    def coefficients(entry) -> np.ndarray:
        if isinstance(entry, list):
            return np.array([-2 * entry[0], entry[0] ** 2 + entry[1] ** 2])
        return np.array([-float(entry)])
    return {part: [coefficients(e) for e in config[part]] for part in ("zeros", "poles")}


def from_sections(config: dict, coefficients: dict[str, list[np.ndarray]]) -> dict:
    """``config`` with the roots of the section ``coefficients`` (:func:`to_sections`) as its zeros
    and poles."""
    out = dict(config)
    for part, polys in coefficients.items():
        out[part] = [e for c in polys for e in sections(np.roots(np.concatenate([[1.0], c])))]
    return out
