"""Fitting the black-box term of a hybrid model (:mod:`nlsid.models.hybrid`) with its physical part
held (derivation in ``docs/pnlss.md``, "The hybrid model").

The term's target is what the physical part leaves of the measured output, the residual
r = y - y_p on the estimation runs (:func:`residual_run`). It starts from a PNLSS model already
fitted to the same data as a whole (the diagnosis' yardstick), whose state equation
(A, B, E; Cz, Dz of the LFR form) is kept: its state trajectory x[t] on the recorded u does not
depend on the output equation, in which

    r[t] ~ C x[t] + D u[t] + F eta(x[t], u[t]) + c

is linear in (C, D, F, c), so the output equation that fits r best along that trajectory is the
solution of a linear least-squares problem (:func:`output_equation`). From there every coefficient
is refined by :func:`nlsid.fit.pnlss.fit_pnlss` on r (the physical parameters stay as they are:
the readable part is not moved by the black box).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.models.pnlss import Pnlss


def residual_run(run: Run, physical: np.ndarray) -> Run:
    """``run`` with its measured y replaced by y - ``physical`` (the physical part's output on it,
    as long as y): the signal the black-box term is fitted to."""
    if run.y is None:
        raise InputError(f"run {run.run_id}", "has no measured output y")
    physical = np.asarray(physical, dtype=float)
    if physical.shape != run.y.shape:
        raise InputError(f"run {run.run_id}", f"the physical part's output has {physical.size} samples, the run "
                                              f"{run.y.size}")
    return dataclasses.replace(run, y=np.asarray(run.y, dtype=float) - physical)


def minus_linear(model: Pnlss, linear) -> Pnlss:
    """A PNLSS model whose output is ``model``'s minus that of the discrete linear model ``linear``
    (a :class:`nlsid.models.lti.StateSpace` at ``model.fs``): the states of both side by side,
    x = (x_1, x_2), A = diag(A_1, A_2), B = (B_1, B_2), C = (C_1, -C_2), D = D_1 - D_2, in the LFR
    form with the monomials of ``model``'s own variables: its combinations z = Cz x_1 + Dz u with
    zero weights on x_2, or, for a full-form ``model``, z = (x_1, u) (z = x_1 without the input),
    whose monomials are the full form's in the same order, so E (zero rows for x_2) and F carry
    over unchanged. Its simulation is ``model``'s minus ``linear``'s exactly (the blocks do not
    interact until a fit gives x_2 weights in z). The polynomial stays one in n_1 + 1 variables
    where a full form in all n_1 + n_2 states and u would multiply the coefficients (and the
    overfitting: 500 against 240 for 3 + 2 states of degrees 2 and 3)."""
    n1, n2 = model.order, linear.order
    n = n1 + n2
    A = np.zeros((n, n))
    A[:n1, :n1], A[n1:, n1:] = model.A, np.asarray(linear.A, dtype=float)
    B = np.concatenate([model.B, np.asarray(linear.B, dtype=float)])
    C = np.concatenate([model.C, -np.asarray(linear.C, dtype=float)])
    D = float(model.D) - float(linear.D)
    M, N = model.mixing()  # the full form's variables (x_1, u) as combinations: [I; 0] and (0, .., 1)
    Cz = np.hstack([np.asarray(M, dtype=float), np.zeros((M.shape[0], n2))])
    E = np.vstack([model.E, np.zeros((n2, model.E.shape[1]))])
    return model.replace(A=A, B=B, C=C, D=D, E=E, Cz=Cz, Dz=np.asarray(N, dtype=float).copy(), with_input=False)


def output_monomials(model: Pnlss, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """eta(v[t]) for every sample (rows) and monomial of the output equation (columns, in the
    order of ``model.output_exponents``), v = M x + N u the monomials' variables
    (:meth:`Pnlss.mixing`); ``u`` the input as the kernels drive the model (its offset added)."""
    M, N = model.mixing()
    v = x @ np.asarray(M, dtype=float).T + np.outer(u, N)
    out = np.ones((x.shape[0], model.output_exponents.shape[0]))
    for k, row in enumerate(model.output_exponents):
        for j in np.flatnonzero(row):
            out[:, k] *= v[:, j] ** int(row[j])
    return out


def _trajectory(model: Pnlss, record) -> tuple[np.ndarray, np.ndarray, int]:
    """(x, u, first): the states and driven input over ``record`` simulated from rest (a periodic
    record in steady state: its lead-in dropped), and the first sample of them the least squares
    use (an arbitrary record's start, where the trajectory from rest has not forgotten the unknown
    initial state, is left out: :func:`nlsid.simulate.pnlss_runs.transient_samples`, at most half
    the record)."""
    from nlsid.simulate.pnlss_kernels import states
    from nlsid.simulate.pnlss_runs import driven_input, transient_samples

    u, lead = driven_input(model, record)
    x = np.zeros((u.size, model.order))
    states(*model.kernel_matrices(), u, np.zeros(model.order), x)
    first = transient_samples(model, record.y.size // 2) if record.arbitrary else 0
    return x[lead:], u[lead:], first


def output_equation(model: Pnlss, runs: Sequence[Run], where: str = "estimation") -> tuple[Pnlss, float]:
    """``model`` with its output equation (C, D, F and the output offset c) fitted to the runs'
    measured y by linear least squares along its state trajectory (module docstring); A, B, E (and
    Cz, Dz) kept. A periodic run counts by its mean steady period, weighted by its periods (the
    cost of every period: :mod:`nlsid.simulate.pnlss_runs`). Returns the model and the rms of its
    error over the samples fitted.

    The columns [x, u, eta, 1] are scaled to unit norm before the solve (its conditioning is then
    that of the signals' correlations, not of their sizes). Raises InputError if the state
    trajectory is not finite (the state equation diverges on these inputs)."""
    from nlsid.simulate.pnlss_runs import records

    rows, targets = [], []
    for record in records(runs, where):
        x, u, first = _trajectory(model, record)
        if not np.all(np.isfinite(x)):
            raise InputError(f"{where}: run {record.run_id}", "the black box's state equation diverges on its input")
        weight = math.sqrt(record.weight)
        rows.append(weight * np.hstack([x, u[:, None], output_monomials(model, x, u), np.ones((u.size, 1))])[first:])
        targets.append(weight * record.y[first:])
    Phi, r = np.vstack(rows), np.concatenate(targets)
    scale = np.linalg.norm(Phi, axis=0)
    scale[~(scale > 0)] = 1.0
    theta = np.linalg.lstsq(Phi / scale, r, rcond=None)[0] / scale
    n = model.order
    fitted = model.replace(C=theta[:n].copy(), D=float(theta[n]), F=theta[n + 1:-1].copy(),
                           output_offset=float(theta[-1]))
    error = Phi @ theta - r
    return fitted, float(math.sqrt(error @ error / max(r.size, 1)))


def fit_black_box(start: Pnlss, estimation: Sequence[Run], validation: Sequence[Run] = (), max_iterations: int = 100,
                  patience: int = 15):
    """The black-box term fitted to the residual runs ``estimation`` (:func:`residual_run`; early
    stopping on ``validation``, residual runs too): its output equation from ``start`` by
    :func:`output_equation`, then every coefficient by :func:`nlsid.fit.pnlss.fit_pnlss` (no
    separate linear stage: the start is a whole model). Returns the
    :class:`nlsid.fit.pnlss.PnlssFit`, its first note the start's least-squares error."""
    from nlsid.fit.pnlss import fit_pnlss

    begun, rms = output_equation(start, estimation)
    fit = fit_pnlss(begun, estimation, validation, max_iterations=max_iterations, linear_iterations=0,
                    patience=patience)
    fit.notes.insert(0, f"started from the state equation (A, B, E) of a PNLSS model fitted to the whole output, "
                        f"its output equation (C, D, F, offset) fitted to the residual by linear least squares "
                        f"(rms {rms:.6g} on the estimation runs)")
    return fit


def difference(first: Pnlss, second: Pnlss) -> Pnlss:
    """A PNLSS model whose output is ``first``'s minus ``second``'s (both at one rate): the states
    side by side, x = (x_1, x_2), A = diag(A_1, A_2), B = (B_1, B_2), C = (C_1, -C_2),
    D = D_1 - D_2, offsets subtracted; in the LFR form over the two models' own variables stacked,
    z = (v_1, v_2), v_k = M_k x_k + N_k u (:meth:`Pnlss.mixing`: a full form's (x_k, u)), so that
    each model's monomial coefficients go to the same monomial of z (the other block's powers zero)
    and the mixed monomials start at zero. Both need the same degrees. Its simulation is the
    difference exactly (the blocks do not interact until a fit couples them)."""
    from nlsid.models.pnlss import exponents

    if first.state_degrees != second.state_degrees or first.output_degrees != second.output_degrees:
        raise InputError("black_box", f"the models' degrees differ ({list(first.state_degrees)}/"
                                      f"{list(first.output_degrees)} and {list(second.state_degrees)}/"
                                      f"{list(second.output_degrees)})")
    n1, n2 = first.order, second.order
    n = n1 + n2
    A = np.zeros((n, n))
    A[:n1, :n1], A[n1:, n1:] = first.A, second.A
    (M1, N1), (M2, N2) = first.mixing(), second.mixing()
    k1, k2 = M1.shape[0], M2.shape[0]
    Cz = np.zeros((k1 + k2, n))
    Cz[:k1, :n1], Cz[k1:, n1:] = M1, M2
    Dz = np.concatenate([N1, N2]).astype(float)

    def placed(table_1: np.ndarray, table_2: np.ndarray, degrees) -> tuple[np.ndarray, np.ndarray, int]:
        wide = exponents(k1 + k2, degrees, False)
        rows = {tuple(r): j for j, r in enumerate(wide)}
        one = np.array([rows[tuple(list(r) + [0] * k2)] for r in table_1], dtype=int)
        two = np.array([rows[tuple([0] * k1 + list(r))] for r in table_2], dtype=int)
        return one, two, wide.shape[0]

    e1, e2, nz = placed(first.state_exponents, second.state_exponents, first.state_degrees)
    f1, f2, nh = placed(first.output_exponents, second.output_exponents, first.output_degrees)
    E = np.zeros((n, nz))
    E[:n1, e1], E[n1:, e2] = first.E, second.E
    F = np.zeros(nh)
    F[f1] += first.F
    F[f2] -= second.F
    return first.replace(A=A, B=np.concatenate([first.B, second.B]), C=np.concatenate([first.C, -second.C]),
                         D=float(first.D) - float(second.D), E=E, F=F, Cz=Cz, Dz=Dz, with_input=False,
                         output_offset=first.output_offset - second.output_offset)
