"""Cheap start values for force parameters of a mass-spring-damper: regression of the residual force.

For ``mass_spring_damper`` (m p'' + c p' + k p = gain u - F_nl, ``docs/configs.md``) the measured
output gives the missing force directly,

    F_nl(t) = gain u(t) - m p''(t) - c p'(t) - k p(t),

and each force law of the config is linear in its parameters: Coulomb fc sign(v) + fv v (per
direction: fc_pos [v > 0] - fc_neg [v < 0] + fv_pos v [v > 0] + fv_neg v [v < 0]), cubic
stiffness k3 p^3. Least squares of F_nl on those candidate signals gives fc, fv (or their sides)
and k3 without a single simulation. Signals: the mean over the steady-state periods of each run
(noise down by P); derivatives by the DFT (exact for a periodic band-limited signal:
X'(k) = j 2 pi k fs/N X(k)),
keeping the lines up to HARMONICS times the highest excited line, which holds the forces'
low harmonics and drops the noise that differentiation amplifies. Samples at low speed are left out: while a mass
sticks the friction force is anything within +-fc (not fc sign(v)), and the band-limited
derivatives smear the jump of sign(v) over a few samples around each reversal. The hold between samples and the
truncated harmonics bias the result by a few percent: a start value, refined by
:func:`nlsid.fit.extension.fit_free_parameters`.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run

HARMONICS = 7
SLIDING = 0.2   # samples with |v| below SLIDING x rms(v) are left out (sticking, sign changes)
_FRICTION = ("fc", "fv", "fc_pos", "fc_neg", "fv_pos", "fv_neg")
_CANDIDATES = {"coulomb": _FRICTION, "cubic_stiffness": ("k3",)}


def _kinematics(y: np.ndarray, fs: float, keep: int, output: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Band-limited position, velocity and acceleration of one period (lines 0..keep) from the
    measured position or velocity (a velocity's integral has mean zero)."""
    n = y.size
    spectrum = np.fft.rfft(y)
    spectrum[keep + 1:] = 0.0
    jw = 2j * np.pi * np.arange(spectrum.size) * fs / n
    if output != "position":
        spectrum[0] = 0.0
        spectrum[1:] /= jw[1:]
    return np.fft.irfft(spectrum, n), np.fft.irfft(jw * spectrum, n), np.fft.irfft(jw ** 2 * spectrum, n)


def force_regression(config_data: dict, runs: Sequence[Run], paths: Sequence[str]) -> dict[str, float]:
    """Start values of the free force parameters ``paths`` (``model.nonlinearities[i].fc``, ``.fv``,
    their sides ``.fc_pos`` ... ``.fv_neg``, ``.k3``) of a mass-spring-damper config from periodic
    runs (``u`` is the plant input, in open or closed loop). The other force parameters keep their config values; their forces are
    subtracted from the residual force first."""
    model = config_data.get("model", {})
    if model.get("type") != "mass_spring_damper":
        raise InputError("model", "start values by force regression need a mass_spring_damper model")
    forces = model.get("nonlinearities", [])
    names = [(i, name) for i, force in enumerate(forces) for name in _CANDIDATES.get(force.get("type"), ())]
    free = [(i, name) for i, name in names if f"model.nonlinearities[{i}].{name}" in paths]
    missing = set(paths) - {f"model.nonlinearities[{i}].{name}" for i, name in free}
    if missing:
        raise InputError("free", f"{sorted(missing)[0]}: force regression estimates only fc, fv, fc_pos, fc_neg, "
                                 "fv_pos, fv_neg (coulomb) and k3 (cubic_stiffness) of a mass_spring_damper")
    m, c, k = model["mass"], model.get("damping", 0.0), model.get("stiffness", 0.0)
    gain = model.get("gain", 1.0)
    friction = any(name in _FRICTION for _, name in free)
    rows, target = [], []
    for run in runs:
        if run.period is None or run.excited_bins is None:
            raise InputError(run.run_id, "force regression needs periodic runs with excited bins")
        keep = min(HARMONICS * int(run.excited_bins[-1]), run.period // 2 - 1)
        p, v, a = _kinematics(run.periods("y").mean(axis=0), run.fs, keep, model.get("output", "position"))
        u = run.periods("u").mean(axis=0)
        forward, backward = v > 0, v < 0
        signals = {"fc": np.sign(v), "fv": v, "fc_pos": forward * 1.0, "fc_neg": -1.0 * backward,
                   "fv_pos": v * forward, "fv_neg": v * backward, "k3": p ** 3}
        force = gain * u - m * a - c * v - k * p
        for i, name in names:
            if (i, name) not in free:
                force = force - forces[i].get(name, 0.0) * signals[name]
        chosen = np.abs(v) > SLIDING * np.sqrt(np.mean(v * v)) if friction else np.ones(v.size, bool)
        target.append(force[chosen])
        rows.append(np.stack([signals[name][chosen] for _, name in free], axis=1))
    X, F = np.vstack(rows), np.concatenate(target)
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(X / scale, F, rcond=None)
    return {f"model.nonlinearities[{i}].{name}": float(value) for (i, name), value in zip(free, theta / scale)}
