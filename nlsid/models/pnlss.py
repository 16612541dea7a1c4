"""The polynomial nonlinear state-space model (PNLSS; Paduart et al., Automatica 46, 2010), discrete
time, single input single output:

    x[t+1] = A x[t] + B u[t] + E zeta(v[t])
    y[t]   = C x[t] + D u[t] + F eta(v[t])

``zeta`` and ``eta`` are vectors of monomials of the variables v, of chosen total degrees (for
example 2 and 3; odd degrees only, such as 3 and 5, keep the model odd). Two forms:

* full (the default): v = (x_1, ..., x_n, u), or the states alone;
* nonlinear LFR (Schoukens and Tiels, Int. J. Control 90, 2017, the parsimonious option): v = z =
  C_z x + D_z u, a few (n_z) linear combinations of the states and the input, C_z (n_z x n) and
  D_z (n_z) coefficients of the model. Its monomial count depends on n_z, not on n.

Both are run by the same kernels with v = M x + N u: the full form's M stacks the identity (and a
zero row for u), N picks u; the LFR form's M, N are C_z, D_z. The linear part (A, B, C, D) is a state-space realisation of a linear model (the BLA's
fit); E (n x n_zeta) and F (n_eta) hold the coefficients of the nonlinear terms. The model can
represent, exactly, a Wiener-Hammerstein system with a polynomial between its filters, a Duffing
oscillator (its cubic spring is a monomial of the position) and a wide class of systems with
polynomial nonlinearities inside the loop (Paduart et al. 2010, Sec. 3).

The monomials are ordered by total degree, then in the order of
``itertools.combinations_with_replacement`` over the variables: for two states and the input,
degree 2 is x1^2, x1 x2, x1 u, x2^2, x2 u, u^2 (:func:`exponents`). The math of the simulation and
of the exact sensitivities is in ``docs/pnlss.md``; the kernels in
:mod:`nlsid.simulate.pnlss_kernels`.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.models.lti import StateSpace, delay_samples, zoh


def check_degrees(degrees, where: str) -> tuple[int, ...]:
    """Total degrees as a sorted tuple of distinct integers >= 2 (degree 1 is the linear part)."""
    try:
        values = [int(d) for d in degrees]
    except (TypeError, ValueError):
        raise InputError(where, f"expected a list of integer degrees >= 2, got {degrees!r}") from None
    if any(float(d) != v for d, v in zip(degrees, values)) or any(v < 2 for v in values):
        raise InputError(where, f"expected integer degrees >= 2 (degree 1 is the linear part A, B, C, D), got {list(degrees)}")
    if len(set(values)) != len(values):
        raise InputError(where, f"a degree is listed twice: {list(degrees)}")
    return tuple(sorted(values))


def exponents(n_states: int, degrees: tuple[int, ...], with_input: bool = True) -> np.ndarray:
    """The exponent table of the monomials (:func:`exponent_table`), shared and read-only."""
    return _exponents(int(n_states), tuple(int(d) for d in degrees), bool(with_input))


@functools.lru_cache(maxsize=64)
def _exponents(n_states: int, degrees: tuple[int, ...], with_input: bool) -> np.ndarray:
    table = exponent_table(n_states, degrees, with_input)
    table.flags.writeable = False
    return table


def exponent_table(n_states: int, degrees: tuple[int, ...], with_input: bool = True) -> np.ndarray:
    """The exponent table of the monomials: one row per monomial, one column per variable
    (x_1 .. x_n, then u if ``with_input``); row r is the monomial prod_v z_v^table[r, v].

    Ordered by total degree (in the order of ``degrees``), then as
    ``itertools.combinations_with_replacement`` picks the variables. For n_v variables there are
    binom(n_v + d - 1, d) monomials of degree d.
    """
    n_vars = n_states + (1 if with_input else 0)
    rows = []
    for d in degrees:
        for combo in itertools.combinations_with_replacement(range(n_vars), d):
            row = np.zeros(n_vars, dtype=np.int64)
            for v in combo:
                row[v] += 1
            rows.append(row)
    return np.array(rows, dtype=np.int64).reshape(len(rows), n_vars)


def monomial_names(n_states: int, degrees: tuple[int, ...], with_input: bool = True, symbol: str = "x") -> list[str]:
    """Readable names of the monomials of :func:`exponents` (``x1^2*u``), in its order; ``symbol``
    names the variables (``z`` for the LFR form's combinations, ``with_input`` False there)."""
    names = [f"{symbol}{i + 1}" for i in range(n_states)] + (["u"] if with_input else [])
    out = []
    for row in exponents(n_states, degrees, with_input):
        factors = [name if e == 1 else f"{name}^{e}" for name, e in zip(names, row) if e]
        out.append("*".join(factors))
    return out


@dataclass(frozen=True)
class Pnlss:
    """A discrete-time PNLSS model (module docstring) at the sample rate ``fs`` (Hz).

    Attributes
    ----------
    A, B, C, D : the linear part: A (n x n), B (n), C (n), D (a number).
    E : (n x n_zeta) coefficients of the state equation's monomials zeta.
    F : (n_eta) coefficients of the output equation's monomials eta.
    state_degrees, output_degrees : total degrees of zeta and eta (empty: no terms).
    with_input : whether the monomials contain the input u (else the states only); full form only.
    input_offset, output_offset : the model runs on u + input_offset and records y + output_offset.
    input_channels : (channel name, gain) pairs: measured channels added to the input
        (u + input_offset + sum gain * channel), as in the other models of the config language.
    zero_if_absent : the names of ``input_channels`` a run may lack (taken as zero there).
    Cz, Dz : None (the full form), or the LFR form's combinations z = Cz x + Dz u: Cz (n_z x n),
        Dz (n_z); the monomials are then those of z (n_z variables).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    E: np.ndarray
    F: np.ndarray
    fs: float
    state_degrees: tuple[int, ...] = (2, 3)
    output_degrees: tuple[int, ...] = (2, 3)
    with_input: bool = True
    input_offset: float = 0.0
    output_offset: float = 0.0
    input_channels: tuple[tuple[str, float], ...] = ()
    zero_if_absent: tuple[str, ...] = ()
    Cz: np.ndarray | None = None
    Dz: np.ndarray | None = None
    state_exponents: np.ndarray = field(init=False, repr=False, compare=False)
    output_exponents: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        n = self.A.shape[0]
        if (self.Cz is None) != (self.Dz is None):
            raise InputError("model.nonlinearity", "the LFR form needs both Cz and Dz")
        if self.Cz is not None:
            nv = self.Dz.shape[0] if self.Dz.ndim == 1 else -1
            if nv < 1 or self.Cz.shape != (nv, n):
                raise InputError("model.nonlinearity", f"expected Cz of n_z rows of {n} coefficients (one per state) and "
                                                       f"Dz of n_z numbers, n_z >= 1; got shapes {self.Cz.shape} and "
                                                       f"{self.Dz.shape}")
        object.__setattr__(self, "state_exponents", self._exponents(self.state_degrees))
        object.__setattr__(self, "output_exponents", self._exponents(self.output_degrees))
        if self.E.shape != (n, self.state_exponents.shape[0]):
            raise InputError("model.E", f"expected {n} rows of {self.state_exponents.shape[0]} coefficients "
                                        f"(one per monomial of degrees {list(self.state_degrees)}), got shape {self.E.shape}")
        if self.F.shape != (self.output_exponents.shape[0],):
            raise InputError("model.F", f"expected {self.output_exponents.shape[0]} coefficients (one per monomial "
                                        f"of degrees {list(self.output_degrees)}), got {self.F.size}")

    def _exponents(self, degrees: tuple[int, ...]) -> np.ndarray:
        if self.Cz is None:
            return exponents(self.A.shape[0], degrees, self.with_input)
        return exponents(self.Cz.shape[0], degrees, False)

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    @property
    def lfr(self) -> bool:
        """Whether the model is of the LFR form (its monomials those of z = Cz x + Dz u)."""
        return self.Cz is not None

    @property
    def lfr_inputs(self) -> int:
        """n_z, the number of combinations z of the LFR form (0 for the full form)."""
        return 0 if self.Cz is None else int(self.Cz.shape[0])

    @property
    def form_text(self) -> str:
        """How the monomials' variables are formed, as the pages and headers append it to the degrees:
        " of k combination(s) z = Cz x + Dz u (LFR form)", or "" for the full form."""
        return f" of {self.lfr_inputs} combination(s) z = Cz x + Dz u (LFR form)" if self.lfr else ""

    @property
    def n_parameters(self) -> int:
        """Coefficients of A, B, C, D, E and F (and Cz, Dz of the LFR form)."""
        n = self.order
        mixing = 0 if self.Cz is None else self.Cz.size + self.Dz.size
        return n * n + 2 * n + 1 + self.E.size + self.F.size + mixing

    def monomials(self, degrees: tuple[int, ...]) -> list[str]:
        """Names of the monomials of ``degrees`` in the model's variables (``x1^2*u``, or ``z1^3``)."""
        if self.Cz is None:
            return monomial_names(self.order, degrees, self.with_input)
        return monomial_names(self.lfr_inputs, degrees, False, "z")

    def mixing(self) -> tuple[np.ndarray, np.ndarray]:
        """(M, N) with the monomials' variables v = M x + N u: the LFR form's (Cz, Dz); the full
        form's [I; 0] and (0, ..., 0, 1) (or I and 0 with the states alone)."""
        if self.Cz is not None:
            return self.Cz, self.Dz
        n = self.order
        M = np.zeros((n + (1 if self.with_input else 0), n))
        M[:n, :n] = np.eye(n)
        N = np.zeros(M.shape[0])
        if self.with_input:
            N[n] = 1.0
        return M, N

    @property
    def linear(self) -> StateSpace:
        """The linear part (A, B, C, D) as a discrete state-space model (E and F left out)."""
        return StateSpace(self.A.copy(), self.B.copy(), self.C.copy(), float(self.D), discrete=True)

    def replace(self, **changes) -> "Pnlss":
        """A copy with the named fields changed (arrays copied as float64)."""
        values = {name: getattr(self, name) for name in ("A", "B", "C", "D", "E", "F", "fs", "state_degrees",
                                                         "output_degrees", "with_input", "input_offset",
                                                         "output_offset", "input_channels",
                                                         "zero_if_absent", "Cz", "Dz")}
        values.update(changes)
        return Pnlss(**values)

    def simulate(self, u: np.ndarray, x0: np.ndarray | None = None, bound: float = 1e150) -> np.ndarray:
        """The output y for the input samples ``u`` from the state ``x0`` (default rest).

        Raises InputError if the state leaves ``bound`` (in absolute value) or becomes non-finite:
        the model diverged on this input.
        """
        y, diverged = self.try_simulate(u, x0, bound)
        if diverged >= 0:
            raise InputError("model", f"the PNLSS simulation diverged at sample {diverged} (|x| > {bound:g} or not finite)")
        return y

    def try_simulate(self, u: np.ndarray, x0: np.ndarray | None = None, bound: float = 1e150) -> tuple[np.ndarray, int]:
        """(y, t): the output, and the first sample t whose next state left ``bound`` or was not
        finite (-1 if none; y after t is not computed)."""
        from nlsid.simulate.pnlss_kernels import simulate

        u = np.ascontiguousarray(u, dtype=np.float64) + self.input_offset
        start = np.zeros(self.order) if x0 is None else np.ascontiguousarray(x0, dtype=np.float64)
        y = np.zeros(u.shape[0])
        t = simulate(*self.kernel_matrices(), u, start, float(bound), y)
        y += self.output_offset
        return y, int(t)

    def steady_state(self, u_period: np.ndarray, lead_periods: int, periods: int = 1,
                     bound: float = 1e150) -> tuple[np.ndarray, int]:
        """(y, t) of :meth:`try_simulate` over ``periods`` periods of the periodic input
        ``u_period``, after ``lead_periods`` periods simulated ahead from rest and discarded."""
        u = np.tile(np.asarray(u_period, dtype=np.float64), lead_periods + periods)
        y, t = self.try_simulate(u, None, bound)
        return y[lead_periods * len(u_period):], t

    def kernel_matrices(self) -> tuple:
        """(A, B, C, D, E, F, state exponents, output exponents, M, N): the kernels' arguments,
        float64 and int64, C-ordered (M, N: :meth:`mixing`)."""
        f = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
        M, N = self.mixing()
        return (f(self.A), f(self.B), f(self.C), float(self.D), f(self.E), f(self.F),
                np.ascontiguousarray(self.state_exponents), np.ascontiguousarray(self.output_exponents), f(M), f(N))

    def spectral_radius(self) -> float:
        """max |eig(A)|: below 1 the linear part is stable."""
        return float(np.max(np.abs(np.linalg.eigvals(self.A)), initial=0.0))


def discretised(ss: StateSpace, fs: float, where: str = "model") -> StateSpace:
    """A discrete realisation at ``fs`` of a linear model: ZOH if continuous, and a dead time of d
    samples as d shift-register states on the input (u[t - d] enters the original state equation)."""
    if ss.discrete:
        A, B = np.asarray(ss.A, float), np.asarray(ss.B, float)
    else:
        Phi, Gamma = zoh(np.asarray(ss.A, float), np.asarray(ss.B, float), 1.0 / fs)
        A, B = np.array(Phi), np.array(Gamma)
    C, D = np.asarray(ss.C, float), float(ss.D)
    d = delay_samples(ss.delay, fs, f"{where}.delay")
    if d == 0:
        return StateSpace(A, B, C, D, discrete=True)
    n = A.shape[0]
    # states [x, q_1 .. q_d]: q_1[t+1] = u[t], q_k[t+1] = q_{k-1}[t]; x[t+1] = A x + B q_d; y = C x + D q_d
    big = np.zeros((n + d, n + d))
    big[:n, :n] = A
    big[:n, n + d - 1] = B
    for k in range(1, d):
        big[n + k, n + k - 1] = 1.0
    b = np.zeros(n + d)
    b[n] = 1.0
    c = np.concatenate([C, np.zeros(d)])
    c[n + d - 1] = D
    return StateSpace(big, b, c, 0.0, discrete=True)


def balanced(ss: StateSpace) -> tuple[StateSpace, str]:
    """A balanced realisation of a stable discrete model (Moore 1981; the square-root method of
    Laub et al. 1987): controllability and observability Gramians Wc = A Wc A' + B B',
    Wo = A' Wo A + C' C, made equal and diagonal (the Hankel singular values). Its states are of
    comparable size and its matrices well conditioned, which the polynomial terms of a PNLSS need.

    Returns the realisation and how it was obtained: an unstable model or one with a Gramian that
    is not positive definite (a non-minimal realisation) keeps its coordinates, scaled so that each
    state's controllability Gramian entry is 1 where it is positive.
    """
    from scipy.linalg import cholesky, solve_discrete_lyapunov, svd

    A, B, C = ss.A, ss.B, ss.C
    n = A.shape[0]
    if n == 0:
        return ss, "no states"
    if np.max(np.abs(np.linalg.eigvals(A))) >= 1.0:
        return ss, "unstable linear part: realisation kept as given"
    Wc = solve_discrete_lyapunov(A, np.outer(B, B))
    Wo = solve_discrete_lyapunov(A.T, np.outer(C, C))
    try:
        Lc = cholesky((Wc + Wc.T) / 2, lower=True)
        Lo = cholesky((Wo + Wo.T) / 2, lower=True)
        U, s, Vt = svd(Lo.T @ Lc)
        if s[-1] <= 1e-12 * s[0]:
            raise np.linalg.LinAlgError("nearly non-minimal")
    except (np.linalg.LinAlgError, ValueError):
        scale = np.sqrt(np.where(np.diag(Wc) > 0, np.diag(Wc), 1.0))
        T = np.diag(scale)
        Ti = np.diag(1.0 / scale)
        return (StateSpace(Ti @ A @ T, Ti @ B, C @ T, ss.D, discrete=True),
                "not minimal (a Gramian is singular): realisation kept, states scaled")
    root = 1.0 / np.sqrt(s)
    T = Lc @ Vt.T * root          # x_old = T x_new
    Ti = (root[:, None] * U.T) @ Lo.T
    return StateSpace(Ti @ A @ T, Ti @ B, C @ T, float(ss.D), discrete=True), "balanced realisation"


def lfr_start_rows(C: np.ndarray, D: float, inputs: int, where: str = "nonlinearity.inputs") -> tuple[np.ndarray, np.ndarray]:
    """(Cz, Dz): the LFR form's start combinations for a linear part with output row (C, D):
    z_1 = C x + D u, the linear output (a Wiener-like start: the nonlinearity acts on what the
    linear model predicts); z_2 = u (Hammerstein-like); z_k = x_(k-2) for k >= 3 (states of a
    balanced realisation are of comparable size). At most n + 1 rows (n states and the input)."""
    n = C.shape[0]
    if not 1 <= inputs <= n + 1:
        raise InputError(where, f"expected 1 to {n + 1} combinations z (the {n} states and the input), got {inputs}")
    Cz, Dz = np.zeros((inputs, n)), np.zeros(inputs)
    Cz[0], Dz[0] = C, D
    if inputs > 1:
        Dz[1] = 1.0
    for k in range(2, inputs):
        Cz[k, k - 2] = 1.0
    return Cz, Dz


def from_linear(ss: StateSpace, fs: float, state_degrees=(2, 3), output_degrees=(2, 3), with_input: bool = True,
                input_offset: float = 0.0, output_offset: float = 0.0, lfr_inputs: int = 0,
                lfr_where: str = "lfr_inputs") -> tuple[Pnlss, str]:
    """A PNLSS model at ``fs`` whose linear part is ``ss`` (ZOH-discretised if continuous, a dead
    time as shift-register states, then balanced: :func:`balanced`) and whose nonlinear
    coefficients E, F are zero; and how the realisation was obtained. ``lfr_inputs`` > 0: the LFR
    form with that many combinations z, started by :func:`lfr_start_rows` (more than n + 1 refused,
    an InputError naming ``lfr_where``)."""
    sd = check_degrees(state_degrees, "state_degrees")
    od = check_degrees(output_degrees, "output_degrees")
    realisation, how = balanced(discretised(ss, fs))
    n = realisation.order
    C = np.array(realisation.C, float)
    Cz, Dz = lfr_start_rows(C, float(realisation.D), int(lfr_inputs), lfr_where) if lfr_inputs else (None, None)
    variables, inputs = (n, with_input) if Cz is None else (Cz.shape[0], False)
    nz = exponents(variables, sd, inputs).shape[0]
    nh = exponents(variables, od, inputs).shape[0]
    model = Pnlss(np.array(realisation.A, float), np.array(realisation.B, float), C,
                  float(realisation.D), np.zeros((n, nz)), np.zeros(nh), float(fs), sd, od, bool(with_input),
                  float(input_offset), float(output_offset), Cz=Cz, Dz=Dz)
    return model, how


def _lfr_of(config, n: int, C: np.ndarray, D: float, where: str) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(Cz, Dz) of a config's ``nonlinearity`` section (None, None: the full form)."""
    spec = config.nonlinearity
    if spec is None or spec.form == "full":
        return None, None
    key = f"{where}.nonlinearity"
    if spec.Cz is None:
        return lfr_start_rows(C, D, spec.inputs, f"{key}.inputs")
    rows = len(spec.Cz)
    if spec.inputs is not None and spec.inputs != rows:
        raise InputError(f"{key}.Cz", f"inputs is {spec.inputs} but Cz has {rows} rows; give one row per combination z")
    if any(len(row) != n for row in spec.Cz):
        raise InputError(f"{key}.Cz", f"expected rows of {n} coefficients (one per state), got lengths "
                                      f"{[len(r) for r in spec.Cz]}")
    Dz = np.zeros(rows) if spec.Dz is None else np.array(spec.Dz, dtype=float)
    if Dz.shape != (rows,):
        raise InputError(f"{key}.Dz", f"expected {rows} numbers (one per row of Cz), got {Dz.size}")
    return np.array(spec.Cz, dtype=float).reshape(rows, n), Dz


def build(config, where: str = "model") -> Pnlss:
    """The :class:`Pnlss` of a validated :class:`nlsid.io.model_config.PnlssConfig`, its matrix
    shapes checked against the number of states and of monomials (an InputError names the key)."""
    from nlsid.io.model_config import absent_as_zero, channel_gain
    from nlsid.models.lti import from_matrices

    ss = from_matrices(config.A, config.B, config.C, config.D, True, 0.0, where)
    n = ss.order
    sd = check_degrees(config.state_degrees, f"{where}.state_degrees")
    od = check_degrees(config.output_degrees, f"{where}.output_degrees")
    Cz, Dz = _lfr_of(config, n, np.array(ss.C, float), float(ss.D), where)
    variables, inputs, symbol = (n, config.with_input, "x") if Cz is None else (Cz.shape[0], False, "z")
    nz = exponents(variables, sd, inputs).shape[0]
    nh = exponents(variables, od, inputs).shape[0]
    if config.E is None:
        E = np.zeros((n, nz))
    else:
        if len(config.E) != n or any(len(row) != nz for row in config.E):
            raise InputError(f"{where}.E", f"expected {n} rows (one per state) of {nz} coefficients (one per monomial "
                                           f"of degrees {list(sd)}: {', '.join(monomial_names(variables, sd, inputs, symbol))}), "
                                           f"got {len(config.E)} rows of lengths {[len(r) for r in config.E]}")
        E = np.array(config.E, dtype=float).reshape(n, nz)
    if config.F is None:
        F = np.zeros(nh)
    else:
        if len(config.F) != nh:
            raise InputError(f"{where}.F", f"expected {nh} coefficients (one per monomial of degrees {list(od)}: "
                                           f"{', '.join(monomial_names(variables, od, inputs, symbol))}), got {len(config.F)}")
        F = np.array(config.F, dtype=float)
    return Pnlss(np.array(ss.A, float), np.array(ss.B, float), np.array(ss.C, float), float(ss.D), E, F,
                 float(config.fs), sd, od, bool(config.with_input), float(config.input_offset),
                 float(config.output_offset), tuple((str(k), channel_gain(v)) for k, v in config.input_channels.items()),
                 tuple(str(k) for k, v in config.input_channels.items() if absent_as_zero(v)), Cz, Dz)


def to_config(model: Pnlss) -> dict:
    """The ``model:`` section of a config (``docs/configs.md``) that :func:`build` makes ``model`` of."""
    out = {"type": "pnlss", "fs": float(model.fs), "A": model.A.tolist(), "B": model.B.tolist(),
           "C": model.C.tolist(), "D": float(model.D), "state_degrees": list(model.state_degrees),
           "output_degrees": list(model.output_degrees), "with_input": bool(model.with_input),
           "E": model.E.tolist(), "F": model.F.tolist()}
    if model.lfr:
        del out["with_input"]  # the LFR form's combinations hold the input (Dz)
        out["nonlinearity"] = {"form": "lfr", "inputs": model.lfr_inputs, "Cz": model.Cz.tolist(),
                               "Dz": model.Dz.tolist()}
    if model.input_offset:
        out["input_offset"] = float(model.input_offset)
    if model.output_offset:
        out["output_offset"] = float(model.output_offset)
    if model.input_channels:
        out["input_channels"] = {name: {"gain": float(gain), "absent": "zero"} if name in model.zero_if_absent
                                 else float(gain) for name, gain in model.input_channels}
    return out
