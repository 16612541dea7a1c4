"""A nonlinear joint in modal form: a cubic spring (or damper) on the modal coordinate of the mode
(or of each of the two modes) of a multi-mode LTI model whose frequency (damping) moves with the
excitation level.

Modal form. The user's LTI model (``state_space``, ``transfer_function`` or ``zpk`` of order >= 4;
a discrete one as its continuous equivalent, the exact inverse of its ZOH discretisation,
:func:`nlsid.models.continuous_equivalent.zoh_inverse`, its D unchanged: the ZOH equivalent of
(A, B, C, D) is (Phi, Gamma, C, D)) is diagonalised, A = V diag(lambda) V^-1, and each mode's
residue r = (C v)(w B) (v the right, w the left eigenvector) written as a real block with its own
modal coordinate q. A complex pair lambda, conj(lambda) becomes

    q'' + 2 zeta w q' + w^2 q = u,   y_i = beta q + alpha q',

w^2 = |lambda|^2, 2 zeta w = -2 Re(lambda), alpha = 2 Re(r), beta = -2 Re(r conj(lambda)) (from
r / (s - lambda) + conj(r) / (s - conj(lambda)) = (alpha s + beta) / (s^2 + 2 zeta w s + w^2)),
states (q, q'), input column (0, 1), output row (beta, alpha): a unit modal participation of the
input, which fixes the scale of q and so the units of k3 (input units per q^3). A real pole p
with residue r is the block q' = p q + u, y_i = r q. The blocks form a block-diagonal
``state_space`` (continuous) with the model's D, the moving mode first (:func:`modal_state_space`).

Acceleration output. A structure driven by a force whose accelerations are measured (a
ground-vibration test) has a transfer function of relative degree 0, G = D + sum of the blocks:
each mode's output is a combination of its coordinate's acceleration, velocity and
displacement, y_i = a2 q'' + a1 q' + a0 q, and with q'' = u - 2 zeta w q' - w^2 q - f (f a force
on that coordinate, below)

    y_i = a2 u + (a1 - 2 zeta w a2) q' + (a0 - w^2 a2) q - a2 f = a2 u + alpha q' + beta q - a2 f:

the force reaches the output through the dynamics (alpha, beta) and directly, by the
acceleration a2 f it takes from the coordinate. The linear response fixes alpha, beta and the
sum of the a2 (D), not each mode's a2. An accelerometer reads accelerations only: each mode's
response is c s^2 / (s^2 + 2 zeta w s + w^2) = c - c (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2),
so alpha = -2 zeta w c, beta = -w^2 c, D = sum c, and a mode's a2 = c = -beta / w^2 (a0 = 0: no
static response, which an acceleration has not; the velocity part a1 = alpha + 2 zeta w a2 a
fitted alpha may hold stays a state read-out). The force point of the moving mode therefore
gets the feedthrough d = a2 = -beta / w^2 (``points: {mode: {..., feedthrough: d}}``: y = C x +
D u - d f), refined with D and the rest. A model whose D is at most :data:`FEEDTHROUGH` of its
peak response |G - D| (a fit's rounding of a position or velocity output, which has no a2) has
its D set to 0 and no feedthrough (:func:`continuous_model`).

Hypothesis. The moving mode's block gets the force k3 q^3 against its motion:

    q'' + 2 zeta w q' + w^2 q + k3 q^3 = u,

a ``nonlinear_feedback`` around the modal state space whose force acts at the ``point`` of that
mode (``points: {mode: {force: [0, 1, 0, ...], position: [1, 0, 0, ...]}}``, docs/configs.md):
it reads q = (1, 0, ...) x and enters along -(0, 1, ...) (and reaches an acceleration output
directly, above: the feedthrough starts at -beta / w^2 of the block as started, its w^2 the
zero-amplitude one below). k3 > 0 is a joint that stiffens with the mode's amplitude, k3 < 0 one
that softens (a torsion mode that drops with the level).

Start value of k3 from the frequency shift. Equivalent linearisation of k3 q^3 replaces it by the
stiffness k_eq = E{q k3 q^3} / E{q^2}. For a sine of amplitude A this is the describing function
3/4 k3 A^2; for the random-phase multisines of the levels, whose modal coordinate is close to
Gaussian with variance sigma^2, E{q^4} = 3 sigma^4 and k_eq = 3 k3 sigma^2. The mode's squared
natural frequency at a level is then

    w_L^2 = (2 pi f_L)^2 = w0^2 + 3 k3 sigma_L^2,   so   df / f ~ 3/2 k3 sigma_L^2 / w0^2

(3/8 k3 A^2 / w0^2 for a sine of amplitude A). With f_L (Hz) the mode's frequency in the BLA of
level L (:func:`nlsid.analysis.modes.level_modes`, with its standard error se_L) and sigma_L^2 the
variance of the model's modal coordinate on that level's estimation runs (the steady-state
period of the mode's exact ZOH response to the input, :func:`modal_variance`), the weighted
least-squares line w_L^2 = a + b sigma_L^2 (weights 1 / (2 w_L se(w_L))) gives

    k3 = b / 3,   w0^2 = a,

its standard error that of b / 3 (times the Birge ratio where the line misses the points beyond
their errors). The moving mode's w^2 starts at w0^2, the frequency at zero amplitude (a model
fitted to a BLA holds the mode where the levels it saw put it). The fit engine then refines k3
with every mode's w^2, 2 zeta w, alpha and beta (a real pole's p and r): the user's modes are a
BLA's, biased by the joint, and a frozen linear part could not reach the floor.

A cubic damper on the same coordinate (``modal_damping``: c3 q'^3, ``cubic_damping`` at the point,
reading the modal velocity q' = (1, 0, ...) A x = x_2) is the dissipative counterpart: its
equivalent viscous damping is 3 c3 sigma_v^2 for a Gaussian modal velocity of variance
sigma_v^2 (3/4 c3 V^2 for a sine of amplitude V), so the line 2 zeta_L w_L = c0 + b sigma_v,L^2
over the levels (standard errors from those of zeta_L and f_L, first order) gives c3 = b / 3 and
the block's 2 zeta w starts at c0. It is chosen by the mode whose damping changes most
significantly, and is a member of the friction family with the dampings of
:mod:`~nlsid.diagnose.hypotheses.nonlinear_damping` (a damping that falls with the level is not a
cubic damper's: not fitted).

Which mode: the one whose frequency changes most significantly from the lowest level to the
highest (the largest |change| / standard error among the significant ones), matched to the model's
mode with the nearest natural frequency; the note names both. Not fitted where no mode moves
significantly, where fewer than two levels give the mode's frequency, or where the model has no
mode within :data:`MATCH` of it. The next mode that moves significantly gets a joint of its own
(:func:`second_joint`) where its line over the levels is significant too (the slope beyond
:data:`SECOND_SIGNIFICANCE` standard errors: a BLA of ten modes compared at the 5 % level shows a
spurious change now and then, which the line then rarely confirms): its block second, its point
``mode_2``, its parameters ``k3_2`` (``c3_2``) and, on an acceleration output, ``feedthrough_2``.
Two at most: the joints' modal coordinates are each started as if alone (the variance of one
mode's coordinate under the other's cubic is a second-order effect the refinement takes up).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis, explained_db, spring
from nlsid.diagnose.hypotheses.feedback import KEPT
from nlsid.diagnose.simulation import ModelRunner, steady_mean
from nlsid.errors import InputError
from nlsid.models.lti import StateSpace

MIN_ORDER = 4  # two modes at least: one mode is the mechanical templates' and the cubic feedback's case
MATCH = 0.1  # a model's mode within this relative distance of the moving mode's frequency is that mode
PAIR_TOLERANCE = 1e-9  # |Im lambda| / |lambda| below this: a real pole
FEEDTHROUGH = 0.01  # a discrete D above this share of the peak response is the output's own, not a fit's rounding
NEGLIGIBLE = 1e-6  # an output coefficient this small relative to the mode's other one is not refined
POINT = "mode"  # the name of the force point of the moving mode
FEEDTHROUGH_KEY = "feedthrough"  # the point's direct term to an acceleration output, and its parameter's name
SECOND_SIGNIFICANCE = 3.0  # a second moving mode's joint: its line's slope this many standard errors from 0


@dataclass(frozen=True)
class Mode:
    """One block of the modal form: a pair ``(alpha s + beta) / (s^2 + c1 s + w2)`` or a real pole
    ``beta / (s - pole)`` (``alpha`` 0); ``pole`` is lambda (Im >= 0)."""

    pole: complex
    alpha: float
    beta: float

    @property
    def pair(self) -> bool:
        return self.pole.imag > 0

    @property
    def frequency_hz(self) -> float:
        return abs(self.pole) / (2 * math.pi)


def lti_of(runner: ModelRunner) -> StateSpace:
    """The user's LTI model as a state space (dead time kept in ``delay``)."""
    from nlsid.models.from_config import lti

    return lti(runner.config.model, "model")


