"""The time-stepping kernel (numba): a sampled-data loop around a state-space plant.

One call simulates one run, sample by sample (k = 0 .. N-1, t_k = k Ts):

1. closed loop: the controller (discrete state space with inputs [e, y_m]: Ac, Bc (nc x 2), Cc,
   Dc (2)) reads the measured output y_m[k] (the recorded y below, noise included) and the
   reference r[k] (already through the prefilter), and outputs
   u[k] = Cc xc + Dc[0] e + Dc[1] y_m + ff[k], e = r[k] - y_m[k] (:mod:`nlsid.models.controller`);
   open loop: u[k] is the given input.
2. the plant input p[k] = f_in(u[k - d] + n_p[k]) + p_bias (dead time of d samples, zero before
   the start; n_p the process noise, input offset and measured input channels; input block f_in,
   :func:`block`; p_bias a constant force term, a template's force_offset / gain) is held
   constant over [t_k, t_k+1) (the DAC's zero-order hold).
3. the output recorded is y[k] = f_out(y(t_k + phi Ts)) + n_y[k] (output block f_out, n_y the
   noise and output offset), read from the state, the input and the forces of the sample by the
   coefficients c_x, c_p, c_f: y(t_k + phi Ts) = c_x x(t_k) + c_p p[k] - sum c_f F. Without
   ``lag``, phi = the output timing in [0, 1) (phi = 0: c_x = C, c_p = D, no c_f); with ``lag``
   (a timing t < 0) the value read with phi = 1 + t in sample k is recorded as y[k + 1], and
   y[0] = C x(0). In closed loop the output must not depend on this sample's input (D = 0 and
   phi = 0, or a lag).
4. the plant state is advanced over ``substeps`` sub-steps of h = Ts / substeps: exact ZOH
   propagation x+ = Phi x + Gamma p, then each nonlinear force in turn (:func:`force`) is
   held over the sub-step, x+ -= Gamma_F F (the laws and their numerical treatment are in
   :mod:`nlsid.models.forces`). The recursion is evaluated in closed form per sample
   (:mod:`nlsid.simulate.propagation`): each force reads its signal from the state at the start
   of the sample and the forces chosen before it, and the state is updated once per sample.

Without nonlinear forces the result at the sample instants is exact for any number of sub-steps
(up to rounding): the ZOH propagation is the exact solution for a held input. The input and output
blocks act on held (or sampled) signals, so evaluating them once per sample is exact as well.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from nlsid.models import blocks, forces
from nlsid.simulate.jit import njit  # numba, its cache outside the package (not `from numba`)

SLIDING = 6.5  # |v| / vs above which e^{-(v/vs)^2} < 5e-19: the Stribeck term is below rounding


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def block(kind: int, p: np.ndarray, x: float, memory: float) -> float:
    """Output of a nonlinear block (laws and parameter encoding in :mod:`nlsid.models.blocks`) for
    input ``x``; ``memory`` is the block's previous output (used by the backlash only)."""
    if kind == blocks.IDENTITY:
        return x
    if kind == blocks.POLYNOMIAL:  # Horner
        y = 0.0
        for i in range(p.shape[0] - 1, -1, -1):
            y = y * x + p[i]
        return y
    if kind == blocks.SATURATION:
        return min(max(x, p[0]), p[1])
    if kind == blocks.DEADZONE:
        return x - p[1] if x > p[1] else (x - p[0] if x < p[0] else 0.0)
    if kind == blocks.PIECEWISE_LINEAR:
        n = p.shape[0] // 2
        i = 0  # segment (x_i, x_{i+1}); the end segments extend beyond the first and last point
        hi = n - 2
        while i < hi:  # bisection for the last x_i <= x, clamped to 0 .. n - 2
            mid = (i + hi + 1) // 2
            if p[mid] <= x:
                i = mid
            else:
                hi = mid - 1
        return p[n + i] + (p[n + i + 1] - p[n + i]) * (x - p[i]) / (p[i + 1] - p[i])
    # BACKLASH: play operator of half width p[0]
    if x - memory > p[0]:
        return x - p[0]
    if memory - x > p[0]:
        return x + p[0]
    return memory


