"""Forward sensitivities of a simulation: the derivatives of the simulated u and y with respect to
a model's parameters, for the models whose simulation is smooth in them.

The kernel (:mod:`nlsid.simulate.kernels`) computes, sample by sample, a map

    x[k+1] = F(x[k], xc[k], q[k], c, k),   y[k] = H(x[k], xc[k], q[k], c, k)

of the plant state x, the controller state xc and the dead time's buffer q, whose coefficients c
(Phi^M, Gamma_M, the force rows and columns of :mod:`nlsid.simulate.propagation`, the read-out
c_x, c_p, c_f, the controller's matrices, the blocks' and forces' parameters, the offsets) are
functions of the model's parameters theta. Differentiating the recursion (the forward, or
tangent, sensitivity equations of the discrete-time system: Ljung 1999, System Identification,
Section 10.3, the gradient of the output error by filtering; Cao, Li, Petzold and Serban 2003,
SIAM J. Sci. Comput. 24(3), for the continuous form) gives for each direction i

    dx[k+1] = F_x dx[k] + F_xc dxc[k] + F_q dq[k] + F_c dc/dtheta_i,   dx[0] = dx0/dtheta_i,

the same loop once more per parameter, carried along with the nominal one. It is exact for the
discrete map the kernel computes where that map is differentiable: plants (not block structures)
whose forces are cubic or polynomial stiffness (a force of the midpoint of the read-out over the
sub-step, a polynomial: its derivative is the polynomial's), whose input and output blocks are the
identity or polynomials, in open or closed loop. Friction (its stick-slip decision), saturation,
deadzone, backlash and piecewise-linear curves have kinks: their parameters keep finite
differences (:func:`smooth` says which). The dead time in whole samples, the lag flag and the
number of sub-steps are structure, not parameters: a parameter that would change them
(:func:`sensitivities` checks it) is not differentiated here either.

The derivatives of the coefficients dc/dtheta_i come from the model's own construction (the
config validated and built, the ZOH matrices computed, :func:`nlsid.simulate.engine.plant_arguments`)
at theta +- h_i, a central difference with h_i = COEFFICIENT_STEP |theta_i| (COEFFICIENT_STEP if
theta_i = 0): the coefficients are analytic functions (matrix exponentials, products) of theta, so
the error is O(h^2) relative, about 1e-10, far below the finite-difference Jacobian's O(h) of 1e-3
(``diff_step``), and their cost is 2 p model builds instead of p simulations.

Used by ``nlsid fit --model --jacobian sensitivities`` (:meth:`nlsid.fit.simulation_cost.Cost.sensitivities`).
Measured against the fit's forward differences (``benchmarks/jacobian.py``, docs/commands.md): exact
to 1.5e-9 where the differences err by 1.4 % of a column, 2.2 times their cost per Jacobian on 2
cores, fewer steps from a distant start.
"""

from __future__ import annotations

import numpy as np

from nlsid.models import blocks, forces
from nlsid.simulate.jit import njit

COEFFICIENT_STEP = 1e-5  # relative step of the coefficients' central differences (about eps^(1/3))
SMOOTH_FORCES = (forces.CUBIC, forces.POLYNOMIAL)
SMOOTH_BLOCKS = (blocks.IDENTITY, blocks.POLYNOMIAL)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _polynomial(p: np.ndarray, x: float) -> tuple[float, float]:
    """(sum p_i x^i, its derivative in x), Horner."""
    value = 0.0
    slope = 0.0
    for i in range(p.shape[0] - 1, -1, -1):
        slope = slope * x + value
        value = value * x + p[i]
    return value, slope


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _block(kind: int, p: np.ndarray, x: float) -> tuple[float, float]:
    """A smooth block's output and its slope in x: the identity, or sum p_i x^i."""
    if kind == blocks.IDENTITY:
        return x, 1.0
    return _polynomial(p, x)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _block_moved(kind: int, dp: np.ndarray, x: float) -> float:
    """A smooth block's change with its parameters along dp: sum dp_i x^i (none for the identity)."""
    if kind == blocks.IDENTITY:
        return 0.0
    return _polynomial(dp, x)[0]


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _force(kind: int, p: np.ndarray, mid: float) -> tuple[float, float]:
    """A smooth force of the read-out's midpoint m over the sub-step (:func:`nlsid.simulate.kernels.force`)
    and its slope in m: cubic k3 m^3, or polynomial m^2 sum_{i<=8} p_i m^i."""
    if kind == forces.CUBIC:
        return p[0] * mid * mid * mid, 3.0 * p[0] * mid * mid
    value, slope = _polynomial(p, mid)
    m2 = mid * mid
    return value * m2, slope * m2 + 2.0 * value * mid


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _force_moved(kind: int, dp: np.ndarray, mid: float) -> float:
    """A smooth force's change with its parameters along dp."""
    if kind == forces.CUBIC:
        return dp[0] * mid * mid * mid
    return _polynomial(dp, mid)[0] * mid * mid