def _applies(runner: ModelRunner) -> str | None:
    if runner.kind not in ("state_space", "transfer_function", "zpk"):
        return "needs a state_space, transfer_function or zpk model (the modes of an LTI model)"
    order = lti_of(runner).order
    if order < MIN_ORDER:
        return f"needs a model of order >= {MIN_ORDER} (several modes); this one has {order}"
    return None


def continuous_model(ss: StateSpace, fs: float) -> tuple[StateSpace | str, list[str]]:
    """The continuous model the modal form is made of, and notes; or why there is none. Its direct
    feedthrough D is an acceleration output's where it exceeds :data:`FEEDTHROUGH` of the peak
    response (kept: module docstring), a fit's rounding below (set to 0), neither beside a pole on
    the frequency axis (none); a discrete model is replaced by its continuous equivalent (ZOH
    inverse, D unchanged)."""
    from nlsid.models.continuous_equivalent import zoh_inverse

    notes = []
    D = ss.D
    if D != 0:
        share = abs(D) / peak_gain(ss)
        if share > FEEDTHROUGH:
            notes.append(f"an acceleration output: D = {D:.3g} ({share:.1%} of the peak response) kept, the moving "
                         "mode's force reaching the output through its acceleration too")
        elif share == 0:  # a pole on the frequency axis: no acceleration (whose response is bounded)
            return ("the model has a direct feedthrough D and a pole on the frequency axis (an unbounded response: "
                    "no acceleration output), which the modal form here does not write"), notes
        else:
            D = 0.0
            notes.append(f"D = {ss.D:.3g} ({share:.2%} of the peak response) set to 0 (a fit's rounding: the output "
                         "is no acceleration)")
    if not ss.discrete:
        return StateSpace(ss.A, ss.B, ss.C, D, False, ss.delay, ss.fs), notes
    equivalent = zoh_inverse(StateSpace(ss.A, ss.B, ss.C, D, True, ss.delay, ss.fs), ss.fs or fs)
    if isinstance(equivalent, str):
        return f"the model has no continuous equivalent: {equivalent}", notes
    notes.append("extended in continuous time (the model's exact ZOH equivalent)")
    return equivalent, notes


