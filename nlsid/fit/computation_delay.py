"""The computation delay of a closed loop chosen from measured data (``closed_loop.computation_delay: auto``).

A drive applies its command u[k] from sample k + d on (:mod:`nlsid.models.controller`), d a whole
number of samples its user rarely knows. Written ``auto`` (candidates 0..3) or ``{auto: {max: D}}``
(0..D), d is estimated as a discrete nuisance: for each candidate d the model is fitted with d
written in, on the estimation runs (``nlsid fit --model``: its free parameters, on the fitted
signal; ``nlsid diagnose``: its nuisances, :mod:`nlsid.diagnose.computation_delay`), and its cost

    V_d = sum over the estimation samples of (s_sim(n; theta_hat_d, d) - s(n))^2

(s the fitted signal, y or u) is kept; the d of the lowest cost wins and the fitted model carries
it as a whole number. A candidate the model refuses at its start values (its loop unstable with
that delay, its simulation diverged) is skipped with the reason.

Whether the data decide it: let a be the winner and b the runner-up, and write each residual on the
same samples as e = m + n, m the model's error and n the measurement noise, white with variance
sigma^2 per sample. Then

    V_b - V_a = ||m_b||^2 - ||m_a||^2 + 2 n^T (m_b - m_a),   m_b - m_a = e_b - e_a = delta,

and delta is measured (the two fitted simulations' difference). The noise's term has the standard
deviation 2 sigma ||delta||, so the order is decided by the data where

    V_b - V_a > Z 2 sigma ||delta||,   Z = 3,

and otherwise stated as not decided by the data (the lowest cost still chosen). The refit of the
parameters on each side is left out of this account (it lowers both costs alike to first order).
sigma is the noise level of the estimation runs where they measure it (two periods or more: the
period-to-period standard deviation, as in :func:`nlsid.fit.simulation_cost.floor_cost`); where
they do not (arbitrary records), the winner's rms error stands in for it: it holds the noise and
the model's error, so it is an upper bound, and a choice stated as decided is decided all the same.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.extension import ExtensionFit
from nlsid.fit.free_parameters import FreeParameter
from nlsid.fit.simulation_cost import Problem
from nlsid.io.model_config import AutoDelayConfig, validate_simulate_config
from nlsid.io.run import Run
from nlsid.models.key_paths import deep_copy

#: standard deviations of the noise's share of the cost difference beyond which the data decide
Z = 3.0
KEY = "closed_loop.computation_delay"


@dataclass(frozen=True)
class Candidate:
    """One candidate delay: its cost V_d and rms error of the fitted signal on the estimation runs
    (NaN when skipped), and why it was skipped (empty when fitted)."""

    delay: int
    cost: float
    rms: float
    reason: str = ""

    @property
    def fitted(self) -> bool:
        return not self.reason


@dataclass(frozen=True)
class DelayChoice:
    """The delay chosen among the candidates 0..max and how firmly (module docstring).

    ``difference``: V_runner_up - V_chosen; ``noise_part``: Z 2 sigma ||delta||, the difference the
    noise can make; ``noise``: sigma, ``noise_known``: measured (else the winner's rms error);
    ``runner_up`` None where no other candidate was fitted; ``by``: how each candidate was fitted
    (``free parameters`` or ``nuisances``)."""

    chosen: int
    signal: str
    candidates: tuple[Candidate, ...]
    decided: bool
    runner_up: int | None
    difference: float
    noise_part: float
    noise: float
    noise_known: bool
    by: str

    def summary(self) -> dict:
        """Plain numbers for JSON (``docs/formats.md``, ``computation_delay``)."""
        return {
            "chosen": self.chosen, "signal": self.signal, "by": self.by, "decided": self.decided,
            "runner_up": self.runner_up, "cost_difference": _number(self.difference),
            "noise_explains": _number(self.noise_part), "noise_rms": _number(self.noise),
            "noise_known": self.noise_known,
            "candidates": [{"delay": c.delay, "cost": _number(c.cost), "rms": _number(c.rms),
                            "skipped": c.reason or None} for c in self.candidates],
            "statement": self.statement(),
        }

    def statement(self) -> str:
        """The choice in words, with every candidate's rms error and the firmness."""
        largest = max(c.delay for c in self.candidates)
        each = "; ".join(f"{c.delay}: rms {c.rms:.4g}" + (" (chosen)" if c.delay == self.chosen else "")
                         if c.fitted else f"{c.delay}: skipped ({c.reason})" for c in self.candidates)
        head = (f"computation delay {self.chosen} sample{'s' if self.chosen != 1 else ''} (auto, 0..{largest}), "
                f"the lowest error of {self.signal} with the {self.by} fitted on the estimation runs: {each}")
        if self.runner_up is None:
            return head + "; the only candidate the model accepts"
        noise = (f"noise rms {self.noise:.3g}" if self.noise_known
                 else f"noise unknown (no two periods per run), bounded by the winner's rms error {self.noise:.3g}")
        versus = (f"{self.runner_up} costs {self.difference:.4g} more (sum of squares), the noise explains "
                  f"{self.noise_part:.3g} ({noise})")
        if self.decided:
            return f"{head}; decided by the data: {versus}"
        return f"{head}; NOT decided by the data: {versus}"


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def candidates_of(data: dict, source: str = "", lines: dict | None = None) -> int | None:
    """The largest candidate D where the config ``data`` asks for ``computation_delay: auto``
    (candidates 0..D), else None. Validates the config (errors name ``source`` and the line)."""
    config = validate_simulate_config(data, source, lines or {})
    loop = config.closed_loop
    if loop is None or not isinstance(loop.computation_delay, AutoDelayConfig):
        return None
    return int(loop.computation_delay.max)


def with_delay(data: dict, delay: int) -> dict:
    """A copy of the config ``data`` with ``closed_loop.computation_delay`` the whole number ``delay``."""
    out = deep_copy(data)
    out["closed_loop"]["computation_delay"] = int(delay)
    return out


def residual(fit: ExtensionFit, runs: Sequence[Run], signal: str, source: str = "") -> np.ndarray:
    """The fitted model's simulation error of ``signal`` on ``runs`` (every run's steady state, as
    the fit measures it: :meth:`nlsid.fit.simulation_cost.Problem.errors`), concatenated."""
    problem = Problem(fit.config, {name: FreeParameter(float(value)) for name, value in zip(fit.names, fit.values)},
                      source, {}, None, signal)
    errors = problem.errors(problem.start, list(runs), problem.inputs(runs))[signal]
    return np.concatenate(errors) if errors else np.zeros(0)


def choose_delay(data: dict, largest: int, fit: Callable[[dict], ExtensionFit], runs: Sequence[Run], signal: str,
                 by: str, source: str = "") -> tuple[ExtensionFit, DelayChoice]:
    """Fit the config ``data`` with each computation delay 0..``largest`` written in (``fit``: the
    config with the delay -> its :class:`~nlsid.fit.extension.ExtensionFit` on the estimation
    ``runs``), and choose the delay of the lowest cost of ``signal`` (module docstring).

    Returns the winner's fit (its ``config`` carries the whole number) and the
    :class:`DelayChoice`. A candidate whose fit raises :class:`~nlsid.errors.InputError` is
    skipped with its message; where every candidate is refused, the first one's error is raised
    (the same for all: as it is; otherwise one error listing each candidate's reason).
    """
    fits: dict[int, ExtensionFit] = {}
    refused: dict[int, InputError] = {}
    for delay in range(largest + 1):
        try:
            fits[delay] = fit(with_delay(data, delay))
        except InputError as exc:
            refused[delay] = exc
    if not fits:
        first = refused[0]
        if all(str(exc) == str(first) for exc in refused.values()):
            raise first
        raise InputError(f"{source}: {KEY}" if source else KEY,
                         "auto: no candidate delay could be fitted: "
                         + "; ".join(f"{d}: {exc}" for d, exc in refused.items()))
    cost = {d: f.estimation_rms ** 2 * f.samples for d, f in fits.items()}
    ranked = sorted(fits, key=lambda d: (cost[d], d))
    chosen = ranked[0]
    candidates = tuple(Candidate(d, cost[d], fits[d].estimation_rms) if d in fits
                       else Candidate(d, math.nan, math.nan, str(refused[d])) for d in range(largest + 1))
    winner = fits[chosen]
    noise_known = math.isfinite(winner.noise_rms_estimation)
    noise = winner.noise_rms_estimation if noise_known else winner.estimation_rms
    if len(ranked) == 1:
        return winner, DelayChoice(chosen, signal, candidates, True, None, math.nan, math.nan, noise, noise_known, by)
    runner_up = ranked[1]
    delta = residual(fits[runner_up], runs, signal, source) - residual(winner, runs, signal, source)
    noise_part = Z * 2.0 * noise * float(np.linalg.norm(delta))
    difference = cost[runner_up] - cost[chosen]
    return winner, DelayChoice(chosen, signal, candidates, bool(difference > noise_part), runner_up, difference,
                               noise_part, noise, noise_known, by)
