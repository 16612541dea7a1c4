"""Simulating a linear model of several inputs and outputs (:class:`nlsid.models.lti.MimoStateSpace`)
on a recording's runs.

The model reads its inputs u_1 .. u_{n_u} from the run's signal u and its channels (the model's
``inputs``) and writes its outputs y_1 .. y_{n_y} as the run's y and channels (its ``outputs``),
with the run's ``inputs`` and ``outputs`` attributes set (format version 3, ``docs/formats.md``).

A continuous model runs on its exact zero-order-hold equivalent (the input held between samples,
as a DAC holds it; :func:`nlsid.models.lti.zoh`), a discrete one as it is, one step per sample:

    x[k+1] = Phi x[k] + Gamma p[k],   y[k] = C x[k] + D p[k],

p[k] the plant input: the inputs plus process noise, ``delay`` samples late, each through its
static block where the model gives it one (``input_nonlinearity``: p_a = f_a(u_a[k - d] + w_a[k])),
and each output through its block (``output_nonlinearity``: y_i = g_i(C_i x + D_i p)) before its
measurement noise is added. Where it starts:

* from rest, by default;
* ``steady`` on a periodic run without transient periods: in its periodic steady state, exactly.
  One period of N samples from rest ends in x_N; the state that one period brings back to itself
  solves x0 = Phi^N x0 + x_N, so x0 = (I - Phi^N)^{-1} x_N (the input periodic, the dead time
  taking the end of the period into its start). A model with a pole on or outside the stability
  boundary has no such state to settle in: it runs from rest, as for a SISO model;
* ``steady`` on an arbitrary run whose outputs are measured: from the initial state that fits
  its first L samples of every output by linear least squares,
  x0 = argmin sum_k || y[k] - y_rest[k] - C Phi^k x0 ||^2, k < L, L the samples in which the
  slowest mode decays to :data:`~nlsid.simulate.engine.STEADY_TOLERANCE` (as
  :mod:`nlsid.simulate.initial_state` for one output); from rest where L exceeds a quarter of the
  record or the run lacks a measured output. With output blocks this x0 is the linear least-squares
  one of the error the blocks leave (exact for blocks of slope one near the outputs' start, a
  first-order estimate otherwise), and the run is simulated from it through the blocks.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.blocks import StaticBlock
from nlsid.models.lti import MimoStateSpace, check_rate, delay_samples, stability
from nlsid.simulate.jit import njit  # numba, its cache outside the package (not `from numba`)
from nlsid.simulate.kernels import apply_block
from nlsid.simulate.noise import Noise

STEADY_TOLERANCE = 1e-6  # a free response below this fraction of its start counts as decayed
RECORD_SHARE = 0.25      # the free response must decay within this share of the record to fit x0


@njit(cache=True, nogil=True)
def state_loop(Phi, Gamma, C, D, P, x0, Y):  # pragma: no cover (compiled)
    """Run x[k+1] = Phi x[k] + Gamma P[:, k], Y[:, k] = C x[k] + D P[:, k] from x0 over the columns
    of P, writing Y in place; return the state after the last sample."""
    n, n_u, n_y = Phi.shape[0], Gamma.shape[1], C.shape[0]
    x = x0.copy()
    following = np.empty(n)
    for k in range(P.shape[1]):
        for i in range(n_y):
            acc = 0.0
            for j in range(n):
                acc += C[i, j] * x[j]
            for j in range(n_u):
                acc += D[i, j] * P[j, k]
            Y[i, k] = acc
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += Phi[i, j] * x[j]
            for j in range(n_u):
                acc += Gamma[i, j] * P[j, k]
            following[i] = acc
        for i in range(n):
            x[i] = following[i]
    return x


def _f64(a) -> np.ndarray:
    """A writable C-ordered float64 copy (one kernel signature, whatever the source)."""
    return np.array(a, dtype=np.float64, order="C")


def check_run(inputs: tuple[str, ...], outputs: tuple[str, ...], run: Run, where: str) -> None:
    """Refuse a run the model of ``inputs`` and ``outputs`` cannot simulate without losing a signal:
    an input of the model the run lacks, an input the run names that the model does not take (it
    would be dropped), or a channel of the run, not among its outputs, that an output of the
    model would overwrite. ``where`` names the run (``rec.h5:/runs/ID``)."""
    have = ", ".join(sorted(run.channels)) or "none"
    for name in inputs[1:]:
        if name not in run.channels:
            raise InputError(where, f"has no input {name!r} (the model's inputs: {', '.join(inputs)}; the run's "
                                    f"channels: {have})")
    unused = [name for name in run.inputs if name not in inputs]
    if unused:
        raise InputError(where, f"has input {unused[0]!r}, which the model does not take (its inputs: "
                                f"{', '.join(inputs)}): simulating it would drop that input")
    for name in outputs[1:]:
        if name in run.channels and name not in run.outputs:
            raise InputError(where, f"has a channel {name!r} that is not one of its outputs "
                                    f"({', '.join(run.outputs)}): the model's output {name!r} would overwrite it")


def signal_blocks(blocks: dict[str, StaticBlock], names: tuple[str, ...], X: np.ndarray) -> np.ndarray:
    """X (signals x samples) with row i passed through the static block of signal ``names[i]``
    (:mod:`nlsid.models.blocks`), rows without one as they are; X itself where no row has one."""
    if not blocks:
        return X
    out = np.array(X, dtype=np.float64)
    for i, name in enumerate(names):
        if name in blocks:
            out[i] = apply_block(blocks[name].kind, blocks[name].params, np.ascontiguousarray(out[i]))
    return out


def _delayed(P: np.ndarray, d: int, periodic: bool) -> np.ndarray:
    """P (n_u, n) ``d`` samples late: zeros before the record, or (``periodic``) the end of the
    record, which a periodic excitation repeats."""
    if not d:
        return P
    if periodic:
        return np.roll(P, d, axis=1)
    out = np.zeros_like(P)
    out[:, d:] = P[:, :-d]
    return out


def periodic_state(Phi: np.ndarray, Gamma: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The state x0 one period of the plant input P (n_u, N) brings back to itself:
    x0 = (I - Phi^N)^{-1} x_N, x_N the state after the period from rest."""
    n = Phi.shape[0]
    Y = np.empty((0, P.shape[1]))
    x_end = state_loop(_f64(Phi), _f64(Gamma), np.zeros((0, n)), np.zeros((0, P.shape[0])), _f64(P), np.zeros(n), Y)
    return np.linalg.solve(np.eye(n) - np.linalg.matrix_power(Phi, P.shape[1]), x_end)