@njit(cache=True, fastmath={"contract"}, nogil=True)
def tangent_loop(phi, gamma, C, x0, kinds, params, row_pow, row_gamma, coupling, col_pow, h, delay, closed, Ac, Bc,
                 Cc, Dc, r, ff, u_in, process, y_noise, in_kind, in_params, out_kind, out_params, p_bias, lag, c_x,
                 c_p, c_f, d_phi, d_gamma, d_C, d_x0, d_params, d_row_pow, d_row_gamma, d_coupling, d_col_pow, d_Ac,
                 d_Bc, d_Cc, d_Dc, d_r, d_ff, d_process, d_y_noise, d_in_params, d_out_params, d_p_bias, d_c_x,
                 d_c_p, d_c_f, moves, u_out, y_out, du_out, dy_out):
    """The kernel's loop (:func:`nlsid.simulate.kernels._make_loop`, the same arguments first) for
    smooth forces and blocks, with the tangent of every quantity along each of the P directions
    whose coefficient derivatives follow (``d_`` + the name, a leading axis of P); ``moves[a]``:
    whether direction a moves the plant's propagation and read-out coefficients (phi .. col_pow,
    C, c_x, c_p, c_f; where it does not, their derivative terms are skipped: a force's, a block's
    or an offset's parameter); fills u_out, y_out (N,) and du_out, dy_out (P, N)."""
    P = d_phi.shape[0]
    substeps = row_pow.shape[0] - 1
    n = phi.shape[0]
    nc = Ac.shape[0]
    n_el = kinds.shape[0]
    x = x0.copy()
    dx = d_x0.copy()
    xn = np.empty(n)
    dxn = np.empty((P, n))
    xc = np.zeros(nc)
    dxc = np.zeros((P, nc))
    xcn = np.empty(nc)
    dxcn = np.empty((P, nc))
    ends = np.zeros(n_el)
    dends = np.zeros((P, n_el))
    f = np.zeros((substeps, n_el))
    df = np.zeros((P, substeps, n_el))
    buf = np.zeros(max(delay, 1))
    dbuf = np.zeros((P, max(delay, 1)))
    y_m = 0.0
    dy_m = np.zeros(P)
    carried = 0.0
    dcarried = np.zeros(P)
    for i in range(n):
        carried += C[i] * x[i]
    for a in range(P):
        for i in range(n):
            dcarried[a] += d_C[a, i] * x[i] + C[i] * dx[a, i]
    du = np.zeros(P)
    dcommand = np.zeros(P)
    dpp = np.zeros(P)
    dy_now = np.zeros(P)
    for k in range(y_out.shape[0]):
        if closed:
            y_now = carried
            for a in range(P):
                dy_now[a] = dcarried[a]
            if not lag:
                y_now = 0.0
                for i in range(n):
                    y_now += C[i] * x[i]
                for a in range(P):
                    acc = 0.0
                    for i in range(n):
                        acc += d_C[a, i] * x[i] + C[i] * dx[a, i]
                    dy_now[a] = acc
            y_m, slope = _block(out_kind, out_params, y_now)
            for a in range(P):
                dy_m[a] = slope * dy_now[a] + _block_moved(out_kind, d_out_params[a], y_now)
            measured = y_m + y_noise[k]
            err = r[k] - measured
            u = Dc[0] * err + Dc[1] * measured + ff[k]
            for i in range(nc):
                u += Cc[i] * xc[i]
            for i in range(nc):
                acc = Bc[i, 0] * err + Bc[i, 1] * measured
                for j in range(nc):
                    acc += Ac[i, j] * xc[j]
                xcn[i] = acc
            for a in range(P):
                dmeasured = dy_m[a] + d_y_noise[a, k]
                derr = d_r[a, k] - dmeasured
                acc = (d_Dc[a, 0] * err + Dc[0] * derr + d_Dc[a, 1] * measured + Dc[1] * dmeasured
                       + d_ff[a, k])
                for i in range(nc):
                    acc += d_Cc[a, i] * xc[i] + Cc[i] * dxc[a, i]
                du[a] = acc
                for i in range(nc):
                    acc = (d_Bc[a, i, 0] * err + Bc[i, 0] * derr + d_Bc[a, i, 1] * measured
                           + Bc[i, 1] * dmeasured)
                    for j in range(nc):
                        acc += d_Ac[a, i, j] * xc[j] + Ac[i, j] * dxc[a, j]
                    dxcn[a, i] = acc
            xc, xcn = xcn, xc
            dxc, dxcn = dxcn, dxc
        else:
            u = u_in[k]
            for a in range(P):
                du[a] = 0.0
        u_out[k] = u
        for a in range(P):
            du_out[a, k] = du[a]
        if delay > 0:
            slot = k % delay
            command = buf[slot]
            buf[slot] = u
            for a in range(P):
                dcommand[a] = dbuf[a, slot]
                dbuf[a, slot] = du[a]
        else:
            command = u
            for a in range(P):
                dcommand[a] = du[a]
        p, slope = _block(in_kind, in_params, command + process[k])
        for a in range(P):
            dpp[a] = (slope * (dcommand[a] + d_process[a, k]) + _block_moved(in_kind, d_in_params[a], command + process[k])
                      + d_p_bias[a])
        pp = p + p_bias
        for j in range(substeps if n_el else 0):
            for e in range(n_el):
                s_free = row_gamma[j + 1, e] * pp
                for i in range(n):
                    s_free += row_pow[j + 1, e, i] * x[i]
                for i in range(j + 1):
                    for e2 in range(n_el if i < j else e):
                        s_free -= coupling[j - i, e, e2] * f[i, e2]
                if j:
                    s_now = ends[e]
                    for e2 in range(e, n_el):
                        s_now -= coupling[0, e, e2] * f[j - 1, e2]
                else:
                    s_now = 0.0
                    for i in range(n):
                        s_now += row_pow[0, e, i] * x[i]
                ends[e] = s_free
                mid = 0.5 * (s_now + s_free)
                f[j, e], slope = _force(kinds[e], params[e], mid)
                for a in range(P):
                    ds_free = row_gamma[j + 1, e] * dpp[a]
                    for i in range(n):
                        ds_free += row_pow[j + 1, e, i] * dx[a, i]
                    for i in range(j + 1):
                        for e2 in range(n_el if i < j else e):
                            ds_free -= coupling[j - i, e, e2] * df[a, i, e2]
                    if j:
                        ds_now = dends[a, e]
                        for e2 in range(e, n_el):
                            ds_now -= coupling[0, e, e2] * df[a, j - 1, e2]
                    else:
                        ds_now = 0.0
                        for i in range(n):
                            ds_now += row_pow[0, e, i] * dx[a, i]
                    if moves[a]:
                        ds_free += d_row_gamma[a, j + 1, e] * pp
                        for i in range(n):
                            ds_free += d_row_pow[a, j + 1, e, i] * x[i]
                        for i in range(j + 1):
                            for e2 in range(n_el if i < j else e):
                                ds_free -= d_coupling[a, j - i, e, e2] * f[i, e2]
                        if j:
                            for e2 in range(e, n_el):
                                ds_now -= d_coupling[a, 0, e, e2] * f[j - 1, e2]
                        else:
                            for i in range(n):
                                ds_now += d_row_pow[a, 0, e, i] * x[i]
                    dends[a, e] = ds_free
                    df[a, j, e] = slope * 0.5 * (ds_now + ds_free) + _force_moved(kinds[e], d_params[a, e], mid)
        if lag or not closed:
            y_now = c_p * pp
            for i in range(n):
                y_now += c_x[i] * x[i]
            for j in range(c_f.shape[0] if n_el else 0):
                for e in range(n_el):
                    y_now -= c_f[j, e] * f[j, e]
            for a in range(P):
                acc = c_p * dpp[a]
                for i in range(n):
                    acc += c_x[i] * dx[a, i]
                for j in range(c_f.shape[0] if n_el else 0):
                    for e in range(n_el):
                        acc -= c_f[j, e] * df[a, j, e]
                if moves[a]:
                    acc += d_c_p[a] * pp
                    for i in range(n):
                        acc += d_c_x[a, i] * x[i]
                    for j in range(c_f.shape[0] if n_el else 0):
                        for e in range(n_el):
                            acc -= d_c_f[a, j, e] * f[j, e]
                if lag:
                    acc, dcarried[a] = dcarried[a], acc
                dy_now[a] = acc
            if lag:
                y_now, carried = carried, y_now
            if not closed:
                y_m, slope = _block(out_kind, out_params, y_now)
                for a in range(P):
                    dy_m[a] = slope * dy_now[a] + _block_moved(out_kind, d_out_params[a], y_now)
        y_out[k] = y_m + y_noise[k]
        for a in range(P):
            dy_out[a, k] = dy_m[a] + d_y_noise[a, k]
        for i in range(n):
            acc = gamma[i] * pp
            for j in range(n):
                acc += phi[i, j] * x[j]
            for j in range(substeps if n_el else 0):
                for e in range(n_el):
                    acc -= col_pow[j, e, i] * f[j, e]
            xn[i] = acc
        for a in range(P):
            for i in range(n):
                acc = gamma[i] * dpp[a]
                for j in range(n):
                    acc += phi[i, j] * dx[a, j]
                for j in range(substeps if n_el else 0):
                    for e in range(n_el):
                        acc -= col_pow[j, e, i] * df[a, j, e]
                if moves[a]:
                    acc += d_gamma[a, i] * pp
                    for j in range(n):
                        acc += d_phi[a, i, j] * x[j]
                    for j in range(substeps if n_el else 0):
                        for e in range(n_el):
                            acc -= d_col_pow[a, j, e, i] * f[j, e]
                dxn[a, i] = acc
        x, xn = xn, x
        dx, dxn = dxn, dx
    return x