def peak_gain(ss: StateSpace) -> float:
    """max |G - D| (the dynamics without the feedthrough) of ``ss`` at its poles' frequencies (the
    resonances' peaks) and on 512 frequencies: a discrete model's up to the Nyquist frequency, a
    continuous one's from 0 to ten times its largest pole's modulus; infinite where one of these
    is a pole (an integrator, an undamped mode)."""
    poles = ss.poles()
    if ss.discrete:
        points = np.exp(1j * np.concatenate([np.linspace(0.0, np.pi, 512), np.abs(np.angle(poles))]))
    else:
        top = 10 * float(np.max(np.abs(poles), initial=1.0))
        points = 1j * np.concatenate([np.linspace(0.0, top, 512), np.abs(poles.imag)])
    try:
        peak = float(np.max(np.abs(ss.frequency_response(points) - ss.D)))
    except np.linalg.LinAlgError:  # a point on a pole: singular sI - A
        return math.inf
    return peak if math.isfinite(peak) else math.inf


def modes_of(ss: StateSpace) -> list[Mode] | str:
    """The modes of a continuous ``ss`` (its dynamics: D is no mode's) by increasing natural
    frequency (module docstring), or why it has no modal form (a defective or nearly defective A)."""
    lam, V = np.linalg.eig(ss.A)
    if np.linalg.cond(V) > 1e10:
        return "its state matrix is (nearly) defective: no modal form"
    W = np.linalg.inv(V)
    residues = (ss.C @ V) * (W @ ss.B)
    out = []
    for p, r in zip(lam, residues):
        if abs(p.imag) <= PAIR_TOLERANCE * abs(p):
            out.append(Mode(complex(p.real, 0.0), 0.0, float(r.real)))
        elif p.imag > 0:
            out.append(Mode(complex(p), float(2 * r.real), float(-2 * (r * np.conj(p)).real)))
    return sorted(out, key=lambda m: m.frequency_hz)


