"""The measured BLA against the model's, per level and over the levels.

At the excited lines of each multisine level the measured BLA (robust method, book Section 6.1.1;
the reference method in closed loop) is compared with the model's BLA computed in the same way
from the simulated runs: per line the gain error ``20 log10 |G/G_model|`` (dB), the phase error,
and the test ``|G - G_model|^2 / var(G) > F_{0.95}(2, 2M - 2)`` of the measured BLA's total
variance (book (6-88), Exercise 92: the model's BLA lies outside the 95% confidence circle).

Across levels (seed 000 Figs. 4-5) the change of the
measured and of the model's BLA with the excitation level.
"""

from __future__ import annotations

import math

import numpy as np

from nlsid.analysis.modes import SIGNIFICANCE
from nlsid.analysis.precision import PRECISION
from nlsid.diagnose.significance import ALPHA

BLA_PROBABILITY = 0.95


def compare_bla(measured, model) -> dict:
    """Measured BLA against the model's at one level's excited lines (module docstring)."""
    from nlsid.analysis.confidence import f_quantile_2

    G, Gm = measured.robust.G, model.robust.G
    M = measured.robust.n_realizations
    variance = measured.robust.var_total
    observations = M
    if not np.all(np.isfinite(variance)):
        variance, observations = measured.robust.var_noise, M * measured.robust.n_periods
    threshold = f_quantile_2(BLA_PROBABILITY, 2 * observations - 2)
    # noise-free data: a zero variance is the numerical precision of G (a circle of that radius)
    variance = np.maximum(variance, PRECISION**2 * np.abs(G) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.abs(G - Gm) ** 2 / variance
    outside = z > threshold
    with np.errstate(divide="ignore"):  # a measured G of exactly 0 (a constant output): -inf dB, said in words
        gain_db = 20 * np.log10(np.abs(G) / np.abs(Gm))
    phase_deg = np.degrees(np.angle(G / Gm))
    freq = measured.lines.frequency(measured.lines.excited)
    worst = int(np.argmax(np.where(outside, np.abs(gain_db), -1))) if outside.any() else None
    return {
        "level": measured.level, "u_rms": measured.u_rms, "lines": int(G.size),
        "outside_bounds": int(outside.sum()), "outside_fraction": float(outside.mean()),
        "expected_fraction": 1 - BLA_PROBABILITY,
        "gain_error_max_db": float(gain_db[np.argmax(np.abs(gain_db))]),
        "phase_error_max_deg": float(phase_deg[np.argmax(np.abs(phase_deg))]),
        "worst_frequency_hz": float(freq[worst]) if worst is not None else float("nan"),
        "frequency_hz": freq, "G": G, "G_model": Gm, "radius": measured.robust.bounds.radius,
        "gain_error_db": gain_db, "phase_error_deg": phase_deg, "outside": outside,
    }


def bla_significant(row: dict) -> bool:
    """More lines outside the 95% circles than chance: a binomial test at :data:`ALPHA`."""
    from scipy.stats import binom

    return bool(binom.sf(row["outside_bounds"] - 1, row["lines"], row["expected_fraction"]) < ALPHA)


def level_findings(rows: list[dict], across: dict) -> list[str]:
    """The change of the measured BLA over the levels and the model's, in words, or why there is none.

    ``rows`` are :func:`nlsid.analysis.levels.across_levels` rows with ``model_bla_change_max_db``,
    ``across`` the rest of the measured ``across_levels`` (``not_compared``, ``lines_compared``).
    The change is that of the highest level compared with the reference (the lowest), on the lines
    excited at every level: a level that was not compared never reads as a change of 0 dB.
    """
    if len(rows) < 2:
        return []
    compared = [row for row in rows if row.get("bla_change_max_db") is not None]
    if not compared:
        reasons = sorted({row["bla_not_compared"] for row in rows[1:] if row.get("bla_not_compared")})
        return [f"BLA not compared over the levels: {'; '.join(reasons) or 'no common lines'}"]
    out = _mode_findings(across.get("modes", []))
    last = compared[-1]
    model = last.get("model_bla_change_max_db")
    model_text = "" if model is None or not math.isfinite(model) else f"; the model's by {model:+.1f} dB"
    aside = [row for row in rows[1:] if row.get("bla_change_max_db") is None]
    return [f"BLA changes by up to {last['bla_change_max_db']:+.1f} dB (mean {last['bla_change_mean_db']:+.2f} dB "
            f"over {last['bla_compared_lines']} lines excited at every level) from level {level_name(rows[0]['level'])} "
            f"to level {level_name(last['level'])}{model_text}"
            + (f"; {len(aside)} level(s) not compared ({aside[0]['bla_not_compared']})" if aside else "")] + out


def _mode_findings(modes: list[dict]) -> list[str]:
    """Each resonance whose frequency or damping changes significantly from the lowest to the highest
    level, with the relative changes and their standard errors (:mod:`nlsid.analysis.modes`); the
    others in one line."""
    out, quiet, alone = [], [], []
    for mode in modes:
        if mode["significant"]:
            out.append(f"mode near {mode['frequency_hz']:.3g} Hz: frequency {_percent(mode, 'frequency')}, damping "
                       f"{_percent(mode, 'damping')} from level {level_name(mode['from_level'])} to level "
                       f"{level_name(mode['to_level'])}: significant ({SIGNIFICANCE:g} standard errors)")
        elif mode["to_level"] == mode["from_level"]:
            alone.append(f"{mode['frequency_hz']:.3g}")
        else:
            quiet.append(f"{mode['frequency_hz']:.3g}")
    if quiet:
        out.append(f"mode{'s' if len(quiet) > 1 else ''} near {', '.join(quiet)} Hz: no significant change of "
                   "frequency or damping over the levels")
    if alone:
        out.append(f"mode{'s' if len(alone) > 1 else ''} near {', '.join(alone)} Hz: fitted at the lowest level only")
    return out


def _percent(mode: dict, name: str) -> str:
    """A relative change and its standard error in percent, e.g. ``-1.3 % +- 0.07 %``."""
    return f"{100 * mode[f'{name}_change']:+.2g} % +- {100 * mode[f'{name}_change_se']:.2g} %"


def level_name(level) -> str:
    return "-" if level is None else f"{level:g}"
