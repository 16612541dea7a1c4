"""A coupled mode: a second mass on the driven one, a resonance/anti-resonance pair that multiplies
the model, estimated by Levy's linearised least squares on the BLA ratio and refined by the fit
engine.

Physics. A load mass m2 coupled to the driven mass m1 by a spring k and a damper c:

    m1 x1'' = F - k (x1 - x2) - c (x1' - x2') - (what the model already has on m1),
    m2 x2'' = k (x1 - x2) + c (x1' - x2').

The second equation gives X2 = (c s + k) / (m2 s^2 + c s + k) X1, so the load pushes back on m1 with
(c s + k) (X2 - X1) = -m2 s^2 H(s) X1, H = (c s + k) / (m2 s^2 + c s + k): the driven mass moves
as if it weighed m1 + m2 H(s), which is m1 + m2 at low frequency (H(0) = 1), m1 at high frequency,
and infinite where m2 s^2 + c s + k = 0. For a free pair driven by F the motor position is

    X1 / F = (m2 s^2 + c s + k) / (s^2 (m1 m2 s^2 + (m1 + m2) (c s + k)))
           = 1 / ((m1 + m2) s^2) R(s),
    R(s) = (wr^2 / wa^2) (s^2 + 2 za wa s + wa^2) / (s^2 + 2 zr wr s + wr^2),

with the anti-resonance wa^2 = k / m2, 2 za wa = c / m2 (the load alone on the spring: there the
load's force cancels the drive's), the resonance wr^2 = (m1 + m2) k / (m1 m2) and 2 zr wr =
(m1 + m2) c / (m1 m2). So wr > wa, R(0) = 1 (the model that sees the total mass at low frequency is
right there), zr / za = wr / wa, and the mass ratio reading is

    (wr / wa)^2 - 1 = m2 / m1:

the load's mass over the driven mass (the part of the total that the low-frequency model lumps in).
With a spring and damper to the ground on m1 (a mass_spring_damper model), the stage's X1 / F is
(m2 s^2 + c s + k) / D(s), D of fourth order, whose roots are a low mode and the resonance; R is then
the exact factor between the stage and the model of its low mode with the same low-frequency gain
(what the user's model identified there is), with wr the resonance's natural frequency, and the
mass ratio reading holds to order (w0 / wa)^2, w0 the low mode.

Estimate. On the ratio R = G_BLA / G_model of the evidence (:func:`bla_ratios`), Levy's linearised
least squares on R (s^2 + a1 s + a0) = b2 s^2 + b1 s + b0, with weights ``1/std(R)`` as for the
missing resonance (:mod:`nlsid.diagnose.hypotheses.resonance`), in s / w_max (w_max the highest
excited line) so that the five columns are of one size; then wr^2 = a0, zr = a1 / (2 wr),
wa^2 = b0 / b2, za = b1 / (2 b2 wa). The gain b2 is not used: the extension has R(0) = 1. Those are
the start; the fit engine refines fr, fa, zr and za by the simulation error (``paths``). That
start assumes the model right at its low mode. A model of one mode that knows the driven mass alone
is not: the load moves the low mode too, R holds two pairs, and its second-order fit fails. For
such a model (:func:`_single_mode`) a second start is the fourth-order fit of the BLA itself
(:func:`_estimate_moved`), the model's own mode (f0, z0) and gain refined with the pair; of the two
starts the one whose extension simulates closer on the estimation runs is kept.

Extension. The model as a continuous ``zpk`` (a transfer function's roots; a mechanical template
through its transfer function, :func:`~nlsid.diagnose.hypotheses.resonance._as_transfer_function`)
with the mode ``{frequency: fa, damping: za}`` added to its zeros and ``{frequency: fr, damping:
zr}`` to its poles: a zpk mode is the unit-DC-gain factor (s^2 + 2 zeta w s + w^2) / w^2
(``docs/configs.md``), so the extended model is exactly the model times R, and the four parameters
are key paths that the fit engine writes (``model.poles[n].frequency``, ...).
"""

from __future__ import annotations

import copy
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.bla_ratio import bla_ratios
from nlsid.diagnose.hypotheses.resonance import _as_transfer_function, _as_zpk, _resonance_applies

MIN_DAMPING = 1e-3  # a start damping ratio at least this (the fit engine keeps the sign of its start)
SK_ITERATIONS = 6  # Levy's fit and five Sanathanan-Koerner passes
PARAMETERS = ("fr", "fa", "zr", "za")