def acceleration_share(linear: dict, j: int = 0) -> float:
    """The acceleration participation a2 = -beta / w^2 of the pair whose block starts at state
    ``j`` (the first: the moving mode's) of a modal ``state_space`` config of
    :func:`modal_state_space` (module docstring): its force point's feedthrough where the output is
    an acceleration."""
    return linear["C"][j] / linear["A"][j + 1][j]


def modal_state_space(modes: list[Mode], D: float = 0.0) -> dict:
    """The block-diagonal modal ``state_space`` config of ``modes`` in their order with the direct
    feedthrough ``D`` (module docstring): a pair's block [[0, 1], [-w^2, -2 zeta w]], input
    (0, 1), output (beta, alpha); a real pole's [[p]], 1, beta."""
    n = sum(2 if m.pair else 1 for m in modes)
    A, B, C = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    j = 0
    for m in modes:
        if m.pair:
            A[j, j + 1] = 1.0
            A[j + 1, j], A[j + 1, j + 1] = -abs(m.pole) ** 2, 2 * m.pole.real
            B[j + 1] = 1.0
            C[j], C[j + 1] = m.beta, m.alpha
            j += 2
        else:
            A[j, j], B[j], C[j] = m.pole.real, 1.0, m.beta
            j += 1
    return {"type": "state_space", "domain": "continuous", "A": A.tolist(), "B": B.tolist(), "C": C.tolist(),
            "D": float(D)}


def blocks(linear: dict) -> list[tuple[int, int]]:
    """(first state, size) of every block of a modal ``state_space`` config written by
    :func:`modal_state_space`: a pair where A[j][j + 1] = 1 and the input enters at j + 1 only."""
    A, B = linear["A"], linear["B"]
    out, j = [], 0
    while j < len(B):
        size = 2 if j + 1 < len(B) and A[j][j + 1] == 1.0 and B[j] == 0.0 else 1
        out.append((j, size))
        j += size
    return out


def modal_variance(run, pole: complex, derivative: int = 0) -> float:
    """Variance of the steady-state period of the modal coordinate q'' - 2 Re(p) q' + |p|^2 q = u
    (``derivative`` 0) or of its velocity q' (1) on ``run`` (u held over each sample: the exact ZOH
    response at the period's lines)."""
    from scipy.linalg import expm

    a = np.array([[0.0, 1.0], [-abs(pole) ** 2, 2 * pole.real]])
    T = 1.0 / run.fs
    M = np.zeros((3, 3))
    M[:2, :2], M[:2, 2] = a * T, (0.0, T)
    E = expm(M)
    Phi, Gamma = E[:2, :2], E[:2, 2]
    u = steady_mean(run, run.u)
    U = np.fft.rfft(u - u.mean())
    z = np.exp(2j * np.pi * np.arange(U.size) / u.size)
    H = np.array([np.linalg.solve(zk * np.eye(2) - Phi, Gamma)[derivative] for zk in z])
    q = np.fft.irfft(H * U, u.size)
    return float(np.var(q))