def _decay_samples(model: MimoStateSpace, fs: float) -> float:
    """Samples in which the slowest mode decays to STEADY_TOLERANCE (inf: a mode that does not decay)."""
    poles = model.poles()
    if not poles.size:
        return 0.0
    with np.errstate(divide="ignore"):
        rates = -np.log(np.abs(poles)) * fs if model.discrete else -poles.real
    sigma = float(np.min(rates))
    return math.log(1 / STEADY_TOLERANCE) / sigma * fs if sigma > 0 else math.inf


def fitted_state(Phi: np.ndarray, C: np.ndarray, residual: np.ndarray, length: int) -> np.ndarray:
    """The least-squares x0 of residual[:, k] = C Phi^k x0, k < ``length`` (residual: the measured
    outputs less those simulated from rest, (n_y, n))."""
    n = Phi.shape[0]
    rows, M = [], C.copy()
    for _ in range(length):
        rows.append(M)
        M = M @ Phi
    O = np.concatenate(rows) if rows else np.zeros((0, n))
    return np.linalg.lstsq(O, residual[:, :length].T.reshape(-1), rcond=None)[0]


def simulate_mimo(model: MimoStateSpace, run: Run, noise: Noise | None = None, steady: bool = False) -> Run:
    """Simulate ``model`` on ``run`` (the module's docstring): the run with u and the model's other
    inputs as recorded (+ the input measurement noise), y and the other outputs simulated (+ the
    output noise), ``inputs`` and ``outputs`` the model's, r dropped (open loop).

    ``noise``: :class:`~nlsid.simulate.noise.Noise` of rows per input (``u``, ``process``) and per
    output (``y``) (:func:`nlsid.simulate.noise.draw_channels`); default none."""
    check_run(model.inputs, model.outputs, run, run.run_id)
    check_rate(model, run.fs, "model", run.run_id)
    n = run.n_samples
    d = delay_samples(model.delay, run.fs, "model.delay")
    if d >= n:
        raise InputError("model.delay", f"dead time of {d} samples is not shorter than the record ({n} samples)")
    U = np.stack([run.named_signal(name) for name in model.inputs]).astype(float)
    if noise is None:
        noise = Noise(np.zeros((model.n_inputs, n)), np.zeros((model.n_outputs, n)), np.zeros((model.n_inputs, n)))
    Phi, Gamma = model.stepped(1.0 / run.fs)
    periodic = steady and run.period is not None and run.transient_periods == 0 and model.order > 0 \
        and stability(model.poles(), model.discrete) == "stable"
    P = signal_blocks(model.input_blocks, model.inputs, _delayed(U, d, periodic) + _delayed(noise.process, d, False))
    x0 = np.zeros(model.order)
    if periodic:
        x0 = periodic_state(Phi, Gamma, signal_blocks(model.input_blocks, model.inputs,
                                                      _delayed(U, d, True)[:, :run.period]))
    Y = np.empty((model.n_outputs, n))
    args = (_f64(Phi), _f64(Gamma), _f64(model.C), _f64(model.D), _f64(P))
    state_loop(*args, _f64(x0), Y)
    Y = signal_blocks(model.output_blocks, model.outputs, Y)
    measured = run.y is not None and all(name in run.channels for name in model.outputs[1:])
    if steady and run.period is None and measured and model.order:
        length = _decay_samples(model, run.fs)
        if length <= RECORD_SHARE * n:
            outputs = np.stack([run.named_signal(name) for name in model.outputs])
            x0 = fitted_state(np.asarray(Phi), model.C, outputs - Y, max(math.ceil(length), 1))
            state_loop(*args, _f64(x0), Y)
            Y = signal_blocks(model.output_blocks, model.outputs, Y)
    if not np.all(np.isfinite(Y)):
        raise InputError("model", f"run {run.run_id}: the simulation diverged (an unstable model?)")
    U_rec, Y_rec = U + noise.u, Y + noise.y
    channels = {**run.channels, **{name: U_rec[i] for i, name in enumerate(model.inputs) if i},
                **{name: Y_rec[i] for i, name in enumerate(model.outputs) if i}}
    return dataclasses.replace(run, u=U_rec[0], y=Y_rec[0], r=None, channels=channels, inputs=tuple(model.inputs),
                               outputs=tuple(model.outputs))
