"""The measured FRF a transfer function is fitted to: one level of a ``bla.h5`` file.

The weight is the variance of the averaged BLA (book Section 7.4.2): the robust method's
``var_total`` (noise + stochastic nonlinear distortions, (6-3)) when the level has M >= 2
realizations, else the fast method's ``var_total`` ((6-55)), else the noise variance alone
(with a warning: nonlinear distortions are then missing from the weight and the cost check
flags them, book Section 7.5 (i)). A variance counts when it is finite, positive and its band mean
is above numerical precision next to mean |G|^2 (:mod:`nlsid.analysis.precision`). A noise-free
BLA, whose variances are zero within that precision, is fitted unweighted (least squares, every
line alike; ``weighted`` False).

Levels of arbitrary runs (``lpm_levels``, the Local Polynomial Method, docs/lpm.md) are numbered
after the multisine levels. Their weight is the LPM's ``var_G_smoothed`` (noise plus distortion,
its disturbance variance averaged over neighbouring lines: at least ``smoothed_dof`` degrees of
freedom q; docs/lpm.md, "Smoothed variance"), or ``var_G`` (q = ``dof``) in files written before
it or when the band was too short to smooth: each cost term is then about F(2, 2q) distributed,
as for sample variances from M = q + 1 realizations, so the expected cost is that of M = q + 1
(finite only for q >= 2, with a finite spread only for q >= 3). The lines are the record's DFT
bins (period = record length).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from nlsid.citations import BOOK
from nlsid.errors import InputError
from nlsid.fit.frf_data import FRFData
from nlsid.analysis.precision import PRECISION, negligible
from nlsid.io.bla_file import read_bla


def _finite(values) -> bool:
    return values is not None and bool(np.all(np.isfinite(values))) and bool(np.all(np.asarray(values) > 0))


@dataclass(frozen=True)
class BLALevel:
    """The FRF to fit, the standard deviations of the averaged BLA's noise and nonlinear parts
    (sqrt(var_noise), sqrt(var_nl / M), for the figure; NaN where unknown), warnings, and what the
    weights (the variances the cost check compares with) are: :data:`WEIGHTS`."""

    data: FRFData
    noise_std: np.ndarray
    nl_std: np.ndarray
    warnings: list[str]
    weights: str = ""
    weighted: bool = True   # False: a noise-free BLA, fitted by unweighted least squares (:data:`UNWEIGHTED`)


#: What the fit's weights measure, by source: the cost check compares the model error with these.
WEIGHTS = {
    "robust": "var_total of the robust method: noise plus stochastic nonlinear distortion, measured over realizations",
    "fast": "var_total of the fast method: noise plus stochastic nonlinear distortion, from one realization",
    "noise": "var_noise only: noise measured over periods, nonlinear distortion not included",
    "lpm": "var_G of the Local Polynomial Method: noise plus stochastic nonlinear distortion, from the local "
           "residuals (an upper bound of the noise)",
    "none": "none: a noise-free BLA (its variances are zero within numerical precision), fitted by unweighted "
            "least squares; the cost and the parameter std are taken against the numerical-precision floor "
            "(1e-9 of the rms |G|), so they measure how closely the model reproduces the BLA, not noise",
}


def _usable(values, G: np.ndarray) -> bool:
    """Finite, positive variances whose band mean is above numerical precision next to mean |G|^2."""
    return _finite(values) and not negligible(float(np.mean(values)), float(np.mean(np.abs(G) ** 2)))


def _zero(values, G: np.ndarray) -> bool:
    """Variances that are zero within numerical precision next to |G|^2 (noise-free data)."""
    if values is None or not np.all(np.isfinite(values)):
        return False
    return negligible(float(np.mean(np.maximum(values, 0.0))), float(np.mean(np.abs(G) ** 2)))


def _std(values, divisor: float, size: int) -> np.ndarray:
    if values is None:
        return np.full(size, np.nan)
    return np.sqrt(np.maximum(np.asarray(values, dtype=float) / divisor, 0.0))


def frf_from_bla(path: str | os.PathLike, level: int | None = None) -> BLALevel:
    """One level of ``bla.h5`` (multisine levels first, then arbitrary-run levels); ``level`` may
    be omitted when the file holds one level."""
    content = read_bla(path)
    return frf_from_levels(content["levels"], content["lpm_levels"], level, str(path))


def frf_from_levels(levels: list[dict], lpm_levels: list[dict], level: int | None, source: str,
                    option: str = "--level", container: str = "the file") -> BLALevel:
    """One level, as :func:`frf_from_bla` takes it, of levels in the layout of
    :func:`nlsid.io.bla_file.read_bla` (``levels``, ``lpm_levels``): a file read, or a BLA computed
    in memory laid out so. ``source`` names them in messages (the file, with the levels' groups
    after it), ``option`` the level's argument (``--level`` on the command line), ``container``
    what holds them."""
    path = source
    total = len(levels) + len(lpm_levels)
    if level is None:
        if total > 1:
            raise InputError(f"{path}", f"{total} levels in {container}; choose one with {option} 0..{total - 1} "
                                        "(multisine levels first, then levels of arbitrary runs)")
        level = 0
    if not 0 <= level < total:
        raise InputError(option, f"expected 0..{total - 1} for {path}, got {level}")
    if level >= len(levels):
        return _lpm_level(path, lpm_levels[level - len(levels)])
    chosen = levels[level]
    attrs, robust, fast = chosen["attrs"], chosen["robust"], chosen["fast"]
    where = f"{path}:/levels/{chosen['name']}"
    warnings = []
    weighted = True
    G_robust = np.asarray(robust["G"], dtype=complex)
    if _usable(robust.get("var_total"), G_robust):
        G, variance, weights = robust["G"], robust["var_total"], WEIGHTS["robust"]
        realizations = int(attrs["n_realizations"])
        if realizations < 7:
            warnings.append(f"weights from M = {realizations} realizations: the variance estimates are rough and the "
                            f"cost check approximate ({BOOK}, Section 6.1.1, advise M >= 7)")
    elif fast is not None and _usable(fast.get("var_total"), np.asarray(fast["G"], dtype=complex)):
        G, variance, weights = fast["G"], fast["var_total"], WEIGHTS["fast"]
        realizations = None
        warnings.append("weights: the fast method's total variance (one realization): the cost check is approximate")
    elif _usable(robust.get("var_noise"), G_robust):
        G, variance, weights = robust["G"], robust["var_noise"], WEIGHTS["noise"]
        realizations = None
        warnings.append("weights: noise variance only (one realization, no detection lines): nonlinear distortions "
                        "are not in the weight and raise the cost above its expected value")
    elif any(_zero(robust.get(name), G_robust) for name in ("var_total", "var_noise")):
        # noise-free data: no variance to weight with, every line counts alike (least squares); the
        # constant is the precision floor, so the cost check asks whether the model reproduces the
        # BLA to numerical precision
        G, weights, weighted, realizations = robust["G"], WEIGHTS["none"], False, None
        variance = np.full(G_robust.size, PRECISION**2 * float(np.mean(np.abs(G_robust) ** 2)))
    else:
        M, P = int(attrs["n_realizations"]), int(attrs["n_periods"])
        raise InputError(f"{where}/robust", f"no variance to weight the fit (M = {M} realization(s) x P = {P} "
                                            "period(s), no detection lines): measure M >= 2 realizations or "
                                            "P >= 2 periods")
    period = int(attrs["period"])
    data = FRFData(np.asarray(chosen["excited_bins"], dtype=np.int64), np.asarray(G, dtype=complex),
                   np.asarray(variance, dtype=float), float(attrs["fs"]), period, realizations)
    m = max(int(attrs["n_realizations"]), 1)
    size = data.bins.size
    return BLALevel(data, _std(robust.get("var_noise"), 1.0, size), _std(robust.get("var_nl"), m, size), warnings,
                    weights, weighted)


def _lpm_level(path, chosen: dict) -> BLALevel:
    """An ``lpm_levels`` group as the FRF to fit (module docstring)."""
    attrs = chosen["attrs"]
    where = f"{path}:/lpm_levels/{chosen['name']}"
    smoothed = chosen.get("var_G_smoothed") is not None and int(attrs.get("smoothing_lines", 1)) > 1
    name = "var_G_smoothed" if smoothed else "var_G"
    variance = np.asarray(chosen[name], dtype=float)
    usable = np.isfinite(variance) & (variance > 0) & np.isfinite(chosen["G"])
    if not usable.any():
        raise InputError(f"{where}/{name}", "no finite positive variance to weight the fit")
    dof = math.floor(float(attrs["smoothed_dof"])) if smoothed else int(attrs["dof"])
    warnings = [] if usable.all() else [f"{int((~usable).sum())} lines without a finite variance left out"]
    if dof < 3:
        warnings.append(f"weights from the LPM with q = {dof} degrees of freedom: the expected cost is "
                        f"{'infinite' if dof < 2 else 'finite but its spread is not'}, so the cost check cannot "
                        "judge the model (use more --lpm-lines or more records for q >= 3)")
    warnings.append("the LPM's estimates at neighbouring lines share their windows: the cost check's spread "
                    "assumes independent lines and is approximate")
    data = FRFData(np.asarray(chosen["bins"], dtype=np.int64)[usable], np.asarray(chosen["G"], dtype=complex)[usable],
                   variance[usable], float(attrs["fs"]), int(attrs["n_samples"]), dof + 1,
                   2 * int(attrs.get("half_width", 0)))
    size = data.bins.size
    weights = WEIGHTS["lpm"]
    if smoothed:
        weights += (f", its disturbance variance averaged over {int(attrs['smoothing_lines'])} lines (at least "
                    f"{float(attrs['smoothed_dof']):.3g} degrees of freedom instead of {int(attrs['dof'])})")
    return BLALevel(data, np.full(size, np.nan), np.full(size, np.nan), warnings, weights)
