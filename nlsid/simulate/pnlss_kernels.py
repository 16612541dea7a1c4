"""numba kernels of the PNLSS model (:mod:`nlsid.models.pnlss`): its simulation and the exact
sensitivities of its output to all coefficients and to the initial state (forward sensitivity
recursion; derivation in ``docs/pnlss.md``).

The monomials are of the variables v = M x + N u (n_v of them): the full form's M = [I; 0] and
N = (0, .., 0, 1), so that v = (x_1 .. x_n, u); the LFR form's M = C_z, N = D_z. They come from a
table of exponents (one row per monomial). Per sample the powers v_a^k, k = 0 .. max degree, are
formed once; a monomial is a product of n_v table look-ups and its partial derivative
d m / d v_a = e_a v_a^(e_a - 1) prod_{b != a} v_b^e_b is formed the same way (no division, so
v_a = 0 is exact).

Sensitivity layout. The state sensitivities S = dx[t] / d theta_s form an (n x P_s) array with
columns [x0 (n) | A (n^2, row-major) | B (n) | E (n n_zeta, row-major)], and with ``lfr`` also
[M (n_v n, row-major) | N (n_v)]; the Jacobian rows J[t] = dy[t] / d theta have these columns and
then [C (n) | D (1) | F (n_eta)]. With ``full`` False only the x0 columns are formed (an
initial-state fit). With G = dzeta/dv, H = deta/dv, W = E G (n x n_v) and h = F H (n_v):

    S[t+1] = (A + W M) S[t] + [x_j, u, zeta_j in row i of A_ij, B_i, E_ij;
                               W_ia x_k for M_ak, W_ia u for N_a]
    J[t]   = (C + h M) S[t]  (then h_a x_k, h_a u in the columns of M_ak, N_a; x, u, eta in those
                              of C, D, F)

The state product costs n^2 P_s multiply-adds per sample, written with the parameter index
innermost (contiguous, vectorised).
"""

from __future__ import annotations

import numpy as np

from nlsid.simulate.jit import njit  # numba, its cache outside the package (not `from numba`)


@njit(cache=True, nogil=True, inline="always")
def _variables(M, N, x, u, v):
    """v = M x + N u."""
    for a in range(M.shape[0]):
        acc = N[a] * u
        for k in range(M.shape[1]):
            acc += M[a, k] * x[k]
        v[a] = acc


@njit(cache=True, nogil=True, inline="always")
def _powers(v, n_pow, pw):
    """pw[a, k] = v_a^k, k = 0 .. n_pow - 1."""
    for a in range(v.shape[0]):
        z = v[a]
        pw[a, 0] = 1.0
        for k in range(1, n_pow):
            pw[a, k] = pw[a, k - 1] * z


@njit(cache=True, nogil=True, inline="always")
def _monomials(ex, pw, out):
    for j in range(ex.shape[0]):
        m = 1.0
        for v in range(ex.shape[1]):
            m *= pw[v, ex[j, v]]
        out[j] = m


