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
the start; the fit engine refines fr, fa, zr and za by the simulation error (``paths``).

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
from nlsid.diagnose.hypotheses.resonance import _as_zpk, _resonance_applies

MIN_DAMPING = 1e-3  # a start damping ratio at least this (the fit engine keeps the sign of its start)
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


def _mass_ratio(values: dict) -> str:
    ratio = (values["fr"] / values["fa"]) ** 2 - 1
    return (f"mass ratio (fr/fa)^2 - 1 = {ratio:.4g}: the coupled mass over the driven mass, for a free pair "
            "(within (f0/fa)^2 with a spring to the ground, f0 its mode)")


def _extend_coupled(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    model = out["model"] = _as_zpk(out["model"])
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
               _resonance_applies, _estimate_coupled, _extend_coupled, PARAMETERS, _paths, _mass_ratio),
)
