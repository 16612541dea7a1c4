"""A missing resonance: the model times g wr^2 / (s^2 + 2 zeta wr s + wr^2), a mode of DC gain g.

Estimate. Levy's linearised least squares (Levy 1959) on the BLA ratio R = G_BLA / G_model of the
evidence (:func:`bla_ratios`), weighted by 1 / std(R): R (s^2 + a1 s + a0) = b0, so wr^2 = a0,
zeta = a1 / (2 wr) and the mode's DC gain g = b0 / a0 (1 where the model is right at low
frequency). Those are the start; the fit engine refines fr, zeta and the extended model's gain by
the simulation error (``paths``): Levy's equation error weights the lines by |s^2 + a1 s + a0|,
which biases the damping where the resonance is sharp.

Extension. The model as a continuous ``zpk`` (a transfer function's roots; a mechanical template
through its transfer function, :func:`_as_transfer_function`) with the pole mode ``{frequency: fr,
damping: zeta}`` added (a zpk mode is the unit-DC-gain factor wr^2 / (s^2 + 2 zeta wr s + wr^2),
``docs/configs.md``) and its gain times g: exactly the model times the mode. ``gain`` is the
extended zpk's gain (the model's own times g): the one key that the fit engine can refine for the
mode's gain.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, regress
from nlsid.diagnose.hypotheses.bla_ratio import bla_ratios
from nlsid.diagnose.simulation import ModelRunner


def _resonance_applies(runner: ModelRunner) -> str | None:
    model = runner.data["model"]
    if model["type"] == "transfer_function" and model.get("domain", "continuous") == "continuous":
        return None
    if runner.mechanical and not model.get("nonlinearities") and not model.get("initial"):
        return None
    return ("needs a continuous transfer_function model, or a mass_spring_damper or two_mass_stage without "
            "forces and initial state")

def _mechanical_transfer_function(model: dict) -> tuple[list[float], list[float]]:
    """(num, den) in s of a mechanical template from u to its output, from the equations of motion
    with force gain u:

    - mass_spring_damper  m x'' + c x' + k x = gain u:  X/U = gain / (m s^2 + c s + k);
    - two_mass_stage  m1 x1'' = gain u - k (x1 - x2) - c (x1' - x2') - c1 x1',
      m2 x2'' = k (x1 - x2) + c (x1' - x2') - c2 x2':  with P1 = m1 s^2 + (c + c1) s + k,
      P2 = m2 s^2 + (c + c2) s + k, D = P1 P2 - (c s + k)^2, X1/U = gain P2 / D (motor),
      X2/U = gain (c s + k) / D (load); D has no constant term (the stage is free: a pole at 0);

    times s for a velocity output (cancelling that pole).
    """
    gain = float(model.get("gain", 1.0))
    if model["type"] == "mass_spring_damper":
        num = np.array([gain])
        den = np.array([float(model["mass"]), float(model.get("damping", 0.0)), float(model.get("stiffness", 0.0))])
    else:
        m1, m2, k = float(model["motor_mass"]), float(model["load_mass"]), float(model["stiffness"])
        c, c1, c2 = (float(model.get(key, 0.0)) for key in ("damping", "motor_damping", "load_damping"))
        p1, p2, coupling = np.array([m1, c + c1, k]), np.array([m2, c + c2, k]), np.array([c, k])
        den = np.polysub(np.convolve(p1, p2), np.convolve(coupling, coupling))
        num = gain * (p2 if model.get("output_at", "load") == "motor" else coupling)
    if model.get("output", "position") == "velocity":  # times s; a free stage's pole at 0 cancels
        num, den = (num, den[:-1]) if den[-1] == 0 else (np.append(num, 0.0), den)
    return [float(v) for v in num], [float(v) for v in den]

def _as_transfer_function(model: dict) -> dict:
    """A mechanical template as its transfer function from u to the output
    (:func:`_mechanical_transfer_function`; the input/output blocks, offsets, input channels,
    output timing and the delay are kept)."""
    if model["type"] == "transfer_function":
        return model
    kept = ("input_nonlinearity", "output_nonlinearity", "delay", "input_offset", "output_offset", "input_channels",
            "output_timing")
    out = {k: v for k, v in model.items() if k in kept}
    num, den = _mechanical_transfer_function(model)
    out.update(type="transfer_function", domain="continuous", num=num, den=den)
    return out

def _entries(roots: np.ndarray) -> list:
    """Roots as zpk entries: a real root a number, a conjugate pair one ``[re, im]`` (im > 0)."""
    return [float(r.real) if r.imag == 0 else [float(r.real), float(r.imag)] for r in roots if r.imag >= 0]


def _as_zpk(model: dict) -> dict:
    """A continuous transfer function or a mechanical template as a zpk of the same response."""
    tf = _as_transfer_function(model)
    num, den = (np.trim_zeros(np.asarray(tf[key], dtype=float), "f") for key in ("num", "den"))
    out = {k: v for k, v in tf.items() if k not in ("type", "num", "den")}
    out.update(type="zpk", zeros=_entries(np.roots(num)) if num.size else [], poles=_entries(np.roots(den)),
               gain=float(num[0] / den[0]) if num.size else 0.0)
    return out


def _estimate_resonance(ctx: Context) -> Estimate | str:
    ratios = bla_ratios(ctx)
    if not ratios:
        return "needs multisine runs (the BLA)"
    rows, rhs = [], []
    for w, R, var in ratios:
        scale = 1 / np.sqrt(var)
        block = np.column_stack([R * 1j * w, R, -np.ones_like(R)]) * scale[:, None]
        rows += [block.real, block.imag]
        target = R * w**2 * scale
        rhs += [target.real, target.imag]
    X, y = np.vstack(rows), np.concatenate(rhs)
    est = regress(y, list(X.T), ["a1", "a0", "b0"])
    a1, a0, b0 = (est.values[k] for k in ("a1", "a0", "b0"))
    if a0 <= 0 or a1 <= 0:
        return "the BLA ratio shows no stable resonance"
    wr = math.sqrt(a0)
    fr_std = est.std["a0"] / (2 * wr) / (2 * math.pi)
    gain = _as_zpk(ctx.runner.data["model"])["gain"] * b0 / a0
    return Estimate({"fr": wr / (2 * math.pi), "zeta": a1 / (2 * wr), "gain": gain},
                    {"fr": fr_std, "zeta": float("nan"), "gain": float("nan")}, est.explained_db,
                    "Levy's linearised least squares on the BLA ratio (start values)")

def _extend_resonance(data: dict, values: dict) -> dict:
    out = copy.deepcopy(data)
    model = out["model"] = _as_zpk(out["model"])
    model["poles"] = model["poles"] + [{"frequency": float(values["fr"]), "damping": float(values["zeta"])}]
    model["gain"] = float(values["gain"])
    return out


def _paths(data: dict) -> dict[str, str]:
    """The added mode's key paths (the last pole of the extended zpk) and the zpk's gain."""
    pole = f"model.poles[{len(_as_zpk(data['model'])['poles'])}]"
    return {"fr": f"{pole}.frequency", "zeta": f"{pole}.damping", "gain": "model.gain"}


HYPOTHESES = (
    Hypothesis("missing_resonance", "A missing resonance", "linear", "fr", "Hz",
               "BLA differs from the model around one frequency; no distortion",
               _resonance_applies, _estimate_resonance, _extend_resonance, ("fr", "zeta", "gain"), _paths),
)