def _estimate_coupled(ctx: Context) -> Estimate | str:
    ratios = bla_ratios(ctx)
    if not ratios:
        return "needs multisine runs (the BLA)"
    scale = max(float(np.max(w)) for w, _, _ in ratios)
    rows, rhs = [], []
    for w, R, var in ratios:
        x, weight = w / scale, 1 / np.sqrt(var)
        block = np.column_stack([R * 1j * x, R, x**2, -1j * x, -np.ones_like(R)]) * weight[:, None]
        rows += [block.real, block.imag]
        target = R * x**2 * weight
        rhs += [target.real, target.imag]
    X, y = np.vstack(rows), np.concatenate(rhs)
    est = regress(y, list(X.T), ["a1", "a0", "b2", "b1", "b0"])
    a1, a0, b2, b1, b0 = (est.values[k] for k in ("a1", "a0", "b2", "b1", "b0"))
    if a0 <= 0 or a1 <= 0:
        return "the BLA ratio shows no stable resonance"
    if b2 == 0 or b0 / b2 <= 0:
        return "the BLA ratio shows no anti-resonance (b0 / b2 <= 0: no pair of zeros near the imaginary axis)"
    wr, wa = math.sqrt(a0) * scale, math.sqrt(b0 / b2) * scale
    if wr <= wa:
        return (f"the BLA ratio's anti-resonance ({wa / (2 * math.pi):.4g} Hz) is not below its resonance "
                f"({wr / (2 * math.pi):.4g} Hz), as a mass coupled to the driven one puts it")
    zr, za = a1 * scale / (2 * wr), b1 / b2 * scale / (2 * wa)
    values = {"fr": wr / (2 * math.pi), "fa": wa / (2 * math.pi), "zr": zr, "za": max(za, MIN_DAMPING)}
    clipped = f"; za {za:.3g} from Levy, started at {MIN_DAMPING:g}" if za < MIN_DAMPING else ""
    return Estimate(values, {k: float("nan") for k in values}, est.explained_db,
                    "Levy's linearised least squares on the BLA ratio (start values)" + clipped)


def _single_mode(model: dict) -> bool:
    """The model is one mode and a gain (a mass_spring_damper, G = b0 / (s^2 + a1 s + a0))."""
    tf = _as_transfer_function(model)
    if tf.get("domain", "continuous") != "continuous":
        return False
    num, den = (np.trim_zeros(np.asarray(tf[key], dtype=float), "f") for key in ("num", "den"))
    return num.size == 1 and den.size == 3 and np.all(den / den[0] > 0)


def _mode(root: complex) -> tuple[float, float]:
    """(frequency in Hz, damping ratio) of a stable root pair."""
    w = abs(root)
    return w / (2 * math.pi), -root.real / w


