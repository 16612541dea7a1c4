"""The result of fitting a model's free parameters to recorded runs: the estimates with their
uncertainty and the simulation errors per run (:func:`nlsid.fit.extension.fit_free_parameters` for
one output, :func:`nlsid.fit.mimo_output_error.fit_mimo_free_parameters` for several)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class RunError:
    """Simulation error of one run: rms of s_sim - s (the fitted signal s) over the steady state, the
    rms of y itself and the noise level (period-to-period std of s, NaN with fewer than two
    periods); the rms errors of y and u (NaN in open loop, where u is the recorded input)."""

    run_id: str
    role: str            # "estimation" or "validation"
    rms: float
    y_rms: float
    noise_rms: float
    start_rms: float     # the same error with the start values
    samples: int
    y_error_rms: float = math.nan
    u_error_rms: float = math.nan
    initial_state: dict | None = None  # the state fitted to an arbitrary record's start (its summary)


@dataclass
class ExtensionFit:
    """Result of :func:`fit_free_parameters` (arrays ordered like ``names``)."""

    names: list[str]
    start: np.ndarray
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    estimation_rms: float
    validation_rms: float
    start_estimation_rms: float
    start_validation_rms: float
    noise_rms_estimation: float
    noise_rms_validation: float
    runs: list[RunError]
    warnings: list[str]
    config: dict              # the config with the fitted values written in, without ``free``
    evaluations: int
    message: str
    samples: int = 0
    bounds: list[tuple[float, float]] = field(default_factory=list)
    fit_on: str = "y"
    signal_rms: dict = field(default_factory=dict)  # "y"/"u" -> {"estimation": rms, "validation": rms}
    jacobians: dict = field(default_factory=dict)  # "differences"/"sensitivities" -> Jacobians formed so

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def summary(self) -> dict:
        """Plain numbers for JSON and the fit report."""
        return {
            "parameters": {
                n: {"value": float(v), "std": float(s), "start": float(s0), "lower": lo, "upper": hi}
                for n, v, s, s0, (lo, hi) in zip(self.names, self.values, self.std, self.start, self.bounds)
            },
            "correlation": self.correlation.tolist(),
            "covariance": self.covariance.tolist(),
            "estimation_rms": self.estimation_rms,
            "validation_rms": self.validation_rms,
            "start_estimation_rms": self.start_estimation_rms,
            "start_validation_rms": self.start_validation_rms,
            "noise_rms_estimation": self.noise_rms_estimation,
            "noise_rms_validation": self.noise_rms_validation,
            "fit_on": self.fit_on,
            **{f"{signal}_{role}_rms": self.signal_rms.get(signal, {}).get(role, math.nan)
               for signal in ("y", "u") for role in ("estimation", "validation")},
            "runs": [dataclasses.asdict(r) for r in self.runs],
            "samples": self.samples,
            "evaluations": self.evaluations,
            "jacobians": dict(self.jacobians),
            "message": self.message,
            "warnings": list(self.warnings),
        }