# the kernel's arguments (nlsid.simulate.engine._kernel_arguments) that depend on the parameters,
# in tangent_loop's order of their derivatives, and those that are the simulation's structure
DIFFERENTIATED = (0, 1, 2, 3, 5, 6, 7, 8, 9, 13, 14, 15, 16, 17, 18, 20, 21, 23, 25, 26, 28, 29, 30)
STRUCTURE = (4, 10, 11, 12, 22, 24, 27)  # force kinds, h, dead time, closed, block kinds, lag
_KINDS, _IN_KIND, _OUT_KIND = 4, 22, 24


def smooth(arguments: tuple) -> bool:
    """Whether the simulation with these kernel arguments is differentiable in its coefficients
    (module docstring): smooth forces and blocks only."""
    return (all(kind in SMOOTH_FORCES for kind in arguments[_KINDS])
            and arguments[_IN_KIND] in SMOOTH_BLOCKS and arguments[_OUT_KIND] in SMOOTH_BLOCKS)


def _padded(arguments: tuple) -> tuple:
    """The arguments with c_f given a row per sub-step (the rows beyond the read-out instant zero):
    an output timing moved by its step may start one more sub-step before the read-out."""
    c_f, substeps = arguments[30], arguments[6].shape[0] - 1
    if c_f.shape[0] == substeps or c_f.shape[1] == 0:
        return arguments
    full = np.zeros((substeps, c_f.shape[1]))
    full[:c_f.shape[0]] = c_f
    return (*arguments[:30], full)


