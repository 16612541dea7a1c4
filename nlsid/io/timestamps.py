"""Sample rate of timestamped messages, with a check that the sampling is uniform.

A logger stores each message with a log time ``t_m`` (integer nanoseconds) and ``c_m >= 1``
samples; sample ``s_m = c_0 + ... + c_{m-1}`` is the first sample of message ``m``. Uniform
sampling at interval ``T`` means ``t_{m+1} - t_m = c_m T`` for every message. ``T`` is taken as the
median of ``(t_{m+1} - t_m) / c_m`` (robust against a few bad intervals, so the worst one can be
named), and every interval must lie within ``rel_tol * T`` of ``c_m T`` (or within 1 ns, the
resolution of the timestamps). The sample rate of a uniform record is then taken from its ends,
``fs = 1e9 (s_last - s_0) / (t_last - t_0)``, whose relative error is at most
``2 rel_tol T / (t_last - t_0)``: one allowed deviation at each end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlsid.errors import InputError

NS = 1e9
REL_TOL = 1e-3


@dataclass(frozen=True)
class Sampling:
    """A uniformly sampled record: first sample time (ns), sample interval (ns), rate and count."""

    t0_ns: int
    interval_ns: float
    fs: float
    n_samples: int

    @property
    def t_last_ns(self) -> float:
        return self.t0_ns + (self.n_samples - 1) * self.interval_ns


def uniform_sampling(times_ns: np.ndarray, counts: np.ndarray, where: str, rel_tol: float = REL_TOL) -> Sampling:
    """Check that messages at ``times_ns`` holding ``counts`` samples each are uniformly sampled.

    ``times_ns`` must be in log-time order. Raises InputError naming the worst interval (its
    sample index, its time since the first sample, and its deviation as a fraction of ``T``).
    """
    times = np.asarray(times_ns, dtype=np.int64)
    counts = np.asarray(counts, dtype=np.int64)
    n = int(counts.sum())
    if times.size < 2:
        raise InputError(where, f"{times.size} message(s) with {n} samples: at least 2 timestamped messages are needed to derive a sample rate")
    steps = np.diff(times)
    interval = float(np.median(steps / counts[:-1]))
    if interval <= 0:
        raise InputError(where, "timestamps do not increase: most messages share their log time with the next one")
    deviation = steps - counts[:-1] * interval
    allowed = max(rel_tol * interval, 1.0)
    bad = np.abs(deviation) > allowed
    if bad.any():
        worst = int(np.argmax(np.abs(deviation)))
        first = np.concatenate(([0], np.cumsum(counts)))[worst + 1]
        raise InputError(
            where,
            f"timestamps are not uniformly sampled: {int(bad.sum())} of {steps.size} intervals deviate by more than "
            f"{rel_tol:g} of the median sample interval {interval:.9g} ns; the worst, before sample {first} "
            f"({(times[worst + 1] - times[0]) / NS:.9g} s after the first), is {int(steps[worst])} ns where "
            f"{counts[worst] * interval:.9g} ns was expected ({deviation[worst] / interval:+.3g} intervals). "
            "Resample the data uniformly or map a uniformly sampled topic",
        )
    samples_between = int(counts[:-1].sum())
    fs = NS * samples_between / float(times[-1] - times[0])
    return Sampling(t0_ns=int(times[0]), interval_ns=NS / fs, fs=fs, n_samples=n)


def check_aligned(reference: Sampling, other: Sampling, names: tuple[str, str], where: str) -> None:
    """Check that two records sample the same instants: same count, first and last within T/2."""
    a, b = names
    if reference.n_samples != other.n_samples:
        raise InputError(
            where,
            f"{a} has {reference.n_samples} samples from t = {reference.t0_ns} ns and {b} has {other.n_samples} "
            f"from t = {other.t0_ns} ns: they must be sampled at the same instants",
        )
    half = reference.interval_ns / 2
    for label, ta, tb in (("first", reference.t0_ns, other.t0_ns), ("last", reference.t_last_ns, other.t_last_ns)):
        if abs(ta - tb) > half:
            raise InputError(
                where,
                f"the {label} samples of {a} and {b} are {abs(ta - tb) / reference.interval_ns:.3g} sample intervals "
                "apart: they must be sampled at the same instants (within half an interval)",
            )