def moving_modes(ctx: Context, quantity: str = "frequency") -> list[dict] | str:
    """The rows of :func:`nlsid.analysis.modes.level_modes` of the measured levels whose
    ``quantity`` (``frequency`` or ``damping``) changes significantly, the most significant change
    (|change| / standard error) first, or why there is none."""
    from nlsid.analysis.levels import common_lines
    from nlsid.analysis.modes import level_modes

    measured = list(ctx.bla_levels[0]) if ctx.bla_levels else []
    if len(measured) < 2:
        return "needs multisines at two levels or more (the mode's frequency compared between levels)"
    rows = [row for row in level_modes(measured, common_lines(measured)) if row[f"{quantity}_significant"]]
    if not rows:
        return f"no mode of the BLA changes its {quantity} significantly with the level"
    return sorted(rows, key=lambda row: -abs(row[f"{quantity}_change"]) / row[f"{quantity}_change_se"])


def level_line(ctx: Context, row: dict, pole: complex, effect: "Effect") -> tuple[float, float, float, int] | str:
    """(slope, its standard error, intercept, levels used) of the weighted line y_L = a + b sigma_L^2
    (module docstring) over the levels where the mode is fitted and an estimation run has that
    level: for a cubic spring y = w_L^2 = (2 pi f_L)^2 against the variance of q, for a cubic
    damper y = 2 zeta_L w_L against the variance of q'; the standard errors of y from those of
    f_L and zeta_L (first order), times the Birge ratio where the line misses the points beyond them."""
    y, se, var = [], [], []
    for fit in row["levels"]:
        if fit is None:
            continue
        members = [run for run in ctx.runs if run.level == fit["level"]]
        if not members:
            continue
        w, se_w = 2 * math.pi * fit["frequency_hz"], 2 * math.pi * fit["frequency_se_hz"]
        if effect.derivative == 0:
            y.append(w * w)
            se.append(2 * w * se_w)
        else:
            y.append(2 * fit["damping"] * w)
            se.append(2 * math.hypot(fit["damping_se"] * w, fit["damping"] * se_w))
        var.append(float(np.mean([modal_variance(run, pole, effect.derivative) for run in members])))
    if len(y) < 2:
        return "the mode is fitted at fewer than two levels of the estimation runs"
    y, se, var = np.array(y), np.array(se), np.array(var)
    if not (np.all(np.isfinite(y)) and np.ptp(var) > 0):
        return "the modal amplitude is the same at every level where the mode is fitted"
    weight = 1 / np.maximum(se, 1e-12 * np.abs(y))
    scale = float(np.max(var))  # the variances in units of the largest: columns of like size
    X = np.column_stack([np.ones_like(var), var / scale]) * weight[:, None]
    (a, b), *_ = np.linalg.lstsq(X, y * weight, rcond=None)
    dof = y.size - 2
    birge = max(1.0, float(np.sum((y * weight - X @ np.array([a, b])) ** 2)) / dof) if dof > 0 else 1.0
    cov = np.linalg.inv(X.T @ X) * birge
    return float(b) / scale, math.sqrt(max(float(cov[1, 1]), 0.0)) / scale, float(a), int(y.size)


@dataclass(frozen=True)
class Effect:
    """A cubic force on the moving mode's coordinate: its config ``force`` type and ``parameter``,
    the mode's ``quantity`` that moves (``frequency`` or ``damping``), the ``derivative`` of q it
    reads (0: q, 1: q'), and the A entry its intercept starts (the block's -w^2 or -2 zeta w)."""

    force: str
    parameter: str
    quantity: str
    derivative: int
    entry: str


SPRING = Effect("cubic_stiffness", "k3", "frequency", 0, "A[1][0]")
DAMPER = Effect("cubic_damping", "c3", "damping", 1, "A[1][1]")


