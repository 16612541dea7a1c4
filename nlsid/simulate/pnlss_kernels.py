"""numba kernels of the PNLSS model (:mod:`nlsid.models.pnlss`): its simulation and the exact
sensitivities of its output to all coefficients and to the initial state (forward sensitivity
recursion; derivation in ``docs/pnlss.md``).

The monomials of z = (x_1 .. x_n, u) come from a table of exponents (one row per monomial). Per
sample the powers z_v^k, k = 0 .. max degree, are formed once; a monomial is a product of n_v
table look-ups and its partial derivative d m / d z_v = e_v z_v^(e_v - 1) prod_{w != v} z_w^e_w
is formed the same way (no division, so z_v = 0 is exact).

Sensitivity layout. The state sensitivities S = dx[t] / d theta_s form an (n x P_s) array with
columns [x0 (n) | A (n^2, row-major) | B (n) | E (n n_zeta, row-major)]; the Jacobian rows
J[t] = dy[t] / d theta have columns [x0 | A | B | E | C (n) | D (1) | F (n_eta)]. With
``full`` False only the x0 columns are formed (an initial-state fit). Recursion:

    S[t+1] = (A + E dzeta/dx) S[t] + [explicit terms: x_j, u, zeta_j in row i of A_ij, B_i, E_ij]
    J[t]   = (C + F deta/dx) S[t]  (then x, u, eta in the columns of C, D, F)

The state product costs n^2 P_s multiply-adds per sample, written with the parameter index
innermost (contiguous, vectorised).
"""

from __future__ import annotations

import numpy as np

from nlsid.simulate.jit import njit  # numba, its cache outside the package (not `from numba`)


@njit(cache=True, nogil=True, inline="always")
def _powers(x, u, n_pow, pw):
    """pw[v, k] = z_v^k for z = (x, u), k = 0 .. n_pow - 1."""
    n = x.shape[0]
    for v in range(n + 1):
        z = x[v] if v < n else u
        pw[v, 0] = 1.0
        for k in range(1, n_pow):
            pw[v, k] = pw[v, k - 1] * z


@njit(cache=True, nogil=True, inline="always")
def _monomials(ex, pw, out):
    for j in range(ex.shape[0]):
        m = 1.0
        for v in range(ex.shape[1]):
            m *= pw[v, ex[j, v]]
        out[j] = m


@njit(cache=True, nogil=True, inline="always")
def _derivatives(ex, pw, n, out):
    """out[j, k] = d m_j / d x_k for the states k < n (the input's derivative is not needed)."""
    nv = ex.shape[1]
    for j in range(ex.shape[0]):
        for k in range(n):
            e = ex[j, k]
            if e == 0:
                out[j, k] = 0.0
                continue
            d = e * pw[k, e - 1]
            for w in range(nv):
                if w != k:
                    d *= pw[w, ex[j, w]]
            out[j, k] = d


@njit(cache=True, nogil=True)
def _max_power(ez, eh) -> int:
    m = 1
    for j in range(ez.shape[0]):
        for v in range(ez.shape[1]):
            m = max(m, ez[j, v])
    for j in range(eh.shape[0]):
        for v in range(eh.shape[1]):
            m = max(m, eh[j, v])
    return m + 1


@njit(cache=True, nogil=True)
def simulate(A, B, C, D, E, F, ez, eh, u, x0, bound, y):
    """y[t] for t = 0 .. N-1 from the state x0. Returns -1, or the first t whose next state has an
    entry beyond ``bound`` in absolute value or not finite (y is then filled up to t)."""
    n = A.shape[0]
    nz, nh = ez.shape[0], eh.shape[0]
    n_pow = _max_power(ez, eh)
    pw = np.empty((n + 1, n_pow))
    zeta = np.empty(nz)
    eta = np.empty(nh)
    x = x0.copy()
    xn = np.empty(n)
    for t in range(u.shape[0]):
        ut = u[t]
        _powers(x, ut, n_pow, pw)
        _monomials(eh, pw, eta)
        acc = D * ut
        for k in range(n):
            acc += C[k] * x[k]
        for j in range(nh):
            acc += F[j] * eta[j]
        y[t] = acc
        _monomials(ez, pw, zeta)
        bad = False
        for i in range(n):
            acc = B[i] * ut
            for k in range(n):
                acc += A[i, k] * x[k]
            for j in range(nz):
                acc += E[i, j] * zeta[j]
            xn[i] = acc
            if not abs(acc) <= bound:  # NaN fails the comparison
                bad = True
        if bad:
            return t
        for i in range(n):
            x[i] = xn[i]
    return -1