def _same_structure(a: tuple, b: tuple) -> bool:
    for i in STRUCTURE:
        if not np.array_equal(a[i], b[i]):
            return False
    return all(np.shape(a[i]) == np.shape(b[i]) for i in DIFFERENTIATED)


def coefficient_steps(theta: np.ndarray) -> np.ndarray:
    """h_i of the coefficients' central differences (module docstring)."""
    return COEFFICIENT_STEP * np.where(theta != 0, np.abs(theta), 1.0)


SIGNALS = (17, 18, 20, 21)  # r, ff, process, y_noise: a run's own; the rest is the model's at its fs


def run_arguments(plant, loop, runs, substeps: int | None) -> list[tuple]:
    """The kernel's arguments (:func:`nlsid.simulate.engine._kernel_arguments`) of each run,
    noise-free, c_f with a row per sub-step (:func:`_padded`); the coefficients computed once per
    sample rate (the same objects in every run of it: :func:`derivatives` differentiates them
    once), the signals per run."""
    from nlsid.simulate.engine import _kernel_arguments, _signal, plant_arguments
    from nlsid.simulate.noise import Noise

    out, first = [], {}
    for run in runs:
        parts = plant_arguments(plant, loop, run, substeps, Noise.zero(run.n_samples))
        if run.fs not in first:
            first[run.fs] = _padded(_kernel_arguments(*parts))
            out.append(first[run.fs])
            continue
        shared = list(first[run.fs])
        shared[17:22] = (_signal(x) for x in parts[13:18])  # r, ff, u, process, y_noise
        out.append(tuple(shared))
    return out