@dataclass(frozen=True)
class Joint:
    """A moving mode's joint as started (module docstring): the BLA's ``row``, the model's ``mode``
    matched to it, the force parameter's ``value`` and standard error ``std``, the block's
    ``intercept`` (w0^2 or 2 zeta w at zero amplitude) and the ``levels`` its line used."""

    row: dict
    mode: Mode
    value: float
    std: float
    intercept: float
    levels: int


def joint(ctx: Context, row: dict, pairs: list[Mode], effect: "Effect") -> Joint | str:
    """The joint of the BLA's moving mode ``row`` on the nearest of the model's ``pairs``, or why
    there is none (no pair within :data:`MATCH`, no line over the levels, a change the effect
    cannot make)."""
    f_moving = row["frequency_hz"]
    mode = min(pairs, key=lambda m: abs(m.frequency_hz / f_moving - 1))
    if abs(mode.frequency_hz / f_moving - 1) > MATCH:
        return (f"the BLA's mode at {f_moving:.4g} Hz changes with the level, and the model has no mode within "
                f"{MATCH:.0%} of it")
    line = level_line(ctx, row, mode.pole, effect)
    if isinstance(line, str):
        return line
    slope, slope_std, intercept, used = line
    value = slope / 3  # the equivalent stiffness (damping) 3 k3 sigma_q^2 (3 c3 sigma_v^2)
    if not (value != 0 and intercept > 0):
        return f"the mode's {effect.quantity} does not change with the modal amplitude"
    if effect is DAMPER and value < 0:
        return "the mode's damping falls with the level (a cubic damper raises it)"
    return Joint(row, mode, value, slope_std / 3, intercept, used)


def second_joint(ctx: Context, rows: list[dict], pairs: list[Mode], first: Joint, effect: "Effect") -> Joint | None:
    """The joint of the next moving mode (``rows`` after the first, most significant first) on
    another of the model's modes whose line over the levels is significant itself (|value| >
    :data:`SECOND_SIGNIFICANCE` standard errors); None where there is none."""
    others = [m for m in pairs if m is not first.mode]
    for row in rows:
        found = joint(ctx, row, others, effect) if others else None
        if isinstance(found, Joint) and abs(found.value) > SECOND_SIGNIFICANCE * found.std:
            return found
    return None


def _estimator(effect: Effect):
    def estimate(ctx: Context) -> Estimate | str:
        """Start values (module docstring)."""
        ss, notes = continuous_model(lti_of(ctx.runner), ctx.runs[0].fs)
        if isinstance(ss, str):
            return f"not fitted: {ss}"
        modes = modes_of(ss)
        if isinstance(modes, str):
            return f"not fitted: {modes}"
        rows = moving_modes(ctx, effect.quantity)
        if isinstance(rows, str):
            return f"not fitted: {rows}"
        pairs = [m for m in modes if m.pair]
        if not pairs:
            return "not fitted: the model has no resonance (no complex pole pair)"
        first = joint(ctx, rows[0], pairs, effect)
        if isinstance(first, str):
            return f"not fitted: {first}"
        second = second_joint(ctx, rows[1:], pairs, first, effect)
        joints = [first] if second is None else [first, second]
        moving = [j.mode for j in joints]
        lti = modal_state_space(moving + [m for m in modes if all(m is not k for k in moving)], ss.D)
        r, c = (int(i) for i in effect.entry[2:-1].split("]["))
        own = {}
        for n, j in enumerate(joints):
            lti["A"][r + 2 * n][c + 2 * n] = -j.intercept
            own[_name(effect.parameter, n)] = j.value
            if ss.D != 0:  # the moving mode's acceleration, at the w^2 the start gives the block
                own[_name(FEEDTHROUGH_KEY, n)] = acceleration_share(lti, 2 * n)
        data = {**ctx.runner.data, "model": {**{k: v for k, v in ctx.runner.data["model"].items() if k in KEPT},
                                             **lti}}
        paths = {**_paths_of(effect)(data), **_second_paths(effect, len(joints), ss.D != 0)}
        values = {**own, **{name: float(_value(data, path)) for name, path in paths.items() if name not in own}}
        before = ctx.simulation_rss(ctx.runner.data)
        try:
            after = ctx.simulation_rss(_extender(effect)(data, values))
        except InputError as exc:  # the start diverges: scored as explaining nothing
            after, notes = before, [*notes, f"the start could not be simulated ({exc.what})"]
        notes = [*(_joint_note(j, effect, n) for n, j in enumerate(joints)), *notes]
        std = {name: math.nan for name in values}
        std.update({_name(effect.parameter, n): j.std for n, j in enumerate(joints)})
        return Estimate(values, std, explained_db(before, after), "; ".join(notes), paths=paths, lti=lti)
    return estimate