@njit(cache=True, nogil=True, fastmath={"contract"})
def sensitivities(A, B, C, D, E, F, ez, eh, u, x, S, full, bound, y, J):
    """Simulate over ``u`` from the state ``x`` with sensitivities ``S`` (module docstring), both
    updated in place to their values after the last sample, so a long record runs in chunks.

    y[t] gets the output and J[t] its derivatives (columns as in the module docstring; n columns
    with ``full`` False). Returns -1, or the first t whose next state left ``bound`` or was not
    finite (as :func:`simulate`).
    """
    n = A.shape[0]
    nz, nh = ez.shape[0], eh.shape[0]
    ps = S.shape[1]
    n_pow = _max_power(ez, eh)
    pw = np.empty((n + 1, n_pow))
    zeta = np.empty(nz)
    eta = np.empty(nh)
    dz = np.empty((nz, n))
    dh = np.empty((nh, n))
    jx = np.empty((n, n))
    ceff = np.empty(n)
    xn = np.empty(n)
    S2 = np.empty_like(S)
    c_col = ps            # first column of C in J
    a_col = n             # first columns of A, B, E in S and J
    b_col = n + n * n
    e_col = b_col + n
    for t in range(u.shape[0]):
        ut = u[t]
        _powers(x, ut, n_pow, pw)
        _monomials(eh, pw, eta)
        _derivatives(eh, pw, n, dh)
        # output and its sensitivities
        acc = D * ut
        for k in range(n):
            acc += C[k] * x[k]
            c = C[k]
            for j in range(nh):
                c += F[j] * dh[j, k]
            ceff[k] = c
        for j in range(nh):
            acc += F[j] * eta[j]
        y[t] = acc
        row = J[t]
        for p in range(ps):
            row[p] = ceff[0] * S[0, p]
        for k in range(1, n):
            c = ceff[k]
            for p in range(ps):
                row[p] += c * S[k, p]
        if full:
            for k in range(n):
                row[c_col + k] = x[k]
            row[c_col + n] = ut
            for j in range(nh):
                row[c_col + n + 1 + j] = eta[j]
        # state update and the state Jacobian A + E dzeta/dx
        _monomials(ez, pw, zeta)
        _derivatives(ez, pw, n, dz)
        bad = False
        for i in range(n):
            acc = B[i] * ut
            for k in range(n):
                acc += A[i, k] * x[k]
                a = A[i, k]
                for j in range(nz):
                    a += E[i, j] * dz[j, k]
                jx[i, k] = a
            for j in range(nz):
                acc += E[i, j] * zeta[j]
            xn[i] = acc
            if not abs(acc) <= bound:
                bad = True
        if bad:
            return t
        for i in range(n):
            target = S2[i]
            a = jx[i, 0]
            for p in range(ps):
                target[p] = a * S[0, p]
            for k in range(1, n):
                a = jx[i, k]
                for p in range(ps):
                    target[p] += a * S[k, p]
            if full:
                for k in range(n):
                    target[a_col + i * n + k] += x[k]
                target[b_col + i] += ut
                for j in range(nz):
                    target[e_col + i * nz + j] += zeta[j]
        for i in range(n):
            x[i] = xn[i]
        S, S2 = S2, S
    if u.shape[0] % 2 == 1:  # the last result is in the caller's S2 buffer: copy it into the caller's S
        S2[:, :] = S
    return -1


@njit(cache=True, nogil=True)
def states(A, B, C, D, E, F, ez, eh, u, x0, x_out):
    """x_out[t] = x[t], t = 0 .. N-1, from x0 (no bound: the caller checks the values)."""
    n = A.shape[0]
    nz = ez.shape[0]
    n_pow = _max_power(ez, eh)
    pw = np.empty((n + 1, n_pow))
    zeta = np.empty(nz)
    x = x0.copy()
    for t in range(u.shape[0]):
        for i in range(n):
            x_out[t, i] = x[i]
        ut = u[t]
        _powers(x, ut, n_pow, pw)
        _monomials(ez, pw, zeta)
        for i in range(n):
            acc = B[i] * ut
            for k in range(n):
                acc += A[i, k] * x_out[t, k]
            for j in range(nz):
                acc += E[i, j] * zeta[j]
            x[i] = acc
