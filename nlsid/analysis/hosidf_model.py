"""Analytic HOSIDFs from a model config: block structures with polynomial blocks (seed 002).

A model config (``docs/configs.md``, read by ``nlsid simulate``) of type ``wiener``,
``hammerstein``, ``wiener_hammerstein`` or ``lpl`` whose nonlinear blocks are all ``polynomial``
is an N-branch LPL system of seed 002 Definition 1. Each LTI block becomes its frequency response
``G(w) = C (xI - A)^{-1} B + D`` at ``x = i w`` (continuous) or ``x = e^{i w / fs}`` (discrete),
times ``e^{-i w tau}`` for a dead time ``tau``; then :func:`lpl_hosidf` gives Lemma 2.

Seed 002 Eq. (1) has no constant term, so a polynomial with a nonzero ``coefficients[0]`` is
refused rather than silently dropped.
"""

from __future__ import annotations

import os

import numpy as np

from nlsid.analysis.hosidf_analytic import Branch, Response
from nlsid.citations import SPECTRAL_ANALYSIS
from nlsid.errors import InputError


def _response(config, fs: float, where: str) -> Response:
    from nlsid.models.from_config import lti

    ss = lti(config, where)

    def response(omega: float) -> complex:
        point = np.exp(1j * omega / fs) if ss.discrete else 1j * omega
        return complex(ss.frequency_response(point)[0] * np.exp(-1j * omega * ss.delay))

    return response


def _branch(before, nonlinear, after, fs: float, where: str) -> Branch:
    if nonlinear.type != "polynomial":
        raise InputError(f"{where}.nonlinear",
                         f"analytic HOSIDFs ({SPECTRAL_ANALYSIS}) need a polynomial block, got '{nonlinear.type}'")
    coefficients = list(nonlinear.coefficients)
    if coefficients[0] != 0:
        raise InputError(f"{where}.nonlinear.coefficients[0]",
                         f"{SPECTRAL_ANALYSIS}, Eq. 1, has no constant term; analytic HOSIDFs need "
                         "coefficients[0] = 0")
    if len(coefficients) < 2:
        raise InputError(f"{where}.nonlinear.coefficients", "the polynomial has no term of degree >= 1")
    pre = _response(before, fs, f"{where}.before") if before is not None else None
    post = _response(after, fs, f"{where}.after") if after is not None else None
    return Branch(tuple(float(c) for c in coefficients[1:]), pre=pre, post=post)


def branches_from_model(model, fs: float) -> list[Branch]:
    """The LPL branches of a validated ``model`` config section (see the module docstring)."""
    kind = model.type
    if kind == "wiener":
        return [_branch(model.linear, model.nonlinear, None, fs, "model")]
    if kind == "hammerstein":
        return [_branch(None, model.nonlinear, model.linear, fs, "model")]
    if kind == "wiener_hammerstein":
        return [_branch(model.first, model.nonlinear, model.second, fs, "model")]
    if kind == "lpl":
        return [_branch(b.before, b.nonlinear, b.after, fs, f"model.branches[{i}]") for i, b in enumerate(model.branches)]
    raise InputError("model.type", f"analytic HOSIDFs need a wiener, hammerstein, wiener_hammerstein or lpl model, got '{kind}'")


def branches_from_data(data: dict, fs: float, source: str = "model") -> list[Branch]:
    """The LPL branches of a model config given as plain data (a loaded YAML, or
    :meth:`nlsid.Model.to_dict`); errors name ``source`` and the key."""
    from nlsid.io.model_config import validate_simulate_config

    config = validate_simulate_config(data, source, {})
    try:
        return branches_from_model(config.model, fs)
    except InputError as exc:
        raise InputError(f"{source}: {exc.where}", exc.what) from None


def branches_from_config(path: str | os.PathLike, fs: float) -> list[Branch]:
    """Load a model config file and return its LPL branches; errors name the file and key."""
    from nlsid.io.config import load_config
    from nlsid.io.model_config import SimulateConfig

    config = load_config(path, SimulateConfig)
    try:
        return branches_from_model(config.model, fs)
    except InputError as exc:
        raise InputError(f"{path}: {exc.where}", exc.what) from None