def derivatives(arguments_at, theta: np.ndarray) -> list[tuple[tuple, list[np.ndarray]]] | None:
    """For each run, (the kernel's arguments at theta, the derivatives of DIFFERENTIATED by each
    parameter, each stacked on a leading axis of P), by central differences of ``arguments_at``
    (theta -> every run's kernel arguments, :func:`run_arguments`; it raises
    :class:`~nlsid.errors.InputError` where the model refuses theta). None where the simulation is
    not smooth, a parameter changes the structure, or theta +- h is refused: the caller
    differentiates by finite differences of the simulations then. The coefficients that runs of
    one sample rate share are differentiated once (keyed by their Phi^M, one object per rate)."""
    from nlsid.errors import InputError

    base = arguments_at(theta)
    if not all(smooth(arguments) for arguments in base):
        return None
    steps = coefficient_steps(theta)
    shifted = []  # per parameter: (every run's arguments at theta + h e_a, at theta - h e_a)
    for a, step in enumerate(steps):
        shift = np.zeros(theta.size)
        shift[a] = step
        try:
            shifted.append((arguments_at(theta + shift), arguments_at(theta - shift)))
        except InputError:
            return None
    if not all(_same_structure(arguments, up[r]) and _same_structure(arguments, down[r])
               for up, down in shifted for r, arguments in enumerate(base)):
        return None

    def stacked(r: int, i: int) -> np.ndarray:
        return np.stack([(np.asarray(up[r][i], dtype=float) - np.asarray(down[r][i], dtype=float)) / (2 * step)
                         for (up, down), step in zip(shifted, steps)])

    model_parts: dict[int, dict[int, np.ndarray]] = {}
    out = []
    for r, arguments in enumerate(base):
        key = id(arguments[0])
        if key not in model_parts:
            model_parts[key] = {i: stacked(r, i) for i in DIFFERENTIATED if i not in SIGNALS}
        own = {**model_parts[key], **{i: stacked(r, i) for i in SIGNALS}}
        out.append((arguments, [own[i] for i in DIFFERENTIATED]))
    return out


PROPAGATION = (0, 1, 2, 6, 7, 8, 9, 28, 29, 30)  # phi .. col_pow, C, c_x, c_p, c_f (moves)


def simulate(arguments: tuple, stack: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(u, y, du, dy): the kernel's u and y on ``arguments`` and their derivatives (P, N) by each
    parameter whose coefficient derivatives ``stack`` holds (:func:`derivatives`)."""
    length = max(arguments[17].shape[0], arguments[19].shape[0])
    P = stack[0].shape[0]
    u, y = np.empty(length), np.empty(length)
    du, dy = np.empty((P, length)), np.empty((P, length))
    derivative = dict(zip(DIFFERENTIATED, stack))
    moves = np.array([any(np.any(derivative[i][a] != 0) for i in PROPAGATION) for a in range(P)])
    tangent_loop(*arguments, *[np.ascontiguousarray(s) for s in stack], moves, u, y, du, dy)
    return u, y, du, dy