def _name(base: str, n: int) -> str:
    """A parameter's (or point's) name for the n-th moving mode: ``k3``, ``k3_2``."""
    return base if n == 0 else f"{base}_{n + 1}"


def _second_paths(effect: "Effect", count: int, acceleration: bool) -> dict[str, str]:
    """The key paths of the second moving mode's force parameter (and feedthrough)."""
    if count < 2:
        return {}
    point = _name(POINT, 1)
    out = {_name(effect.parameter, 1): f"model.nonlinearities[1].{effect.parameter}"}
    if acceleration:
        out[_name(FEEDTHROUGH_KEY, 1)] = f"model.points.{point}.{FEEDTHROUGH_KEY}"
    return out


def _joint_note(j: Joint, effect: "Effect", n: int) -> str:
    row, quantity = j.row, effect.quantity
    change, change_se = row[f"{quantity}_change"], row[f"{quantity}_change_se"]
    which = "mode" if n == 0 else "second moving mode"
    return (f"{which} near {row['frequency_hz']:.4g} Hz (the BLA's, {quantity} {change:+.2%} +- {change_se:.2%} "
            f"from level {row['from_level']:g} to {row['to_level']:g}), the model's at {j.mode.frequency_hz:.4g} Hz; "
            f"{_name(effect.parameter, n)} = b / 3 from the line {_line_text(effect)} over {j.levels} levels")


def _line_text(effect: Effect) -> str:
    if effect is SPRING:
        return "w^2 = a + b sigma_q^2 (the mode's start at zero amplitude: w^2 = a)"
    return "2 zeta w = a + b sigma_v^2 (the mode's start at zero amplitude: 2 zeta w = a)"


def _value(data: dict, path: str) -> float:
    from nlsid.fit.free_parameters import value_at

    return value_at(data, path.replace("model.linear.", "model."))


def _paths_of(effect: Effect):
    def paths(data: dict) -> dict[str, str]:
        """The force's parameter and every block's coefficients (module docstring): a pair's -w^2
        (``A[j+1][j]``), -2 zeta w (``A[j+1][j+1]``), beta (``C[j]``) and alpha (``C[j+1]``), a real
        pole's p and r; an output coefficient negligible beside the block's other (a
        displacement's alpha) left out. ``data``: the config whose model is the modal state space
        (before or after the extension)."""
        model = data["model"]
        linear = model["linear"] if model["type"] == "nonlinear_feedback" else model
        A, C = linear["A"], linear["C"]
        out = {effect.parameter: f"model.nonlinearities[0].{effect.parameter}"}
        if linear.get("D", 0.0) != 0:  # an acceleration output: D and the moving mode's feedthrough
            out.update({"D": "model.linear.D", FEEDTHROUGH_KEY: f"model.points.{POINT}.{FEEDTHROUGH_KEY}"})
        for j, size in blocks(linear):
            if size == 1:
                names = [(f"A[{j}][{j}]", A[j][j]), (f"C[{j}]", C[j])]
            else:
                w = math.sqrt(abs(A[j + 1][j]))
                beta, alpha = C[j], C[j + 1]
                names = [(f"A[{j + 1}][{j}]", A[j + 1][j]), (f"A[{j + 1}][{j + 1}]", A[j + 1][j + 1])]
                if abs(beta) > NEGLIGIBLE * abs(alpha) * w:
                    names.append((f"C[{j}]", beta))
                if abs(alpha) * w > NEGLIGIBLE * abs(beta):
                    names.append((f"C[{j + 1}]", alpha))
            out.update({name: f"model.linear.{name}" for name, value in names if value != 0})
        return out
    return paths