def _estimate_moved(ctx: Context) -> Estimate | str:
    """A start where the coupled mass also moved the model's own mode (the user's model of the
    driven mass alone, or of the wrong total): Levy's linearised least squares on the measured BLA
    itself, G (s^4 + a3 s^3 + a2 s^2 + a1 s + a0) = b2 s^2 + b1 s + b0, iterated by Sanathanan and
    Koerner (1963: each pass weighted by 1 / (std(G) |D(s)|) of the pass before, which removes
    Levy's bias toward high frequencies; s in units of the highest excited line), the quartic's
    roots the low mode (f0, z0) and the resonance (fr, zr), the quadratic's the anti-resonance
    (fa, za), an unstable root reflected into the left half-plane; the gain G(0) = b0 / a0."""
    measured, _ = ctx.bla_levels
    if not measured:
        return "needs multisine runs (the BLA)"
    levels = [(2 * np.pi * a.lines.frequency(a.lines.excited), a.robust.G,
               a.robust.var_total if np.all(np.isfinite(a.robust.var_total)) else a.robust.var_noise)
              for a in measured]
    scale = max(float(np.max(w)) for w, _, _ in levels)
    den = np.array([1.0, 0.0, 0.0, 0.0, 0.0])
    for _ in range(SK_ITERATIONS):
        rows, rhs = [], []
        for w, G, var in levels:
            x = 1j * w / scale
            weight = 1 / (np.sqrt(np.maximum(var, 1e-30)) * np.maximum(np.abs(np.polyval(den, x)), 1e-12))
            block = np.column_stack([-G * x**3, -G * x**2, -G * x, -G, x**2, x, np.ones_like(G)]) * weight[:, None]
            rows += [block.real, block.imag]
            target = G * x**4 * weight
            rhs += [target.real, target.imag]
        X, y = np.vstack(rows), np.concatenate(rhs)
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
            return "the BLA has lines without a variance to weight a fourth-order fit by"
        a3, a2, a1, a0, b2, b1, b0 = np.linalg.lstsq(X, y, rcond=None)[0]
        den = np.array([1.0, a3, a2, a1, a0])
    poles, zeros = np.roots(den) * scale, np.roots([b2, b1, b0]) * scale
    pairs = sorted((complex(-abs(p.real), p.imag) for p in poles if p.imag > 0), key=abs)  # reflected if unstable
    if len(pairs) != 2 or not (zeros.imag != 0).all():
        return "the BLA shows no low mode, resonance and anti-resonance (a fourth-order fit)"
    zeros = -np.abs(zeros.real) + 1j * zeros.imag
    (f0, z0), (fr, zr), (fa, za) = _mode(pairs[0]), _mode(pairs[1]), _mode(zeros[0])
    if not f0 < fa < fr:
        return (f"the BLA's anti-resonance ({fa:.4g} Hz) does not lie between its low mode ({f0:.4g} Hz) and its "
                f"resonance ({fr:.4g} Hz), as a mass coupled to the driven one puts it")
    values = {"fr": fr, "fa": fa, "zr": zr, "za": max(za, MIN_DAMPING), "f0": f0, "z0": max(z0, MIN_DAMPING),
              "gain": float((b0 / a0).real)}
    paths = {"f0": "model.poles[0].frequency", "z0": "model.poles[0].damping", "gain": "model.gain",
             "fr": "model.poles[1].frequency", "zr": "model.poles[1].damping",
             "fa": "model.zeros[0].frequency", "za": "model.zeros[0].damping"}
    return Estimate(values, {k: float("nan") for k in values}, float("nan"),
                    "the model's own mode moved too: Levy's linearised least squares on the BLA (start values)",
                    paths=paths)


def _estimate(ctx: Context) -> Estimate | str:
    """The start on the BLA ratio (the model right at its low mode); for a model of one mode, where
    that finds no pair or the fourth-order start on the BLA simulates closer, that one."""
    ratio = _estimate_coupled(ctx)
    if not _single_mode(ctx.runner.data["model"]):
        return ratio
    moved = _estimate_moved(ctx)
    if isinstance(moved, str):
        return ratio
    if isinstance(ratio, str):
        return moved
    data = ctx.runner.data
    rss = [ctx.simulation_rss(_extend_coupled(data, e.values)) for e in (ratio, moved)]
    return moved if rss[1] < rss[0] else ratio


def _mass_ratio(values: dict) -> str:
    ratio = (values["fr"] / values["fa"]) ** 2 - 1
    return (f"mass ratio (fr/fa)^2 - 1 = {ratio:.4g}: the coupled mass over the driven mass, for a free pair "
            "(within (f0/fa)^2 with a spring to the ground, f0 its mode)")


def _extend_coupled(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    model = out["model"] = _as_zpk(out["model"])
    if "f0" in values:  # the model's own mode moved too (:func:`_estimate_moved`)
        model.update(zeros=[], poles=[{"frequency": float(values["f0"]), "damping": float(values["z0"])}],
                     gain=float(values["gain"]))
    model["zeros"] = model["zeros"] + [{"frequency": float(values["fa"]), "damping": float(values["za"])}]
    model["poles"] = model["poles"] + [{"frequency": float(values["fr"]), "damping": float(values["zr"])}]
    return out


def _paths(data: dict) -> dict[str, str]:
    """The added mode's key paths: the last zero and pole of the extended zpk."""
    model = _as_zpk(data["model"])
    zero, pole = f"model.zeros[{len(model['zeros'])}]", f"model.poles[{len(model['poles'])}]"
    return {"fr": f"{pole}.frequency", "zr": f"{pole}.damping", "fa": f"{zero}.frequency", "za": f"{zero}.damping"}


HYPOTHESES = (
    Hypothesis("coupled_mode", "A coupled mode (second mass)", "linear", "fr", "Hz",
               "BLA differs from the model by a resonance with an anti-resonance below it; no distortion",
               _resonance_applies, _estimate, _extend_coupled, PARAMETERS, _paths, _mass_ratio),
)