@njit(cache=True, fastmath={"contract"}, nogil=True)
def apply_block(kind: int, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """:func:`block` along a signal, starting from memory 0."""
    y = np.empty_like(x)
    memory = 0.0
    for k in range(x.shape[0]):
        memory = block(kind, p, x[k], memory)
        y[k] = memory
    return y


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _stick_or_slip(v_free: float, g: float, breakaway: float, breakaway_neg: float) -> bool:
    """Whether the mass sticks: the force that holds it, v_free / g, lies in [-breakaway_neg, breakaway]."""
    return -(g * breakaway_neg) <= v_free <= g * breakaway


@njit(cache=True, fastmath={"contract"}, nogil=True)
def _derived(kinds: np.ndarray, p: np.ndarray, h: float, gains: np.ndarray) -> np.ndarray:
    """Per-element constants of the LuGre step for sub-step h and force gain g (computed once per
    run): theta (:mod:`nlsid.models.forces`; the stiffness with the larger side of sigma2), 1/vs,
    sigma0 h, sigma1/h, 1/fc for v > 0 and 1/fc for v < 0."""
    d = np.zeros((p.shape[0], 6))
    for e in range(p.shape[0]):
        if kinds[e] == forces.LUGRE:
            stiffness = gains[e] * (p[e, 0] * h + p[e, 1] + max(p[e, 2], p[e, 2] + p[e, 6]))
            d[e, 0] = max(0.5, 1.0 - 0.5 / stiffness) if stiffness > 0.0 else 0.5
            d[e, 1] = 1.0 / p[e, 5]
            d[e, 2] = p[e, 0] * h
            d[e, 3] = p[e, 1] / h
            d[e, 4] = 1.0 / p[e, 3]
            d[e, 5] = 1.0 / (p[e, 3] + p[e, 7])
    return d


def _series(weight) -> tuple:
    """Taylor coefficients c_n = (-1)^n weight(n) / (n + 1)!, n = 0 .. 15, of the relaxation functions."""
    return tuple((-1.0) ** n * weight(n) / math.factorial(n + 1) for n in range(16))


# m0 = sum (-x)^n / (n+1)!, r = sum (-x)^n / (n+2)!, dr/dx = -sum (n+1) (-x)^n / (n+3)!, summed to
# n = 15 for x <= SERIES_END: the first term left out is below 3e-17 of the sum (0.75^16 / 17! for m0).
SERIES_END = 0.75
M0 = _series(lambda n: 1.0)
R = _series(lambda n: 1.0 / (n + 2))
DR = _series(lambda n: -(n + 1) / ((n + 2) * (n + 3)))


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _estrin(c, x: float, x2: float, x4: float, x8: float) -> float:
    """sum c_n x^n, n = 0 .. 15, by Estrin's scheme (four dependent multiply-adds instead of 15)."""
    a0, a1, a2, a3 = c[0] + c[1] * x, c[2] + c[3] * x, c[4] + c[5] * x, c[6] + c[7] * x
    a4, a5, a6, a7 = c[8] + c[9] * x, c[10] + c[11] * x, c[12] + c[13] * x, c[14] + c[15] * x
    b0, b1, b2, b3 = a0 + a1 * x2, a2 + a3 * x2, a4 + a5 * x2, a6 + a7 * x2
    return (b0 + b1 * x4) + (b2 + b3 * x4) * x8


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _relaxation(x: float) -> tuple[float, float, float, float]:
    """m0 = (1 - e^-x) / x (the mean of e^{-lambda t} over the sub-step, x = lambda h), r = (1 - m0) / x,
    and their derivatives in x, dm0/dx = r - m0 (from e^-x = 1 - x m0) and dr/dx.

    Up to SERIES_END (a mild relaxation over the sub-step: on the sample stage 60-99 % of the
    evaluations under a sine, 23-39 % under a multisine) their power series, with no exponential,
    division or cancellation on the kernel's serial chain;
    beyond, the closed forms with exp, which have no cancellation there. Both within a few units in
    the last place (tests/simulate/test_simulate_friction.py checks against an 80-digit evaluation). Measured on
    the sample stage: kernel time 16-27 % lower than with expm1 at every x (docs/commands.md).
    """
    if x <= SERIES_END:
        x2 = x * x
        x4 = x2 * x2
        x8 = x4 * x4
        m0, r = _estrin(M0, x, x2, x4, x8), _estrin(R, x, x2, x4, x8)
        return m0, r, r - m0, _estrin(DR, x, x2, x4, x8)
    inv_x = 1.0 / x
    decay = math.exp(-x)
    m0 = (1.0 - decay) * inv_x
    r = (1.0 - m0) * inv_x
    dm0 = (decay - m0) * inv_x
    return m0, r, dm0, -(dm0 + r) * inv_x


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _lugre(p: tuple, d: tuple, z: float, previous: float, s_free: float, s_now: float, g: float,
           h: float) -> tuple[float, float]:
    """LuGre force over a sub-step and the bristle state z at its end (scheme and error in
    :mod:`nlsid.models.forces`), solved for the weighted velocity vv = v + theta (v+ - v).

    ``s_now`` and ``s_free`` are the velocity at the start and at the end without this force, so
    vv = vv_free - theta g F(vv), vv_free = v + theta (v_free - v). The force over the sub-step is
    F(vv) = f_z z + f_v vv, whose coefficients depend on x = h sigma0 |vv| / s(vv). The residual
    R(vv) = vv + theta g F(vv) - vv_free has at vv = 0 the value theta g sigma0 z - vv_free, so the
    root lies on the side of zero of -R(0), where |vv| is smooth: Newton's method there
    (an iterate that crosses zero is replaced by half the previous one), from the prediction
    v_free - g F_prev with F_prev the ``previous`` sub-step's force, until the step is below
    LUGRE_TOLERANCE (|vv| + vs). ``p`` holds the element's parameters, ``d`` its constants of
    :func:`_derived`. The levels fc, fs and the viscous sigma2 are those of the side of zero the
    root lies on (a continuous law: lambda and sigma2 vv vanish at vv = 0 on both sides).
    """
    sigma0, sigma1, sigma2, fc, fs, vs, d_sigma2, d_fc, d_fs = p
    theta, inv_vs, s0h, s1h, inv_fc, inv_fc_neg = d
    a = 2.0 - 2.0 * theta  # weights of the mean and of the end value of z in the spring force
    b = 2.0 * theta - 1.0
    tg = theta * g
    vv_free = s_now + theta * (s_free - s_now)
    r0 = tg * sigma0 * z - vv_free
    if r0 == 0.0:
        return sigma0 * z, z
    sd = -1.0 if r0 > 0.0 else 1.0
    if r0 > 0.0:  # the root lies at vv < 0: that side's levels
        sigma2, fc, fs, inv_fc = sigma2 + d_sigma2, fc + d_fc, fs + d_fs, inv_fc_neg
    vv = s_now + theta * (s_free - g * previous - s_now)
    if vv * sd <= 0.0:  # the prediction is on the wrong side: the root of R linearised at x = 0
        vv = -r0 / (1.0 + tg * (s0h * (0.5 * a + b) + sigma1 + sigma2))
    force, decay, m0 = sigma0 * z, 1.0, 1.0
    for _ in range(forces.MAX_ITERATIONS):
        w = vv * inv_vs
        if w * w < SLIDING * SLIDING:
            ex = math.exp(-w * w)
            inv_level = 1.0 / (fc + (fs - fc) * ex)
        else:  # sliding: the level is fc
            ex, inv_level = 0.0, inv_fc
        x = s0h * vv * sd * inv_level
        m0, r, dm0, dr = _relaxation(x)
        decay = 1.0 - x * m0
        f_v = s0h * (a * r + b * m0) + sigma1 * m0 + sigma2
        force = (sigma0 * (a * m0 + b * decay) - s1h * x * m0) * z + f_v * vv
        # dF/dx (d decay/dx = -(m0 + x dm0)) and dx/dvv (the level s falls with |vv|)
        df_dx = ((sigma0 * (a * dm0 - b * (m0 + x * dm0)) - s1h * (m0 + x * dm0)) * z
                 + (s0h * (a * dr + b * dm0) + sigma1 * dm0) * vv)
        dx_dvv = s0h * inv_level * (sd + 2.0 * (fs - fc) * ex * w * inv_vs * vv * sd * inv_level)
        df_dvv = f_v + df_dx * dx_dvv
        step = (vv + tg * force - vv_free) / (1.0 + tg * df_dvv)
        v_new = vv - step
        if abs(step) <= forces.LUGRE_TOLERANCE * (abs(vv) + vs) and v_new * sd > 0.0:
            # F and z+ carried to v_new to first order: off by O(step^2), not by step (1 + theta g F'),
            # which for stiff bristles (theta g F' ~ 1e3) would let a mass at rest creep
            dz_dvv = (h * dm0 * vv - (m0 + x * dm0) * z) * dx_dvv + h * m0
            return force - df_dvv * step, decay * z + h * m0 * vv - dz_dvv * step
        vv = v_new if v_new * sd > 0.0 else 0.5 * vv
    return force, decay * z + h * m0 * vv


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _side(kind: int, p: tuple, forward: bool) -> tuple[float, float, float]:
    """(fc, fs, fv) of a friction law on one side of zero (Coulomb: fs = fc, no break-away peak)."""
    if kind == forces.COULOMB:
        fc, fv = (p[0], p[1]) if forward else (p[0] + p[2], p[1] + p[3])
        return fc, fc, fv
    if forward:
        return p[0], p[1], p[4]
    return p[0] + p[5], p[1] + p[6], p[4] + p[7]


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _ratio_power(w: float, vs: float, delta: float) -> float:
    """(w / vs)^delta, as a product for the usual delta = 2 (a general power costs a fifth of a
    Stribeck sub-step; the product is the same number)."""
    x = w / vs
    return x * x if delta == 2.0 else x ** delta


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _level(kind: int, fc: float, fs: float, vs: float, delta: float, w: float) -> float:
    """The friction level at speed w >= 0 without the viscous term: fc, or fc + (fs - fc) e^{-(w/vs)^delta}."""
    if kind == forces.COULOMB:
        return fc
    return fc + (fs - fc) * math.exp(-_ratio_power(w, vs, delta))


@njit(cache=True, fastmath={"contract"}, nogil=True)
def _gamma_p(a: float, x: float) -> float:
    """The regularised lower incomplete gamma function P(a, x) = gamma(a, x) / Gamma(a), x >= 0: its
    series sum_n x^n / (a (a+1) .. (a+n)) times x^a e^{-x} / Gamma(a) for x < a + 1, else 1 - Q
    with Q's continued fraction by the modified Lentz method (Press et al. 2007, Numerical Recipes,
    3rd ed., Section 6.2, eqs. 6.2.5 and 6.2.7), both summed to rounding."""
    if x <= 0.0:
        return 0.0
    front = math.exp(a * math.log(x) - x - math.lgamma(a))
    if x < a + 1.0:
        term = total = 1.0 / a
        n = a
        for _ in range(1000):
            n += 1.0
            term *= x / n
            total += term
            if abs(term) < 1e-17 * abs(total):
                break
        return total * front
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 1000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        step = d * c
        h *= step
        if abs(step - 1.0) < 1e-16:
            break
    return 1.0 - front * h


@njit(cache=True, fastmath={"contract"}, nogil=True)
def _stribeck_area(vs: float, delta: float, w: float) -> float:
    """The integral I(w) of e^{-(x/vs)^delta} over x in [0, w]: with t = (x/vs)^delta it is
    vs Gamma(1 + 1/delta) P(1/delta, (w/vs)^delta) (:func:`_gamma_p`); vs sqrt(pi)/2 erf(w/vs) for
    delta = 2."""
    if delta == 2.0:
        return 0.5 * math.sqrt(math.pi) * vs * math.erf(w / vs)
    a = 1.0 / delta
    return vs * math.exp(math.lgamma(1.0 + a)) * _gamma_p(a, (w / vs) ** delta)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _area(kind: int, p: tuple, speed: float) -> float:
    """I(speed) of :func:`_stribeck_area` for a Stribeck law (0 for Coulomb, which does not use it;
    beyond :func:`_sliding_speed` it is I(infinity) = vs Gamma(1 + 1/delta) to rounding)."""
    if kind == forces.COULOMB:
        return 0.0
    if speed >= _sliding_speed(p[2], p[3]):
        return p[2] * math.exp(math.lgamma(1.0 + 1.0 / p[3]))
    return _stribeck_area(p[2], p[3], speed)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _ramp_mean(kind: int, fc: float, fs: float, vs: float, delta: float, a: float, b: float, area_a: float) -> float:
    """The mean friction level while the speed moves linearly between a and b (both >= 0): fc, or
    fc + (fs - fc) (I(a) - I(b)) / (a - b) with I of :func:`_stribeck_area` (``area_a`` = I(a),
    computed once by the caller for the several b of an iteration); the level at the
    midpoint when a and b are within 1e-4 (a + b + vs) (error (a - b)^2 |level''| / 24)."""
    if kind == forces.COULOMB:
        return fc
    if abs(a - b) <= 1e-4 * (a + b + vs):
        return _level(kind, fc, fs, vs, delta, 0.5 * (a + b))
    return fc + (fs - fc) * (area_a - _stribeck_area(vs, delta, b)) / (a - b)


# A Newton step of this relative size leaves an error of about K step^2, K = |psi''| / (2 |psi'|)
# (psi' ~ 1, psi'' ~ g |M''| ~ g (fs - fc) / vs^2, so K (w + vs) << 1): below TOLERANCE (1e-10).
QUADRATIC_TOLERANCE = 1e-6


# Not inlined: its bracketed iteration is long and rarely used; inlined, it slows the common laws.
@njit(cache=True, fastmath={"contract"}, nogil=True)
def _stribeck_speed(fc: float, fs: float, vs: float, delta: float, fv: float, a: float, area_a: float,
                    target: float, g: float) -> float:
    """The root w in (0, target) of psi(w) = w (1 + g fv / 2) + g (M(w) + fv a / 2) - target, M(w)
    the mean level over the speed ramp from a to w (:func:`_ramp_mean`, ``area_a`` = I(a)), given psi(0) < 0
    (psi(target) > 0): Newton's method, with bisection whenever a step leaves the bracket (the
    Stribeck curve's negative slope can make psi non-monotone, where a plain fixed-point
    iteration would diverge). dM/dw = (M(w) - level(w)) / (a - w), level'(w) / 2 at w = a."""
    lo, hi = 0.0, target
    w = (target - g * (_level(forces.STRIBECK, fc, fs, vs, delta, a) + 0.5 * fv * a)) / (1.0 + 0.5 * g * fv)
    if not 0.0 < w < target:
        w = target
    for _ in range(forces.MAX_ITERATIONS):
        mean = _ramp_mean(forces.STRIBECK, fc, fs, vs, delta, a, w, area_a)
        psi = w * (1.0 + 0.5 * g * fv) + g * (mean + 0.5 * fv * a) - target
        if psi == 0.0:  # the root (Newton lands on it where the curve is flat; bisecting on would leave it)
            return w
        if psi > 0.0:
            hi = w
        else:
            lo = w
        level = _level(forces.STRIBECK, fc, fs, vs, delta, w)
        if abs(a - w) > 1e-4 * (a + w + vs):
            d_mean = (mean - level) / (a - w)
        else:
            ratio = _ratio_power(w, vs, delta)
            d_mean = -0.5 * (fs - fc) * math.exp(-ratio) * delta * ratio / w if w > 0.0 else 0.0
        w_new = w - psi / (1.0 + 0.5 * g * fv + g * d_mean)
        settled = QUADRATIC_TOLERANCE
        if not lo <= w_new <= hi:
            w_new = 0.5 * (lo + hi)
            settled = forces.TOLERANCE
        done = abs(w_new - w) <= settled * (w_new + vs)
        w = w_new
        if done:
            break
    return w


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _sliding_speed(vs: float, delta: float) -> float:
    """The speed beyond which the Stribeck term e^{-(w/vs)^delta} is below e^{-SLIDING^2} = 4.5e-19,
    that is below rounding against the level fc."""
    return SLIDING * vs if delta == 2.0 else vs * (SLIDING * SLIDING) ** (1.0 / delta)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _ramp_force(kind: int, p: tuple, forward: bool, a: float, target: float, g: float, area_a: float) -> float:
    """The magnitude of the force held over a sub-step in which the mass moves on one side from
    speed a to the end speed w: the mean of the law over that (linear) speed ramp,
    M(a, w) + fv (a + w) / 2, with w solving w = target - g (M(a, w) + fv (a + w) / 2), which has a
    root w > 0 when target > g (M(a, 0) + fv a / 2) (the caller's); with M = fc (Coulomb) in
    closed form, w = (target - g (fc + fv a / 2)) / (1 + g fv / 2). A Stribeck law whose ramp stays
    beyond :func:`_sliding_speed` (both a and that w) is fc there to rounding, so the closed form is
    its root as well (the fast sliding of a friction test: no erf and no iteration); otherwise
    :func:`_stribeck_speed`. ``area_a``: I(a) of :func:`_stribeck_area` (unused by Coulomb)."""
    fc, fs, fv = _side(kind, p, forward)
    w = (target - g * (fc + 0.5 * fv * a)) / (1.0 + 0.5 * g * fv)
    if kind == forces.COULOMB or min(a, w) >= _sliding_speed(p[2], p[3]):
        return fc + 0.5 * fv * (a + w)
    w = _stribeck_speed(fc, fs, p[2], p[3], fv, a, area_a, target, g)
    return _ramp_mean(kind, fc, fs, p[2], p[3], a, w, area_a) + 0.5 * fv * (a + w)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _from_rest(kind: int, p: tuple, s_free: float, g: float) -> float:
    """Coulomb or Stribeck force over a sub-step that starts at rest (Moreau): sticks while
    -g fs- <= v_free <= g fs+ (the break-away forces; fc for Coulomb), the force then v_free / g;
    else slides on the side of v_free, the force the law's mean over the speed ramp from 0
    (:func:`_ramp_force`)."""
    if _stick_or_slip(s_free, g, _side(kind, p, True)[1], _side(kind, p, False)[1]):
        return s_free / g
    forward = s_free > 0.0
    f = _ramp_force(kind, p, forward, 0.0, abs(s_free), g, 0.0)
    return f if forward else -f


# Not inlined: compiled once on its own, it keeps the kernel's compilation short (inlined, 3x longer).
@njit(cache=True, fastmath={"contract"}, nogil=True)
def _friction(kind: int, p: tuple, s_now: float, s_free: float, g: float) -> float:
    """Coulomb or Stribeck force held over a sub-step from the start velocity v = ``s_now``: the
    law's mean over the sub-step's velocity path taken as linear, which makes the step second
    order in h in slip, at break-away and at reversals (scheme in :mod:`nlsid.models.forces`).

    From rest: :func:`_from_rest`. In slip on the side s of v: if the mass is still sliding on
    that side at the end (s v_free > g F_d, F_d = M(|v|, 0) + fv |v| / 2 the mean force of a ramp
    down to zero; first tested against its bound max(fc, fs) + fv |v| / 2, which needs no ramp
    mean), the mean over the ramp from |v| to the end speed (:func:`_ramp_force`). Otherwise the
    mass reaches v = 0 in the sub-step: with the other forces on the mass held
    (A = (v_free - v) / g), it decelerates under s F_d and stops at tau = v / (v - v_a),
    v_a = v_free - g s F_d; from rest there, the step over the remaining (1 - tau) h (free end
    velocity (1 - tau) g A, sensitivity (1 - tau) g) decides stick or slip on either side and gives
    F_b. The force held is the sub-step's mean tau s F_d + (1 - tau) F_b, which gives the end
    velocity of that motion. The branches meet at the end speed 0, tau = 1.
    """
    if s_now == 0.0:
        return _from_rest(kind, p, s_free, g)
    forward = s_now > 0.0
    s = 1.0 if forward else -1.0
    fc, fs, fv = _side(kind, p, forward)
    speed = abs(s_now)
    area = _area(kind, p, speed)
    if s * s_free > g * (max(fc, fs) + 0.5 * fv * speed):  # beyond the largest F_d: still sliding
        return s * _ramp_force(kind, p, forward, speed, s * s_free, g, area)
    stopping = _ramp_mean(kind, fc, fs, p[2], p[3], speed, 0.0, area) + 0.5 * fv * speed
    if s * s_free > g * stopping:
        return s * _ramp_force(kind, p, forward, speed, s * s_free, g, area)
    tau = s_now / (s_now - (s_free - g * s * stopping))
    rest = 1.0 - tau
    return tau * s * stopping + rest * _from_rest(kind, p, rest * (s_free - s_now), g * rest)


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _damping(c2: float, c3: float, a: float, b: float) -> float:
    """The nonlinear damping force F = c2 m |m| + c3 m^3 at the sub-step's mean velocity m, which the
    force itself lowers: m = (v + v+) / 2 = a - b F with a = (v + v_free) / 2 and b = g / 2 (the
    implicit midpoint rule, :mod:`nlsid.models.forces`). Newton's method on
    m + b (c2 m |m| + c3 m^3) = a from m = a: for c2, c3 >= 0 the left side is increasing and
    convex on the side of a, so the iterates fall monotonically onto the root (no overshoot)."""
    m = a
    for _ in range(forces.MAX_ITERATIONS):
        value = c2 * m * abs(m) + c3 * m * m * m
        slope = 1.0 + b * (2.0 * c2 * abs(m) + 3.0 * c3 * m * m)
        step = (m + b * value - a) / slope
        m -= step
        if abs(step) <= forces.TOLERANCE * abs(a):
            break
    return c2 * m * abs(m) + c3 * m * m * m


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _bouc_wen_rate(v: float, z: float, a: float, beta: float, gamma: float, n: float) -> float:
    """z' = A v - beta |v| |z|^(n-1) z - gamma v |z|^n (no power for the usual n = 1)."""
    if n != 1.0:
        size = abs(z) ** n
        return a * v - beta * abs(v) * math.copysign(size, z) - gamma * v * size
    return a * v - beta * abs(v) * z - gamma * v * abs(z)


# Not inlined: its loops would lengthen the kernel's compilation for a rarely used law.
@njit(cache=True, fastmath={"contract"}, nogil=True)
def _bouc_wen(p: tuple, z: float, previous: float, s_free: float, s_now: float, g: float,
              h: float) -> tuple[float, float]:
    """Bouc-Wen force over a sub-step and z at its end (scheme in :mod:`nlsid.models.forces`): z
    integrated by Heun's method along the velocity ramp from ``s_now`` to v+ = s_free - g F on
    parts short against its relaxation, the force k times z's trapezoidal mean; twice, from the
    ``previous`` sub-step's force and then from the first pass's."""
    k, a, beta, gamma, n = p[0], p[1], p[2], p[3], p[4]
    linear = n == 1.0  # the usual n = 1: no powers (|z|^0 = 1 exactly: the same rate), no bound needed
    bound = 0.0 if linear else (a / (beta + gamma)) ** (1.0 / n)
    force, end = previous, z
    for _ in range(2):
        v_end = s_free - g * force
        if linear:
            rate = (beta + abs(gamma)) * max(abs(s_now), abs(v_end))
        else:
            size = max(abs(z), bound)
            rate = (beta + abs(gamma)) * n * size ** (n - 1.0) * max(abs(s_now), abs(v_end))
        share = rate * h / forces.BOUC_WEN_PART
        if -1.0 < share < 1.0:  # one part, the usual: no divisions by it (x / 1 = x) on the serial chain
            parts, dt, dv = 1, h, v_end - s_now
        else:
            parts = min(forces.BOUC_WEN_PARTS, int(share) + 1)
            dt = h / parts
            dv = (v_end - s_now) / parts
        end = z
        total = 0.5 * z
        for i in range(parts):
            va = s_now + i * dv
            slope = _bouc_wen_rate(va, end, a, beta, gamma, n)
            guess = end + dt * slope
            end = end + 0.5 * dt * (slope + _bouc_wen_rate(va + dv, guess, a, beta, gamma, n))
            total += end
        force = k * (total - 0.5 * end)
        if parts != 1:
            force /= parts
    return force, end


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _stop(edge: float, sign: float, k: float, c: float, s_now: float, s_free: float, g: float, h: float) -> float:
    """The force of one end stop (``sign`` +1 beyond an upper edge, -1 below a lower) held over a
    sub-step (:mod:`nlsid.models.forces`): the free path from ``s_now`` to ``s_free`` taken as
    linear, the stop is touched over the share phi of the sub-step where it is beyond the edge,
    at the mean depth of that part; the spring and damper there, at the depth and velocity the
    force itself lowers, held over phi of the sub-step, cut at zero (a contact only pushes) and at
    the force that brings the mean depth back to zero."""
    d0, d1 = sign * (s_now - edge), sign * (s_free - edge)
    if d0 <= 0.0 and d1 <= 0.0:
        return 0.0
    if d0 >= 0.0 and d1 >= 0.0:
        phi = 1.0
    else:  # the edge is crossed within the sub-step
        phi = max(d0, d1) / abs(d1 - d0)
    depth = 0.5 * (max(d0, 0.0) + max(d1, 0.0))
    push = (k * depth + c * sign * (s_free - s_now) / h) / (1.0 + phi * g * (0.5 * k + c / h))
    if push <= 0.0:
        return 0.0
    if g > 0.0:
        push = min(push, 2.0 * depth / (phi * g))
    return sign * phi * push


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _end_stop(p: tuple, s_free: float, s_now: float, g: float, h: float) -> float:
    """The end stops' force over a sub-step from the position at its start ``s_now`` and at its
    end without the force ``s_free``: the stop whose side the sub-step reaches (lower < upper)."""
    if p[4] != 0.0 and max(s_now, s_free) > p[0]:
        return _stop(p[0], 1.0, p[2], p[3], s_now, s_free, g, h)
    if p[5] != 0.0 and min(s_now, s_free) < p[1]:
        return _stop(p[1], -1.0, p[2], p[3], s_now, s_free, g, h)
    return 0.0


@njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def force(kind: int, p: tuple, d: tuple, z: float, previous: float, s_free: float, s_now: float, g: float,
          h: float) -> tuple[float, float]:
    """The force of an element (parameters ``p``, LuGre's constants ``d``) held over one sub-step
    and its internal state after it (LuGre's bristle deflection, Bouc-Wen's z; ``z``, unused by the
    other laws, is returned unchanged). ``previous`` is the element's force over the previous sub-step (LuGre's
    prediction of the velocity).

    ``s_free`` is the read-out signal (velocity, or position for cubic and polynomial stiffness) at the
    end of the sub-step without this force, ``s_now`` its value at the start, ``g`` its sensitivity
    to a unit force held over the sub-step, ``h`` the sub-step length. The friction laws take their levels
    for v > 0 from ``p`` and those for v < 0 as these plus the offsets of :mod:`nlsid.models.forces`.
    """
    if kind == forces.LUGRE:
        return _lugre(p, d, z, previous, s_free, s_now, g, h)
    if kind == forces.COULOMB or kind == forces.STRIBECK:
        return _friction(kind, p, s_now, s_free, g), z
    if kind == forces.DAMPING:
        return _damping(p[0], p[1], 0.5 * (s_now + s_free), 0.5 * g), z
    if kind == forces.BOUC_WEN:
        return _bouc_wen(p, z, previous, s_free, s_now, g, h)
    if kind == forces.END_STOP:
        return _end_stop(p, s_free, s_now, g, h), z
    mid = 0.5 * (s_now + s_free)
    if kind == forces.POLYNOMIAL:  # k2 mid^2 + ... + k10 mid^10, Horner from k10 down
        acc = p[8]
        for i in (7, 6, 5, 4, 3, 2, 1, 0):
            acc = acc * mid + p[i]
        return acc * mid * mid, z
    # CUBIC
    return p[0] * mid * mid * mid, z


SIZED_SAMPLES = 1 << 19  # runs at least this long get a kernel compiled for their state sizes (:func:`simulate_loop`)

_KERNELS: dict[tuple, object] = {}
_KERNELS_LOCK = threading.Lock()


def simulate_loop(n_el: int, sizes: tuple[int, int] | None = None):
    """The kernel for ``n_el`` force elements (:func:`_make_loop`), one object per key for all
    threads: parallel runs then wait for one compilation instead of compiling it twice.

    ``sizes`` = (plant order, controller order) compiles these in as well: the loops over the
    state then unroll, 9 % less time per sample on the sample stage, for one more compilation
    (about 8 s, cached on disk) per model shape. The engine asks for it only for runs of at least
    SIZED_SAMPLES samples, where the time saved is worth it and few shapes occur; diagnoses and the
    test suite, with many shapes and short runs, share one kernel per force count.
    """
    key = (n_el, sizes)
    with _KERNELS_LOCK:
        if key not in _KERNELS:
            _KERNELS[key] = _make_loop(n_el, *(sizes or (-1, -1)))
        return _KERNELS[key]


def _make_loop(n_el: int, fixed_n: int, fixed_nc: int):
    """The kernel for ``n_el`` force elements, and for ``fixed_n`` plant and ``fixed_nc`` controller
    states if these are not negative (compiled once per key, cached on disk): with these counts
    constants of the compiled code the force loops fold away and the state loops unroll (measured
    on the sample stage: docs/commands.md, Speed).

    The kernel ``loop(phi, gamma, C, x0, kinds, ...)`` runs the loop described in the module
    docstring, fills ``u_out`` and ``y_out`` and returns the final state. ``phi`` .. ``col_pow`` are
    the closed-form coefficients of :class:`nlsid.simulate.propagation.Propagation` (their first
    axis is the number of sub-steps + 1).
    """

    def loop(phi, gamma, C, x0, kinds, params, row_pow, row_gamma, coupling, col_pow, h, delay, closed, Ac, Bc,
             Cc, Dc, r, ff, u_in, process, y_noise, in_kind, in_params, out_kind, out_params, p_bias, lag, c_x, c_p,
             c_f, u_out, y_out):
        substeps = row_pow.shape[0] - 1
        n = fixed_n if fixed_n >= 0 else phi.shape[0]
        nc = fixed_nc if fixed_nc >= 0 else Ac.shape[0]
        x = x0.copy()
        xn = np.empty(n)
        xc = np.zeros(nc)
        xcn = np.empty(nc)
        state = np.zeros(n_el)
        ends = np.zeros(n_el)  # each element's free value at the end of the last sub-step
        f = np.zeros((substeps, n_el))  # the forces of the sub-steps of this sample (of the last one before)
        gains = np.empty(n_el)
        for e in range(n_el):
            gains[e] = coupling[0, e, e]
        derived = _derived(kinds, params, h, gains)
        buf = np.zeros(max(delay, 1))
        p = 0.0  # the input block's output (also its memory); the plant input is p + p_bias
        y_m = 0.0  # plant output through the output block (also its memory)
        carried = 0.0  # with a lagging output: the output read in the previous sample
        for i in range(n):
            carried += C[i] * x[i]
        for k in range(y_out.shape[0]):
            if closed:  # the output read does not depend on this sample's input (lagging, or at t_k with D = 0)
                y_now = carried
                if not lag:
                    y_now = 0.0
                    for i in range(n):
                        y_now += C[i] * x[i]
                y_m = block(out_kind, out_params, y_now, y_m)
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
                xc, xcn = xcn, xc
            else:
                u = u_in[k]
            u_out[k] = u
            if delay > 0:
                slot = k % delay
                command = buf[slot]
                buf[slot] = u
            else:
                command = u
            p = block(in_kind, in_params, command + process[k], p)
            pp = p + p_bias
            for j in range(substeps if n_el else 0):
                for e in range(n_el):
                    s_free = row_gamma[j + 1, e] * pp
                    for i in range(n):
                        s_free += row_pow[j + 1, e, i] * x[i]
                    for i in range(j + 1):
                        for e2 in range(n_el if i < j else e):
                            s_free -= coupling[j - i, e, e2] * f[i, e2]
                    s_now = 0.0
                    if kinds[e] in forces.START_KINDS:  # the only laws that read the start value
                        if j:  # the end of the previous sub-step: its free value less its forces from e on
                            s_now = ends[e]
                            for e2 in range(e, n_el):
                                s_now -= coupling[0, e, e2] * f[j - 1, e2]
                        else:  # the start of the sample (Gamma_0 = 0: no wait for p)
                            for i in range(n):
                                s_now += row_pow[0, e, i] * x[i]
                    ends[e] = s_free
                    previous = f[j - 1 if j else substeps - 1, e]
                    # scalars, not array rows: an array passed to the inlined law costs two atomic
                    # reference-count updates each way per call (11 % of the kernel's time)
                    pe = (params[e, 0], params[e, 1], params[e, 2], params[e, 3], params[e, 4], params[e, 5],
                          params[e, 6], params[e, 7], params[e, 8])
                    de = (derived[e, 0], derived[e, 1], derived[e, 2], derived[e, 3], derived[e, 4], derived[e, 5])
                    f[j, e], state[e] = force(kinds[e], pe, de, state[e], previous, s_free, s_now, gains[e], h)
            if lag or not closed:  # the output at t_k + phi Ts (phi = 0 at t_k, else the timing's fraction)
                y_now = c_p * pp
                for i in range(n):
                    y_now += c_x[i] * x[i]
                for j in range(c_f.shape[0] if n_el else 0):
                    for e in range(n_el):
                        y_now -= c_f[j, e] * f[j, e]
                if lag:
                    y_now, carried = carried, y_now
                if not closed:
                    y_m = block(out_kind, out_params, y_now, y_m)
            y_out[k] = y_m + y_noise[k]
            for i in range(n):
                acc = gamma[i] * pp
                for j in range(n):
                    acc += phi[i, j] * x[j]
                for j in range(substeps if n_el else 0):
                    for e in range(n_el):
                        acc -= col_pow[j, e, i] * f[j, e]
                xn[i] = acc
            x, xn = xn, x
        return x

    # A name per key: numba names the compiled code, and the environment holding its constants, after
    # the function's qualified name and a per-process counter, so two variants compiled first in two
    # processes would share both names when a third loads them from the disk cache, and the second
    # would be handed the first one's constants. With the key in the name they cannot meet (and each
    # variant has its own cache index).
    loop.__qualname__ = f"{loop.__qualname__}_{n_el}_{fixed_n}_{fixed_nc}".replace("-", "m")
    return njit(cache=True, fastmath={"contract"}, nogil=True)(loop)