def _extender(effect: Effect):
    def extend(data: dict, values: dict) -> dict:
        """The modal state space of ``data`` (the moving mode first) as the linear part of a
        ``nonlinear_feedback`` with the effect's force at the moving mode's point."""
        out = copy.deepcopy(data)
        model = out["model"]
        linear = {k: copy.deepcopy(model[k]) for k in ("type", "domain", "A", "B", "C")}
        linear["D"] = float(values.get("D", model.get("D", 0.0)))
        for name, value in values.items():
            if name.startswith("A["):
                r, c = (int(i) for i in name[2:-1].split("]["))
                linear["A"][r][c] = float(value)
            elif name.startswith("C["):
                linear["C"][int(name[2:-1])] = float(value)
        n = len(linear["B"])
        points, forces = {}, []
        count = 2 if _name(effect.parameter, 1) in values else 1
        for m in range(count):  # the moving modes' blocks first, each (q, q') from state 2 m
            force, position = [0.0] * n, [0.0] * n
            force[2 * m + 1], position[2 * m] = 1.0, 1.0
            point = {"force": force, "position": position}
            if values.get(_name(FEEDTHROUGH_KEY, m)):
                point[FEEDTHROUGH_KEY] = float(values[_name(FEEDTHROUGH_KEY, m)])
            points[_name(POINT, m)] = point
            forces.append({"type": effect.force, effect.parameter: float(values[_name(effect.parameter, m)]),
                           "at": _name(POINT, m)})
        out["model"] = {"type": "nonlinear_feedback", "linear": linear, "gain": 1.0, "points": points,
                        "nonlinearities": forces, **{k: model[k] for k in KEPT if k in model}}
        return out
    return extend


def _frequency_hz(values: dict, n: int = 0) -> float:
    """The natural frequency of the n-th moving mode's block (its -w^2 at A[2n+1][2n])."""
    key = f"A[{2 * n + 1}][{2 * n}]"
    return math.sqrt(-values[key]) / (2 * math.pi) if values.get(key, 0) < 0 else math.nan


def _spring_reading(values: dict) -> str:
    text = (f"a {spring(values['k3'])} cubic spring on the modal coordinate of the mode at "
            f"{_frequency_hz(values):.4g} Hz (zero amplitude)")
    if "k3_2" in values:
        text += f", and a {spring(values['k3_2'])} one on the mode at {_frequency_hz(values, 1):.4g} Hz"
    return text


def _damper_reading(values: dict) -> str:
    text = f"a cubic damper on the modal velocity of the mode at {_frequency_hz(values):.4g} Hz"
    if "c3_2" in values:
        text += f", and one on the mode at {_frequency_hz(values, 1):.4g} Hz"
    return text


MODAL_JOINT = Hypothesis(
    "modal_joint", "Cubic spring on the moving mode(s) (a nonlinear joint in modal form)", "stiffness", "k3",
    "input units / modal coordinate^3",
    "odd distortion; the frequency of one mode of a multi-mode model moves with the level; the rest stay",
    _applies, _estimator(SPRING), _extender(SPRING), ("k3",), _paths_of(SPRING), reading=_spring_reading,
    qualifier=lambda values: spring(values["k3"]))

MODAL_DAMPING = Hypothesis(
    "modal_damping", "Cubic damping on the moving mode(s) (a dissipative joint in modal form)", "friction", "c3",
    "input units / modal velocity^3",
    "odd distortion; the damping of one mode of a multi-mode model grows with the level",
    _applies, _estimator(DAMPER), _extender(DAMPER), ("c3",), _paths_of(DAMPER), reading=_damper_reading)

HYPOTHESES = (MODAL_JOINT, MODAL_DAMPING)