@njit(cache=True, nogil=True, inline="always")
def _derivatives(ex, pw, out):
    """out[j, a] = d m_j / d v_a for every variable a."""
    nv = ex.shape[1]
    for j in range(ex.shape[0]):
        for a in range(nv):
            e = ex[j, a]
            if e == 0:
                out[j, a] = 0.0
                continue
            d = e * pw[a, e - 1]
            for w in range(nv):
                if w != a:
                    d *= pw[w, ex[j, w]]
            out[j, a] = d


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
def simulate(A, B, C, D, E, F, ez, eh, M, N, u, x0, bound, y):
    """y[t] for t = 0 .. N-1 from the state x0. Returns -1, or the first t whose next state has an
    entry beyond ``bound`` in absolute value or not finite (y is then filled up to t)."""
    n = A.shape[0]
    nz, nh = ez.shape[0], eh.shape[0]
    n_pow = _max_power(ez, eh)
    v = np.empty(M.shape[0])
    pw = np.empty((M.shape[0], n_pow))
    zeta = np.empty(nz)
    eta = np.empty(nh)
    x = x0.copy()
    xn = np.empty(n)
    for t in range(u.shape[0]):
        ut = u[t]
        _variables(M, N, x, ut, v)
        _powers(v, n_pow, pw)
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
def sensitivities(A, B, C, D, E, F, ez, eh, M, N, lfr, u, x, S, full, bound, y, J):
    """Simulate over ``u`` from the state ``x`` with sensitivities ``S`` (module docstring), both
    updated in place to their values after the last sample, so a long record runs in chunks.

    y[t] gets the output and J[t] its derivatives (columns as in the module docstring, those of M
    and N with ``lfr``; n columns with ``full`` False). Returns -1, or the first t whose next
    state left ``bound`` or was not finite (as :func:`simulate`).
    """
    n = A.shape[0]
    nv = M.shape[0]
    nz, nh = ez.shape[0], eh.shape[0]
    ps = S.shape[1]
    n_pow = _max_power(ez, eh)
    v = np.empty(nv)
    pw = np.empty((nv, n_pow))
    zeta = np.empty(nz)
    eta = np.empty(nh)
    gz = np.empty((nz, nv))
    gh = np.empty((nh, nv))
    w = np.empty((n, nv))
    h = np.empty(nv)
    jx = np.empty((n, n))
    ceff = np.empty(n)
    xn = np.empty(n)
    S2 = np.empty_like(S)
    c_col = ps            # first column of C in J
    a_col = n             # first columns of A, B, E, M, N in S and J
    b_col = n + n * n
    e_col = b_col + n
    m_col = e_col + n * nz
    n_col = m_col + nv * n
    mixing = full and lfr
    for t in range(u.shape[0]):
        ut = u[t]
        _variables(M, N, x, ut, v)
        _powers(v, n_pow, pw)
        _monomials(eh, pw, eta)
        _derivatives(eh, pw, gh)
        # output and its sensitivities: h = F deta/dv, C_eff = C + h M
        for a in range(nv):
            c = 0.0
            for j in range(nh):
                c += F[j] * gh[j, a]
            h[a] = c
        acc = D * ut
        for k in range(n):
            acc += C[k] * x[k]
            c = C[k]
            for a in range(nv):
                c += h[a] * M[a, k]
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
        if mixing:
            for a in range(nv):
                for k in range(n):
                    row[m_col + a * n + k] += h[a] * x[k]
                row[n_col + a] += h[a] * ut
        # state update and the state Jacobian A + W M, W = E dzeta/dv
        _monomials(ez, pw, zeta)
        _derivatives(ez, pw, gz)
        bad = False
        for i in range(n):
            for a in range(nv):
                c = 0.0
                for j in range(nz):
                    c += E[i, j] * gz[j, a]
                w[i, a] = c
            acc = B[i] * ut
            for k in range(n):
                acc += A[i, k] * x[k]
                c = A[i, k]
                for a in range(nv):
                    c += w[i, a] * M[a, k]
                jx[i, k] = c
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
            if mixing:
                for b in range(nv):
                    c = w[i, b]
                    for k in range(n):
                        target[m_col + b * n + k] += c * x[k]
                    target[n_col + b] += c * ut
        for i in range(n):
            x[i] = xn[i]
        S, S2 = S2, S
    if u.shape[0] % 2 == 1:  # the last result is in the caller's S2 buffer: copy it into the caller's S
        S2[:, :] = S
    return -1


@njit(cache=True, nogil=True)
def states(A, B, C, D, E, F, ez, eh, M, N, u, x0, x_out):
    """x_out[t] = x[t], t = 0 .. N-1, from x0 (no bound: the caller checks the values)."""
    n = A.shape[0]
    nz = ez.shape[0]
    n_pow = _max_power(ez, eh)
    v = np.empty(M.shape[0])
    pw = np.empty((M.shape[0], n_pow))
    zeta = np.empty(nz)
    x = x0.copy()
    for t in range(u.shape[0]):
        for i in range(n):
            x_out[t, i] = x[i]
        ut = u[t]
        _variables(M, N, x, ut, v)
        _powers(v, n_pow, pw)
        _monomials(ez, pw, zeta)
        for i in range(n):
            acc = B[i] * ut
            for k in range(n):
                acc += A[i, k] * x_out[t, k]
            for j in range(nz):
                acc += E[i, j] * zeta[j]
            x[i] = acc
