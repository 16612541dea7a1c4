"""Nonlinear forces acting on a mass of a mechanical plant, and their update over one sub-step.

The laws are implemented in :func:`nlsid.simulate.kernels.force` (kept in the kernel's module so
that numba's on-disk cache, which watches only the compiled function's own file, stays current).

Each force is a feedback from the mass's velocity v (friction) or position p (cubic or polynomial
stiffness) to a force F that opposes the actuator (``m v' = ... - F``). Over a sub-step of length
h the linear plant is propagated exactly with F held constant (ZOH), so the mass's velocity and
position at the end of the sub-step are

    v+ = v_free - g_v F,      p+ = p_free - g_p F,

with v_free, p_free the values without F and g_v = row_v . Gamma_F (about h/m), g_p = row_p . Gamma_F
(about h^2 / 2m) the effect of a unit force held over the sub-step. Each law below chooses F.

The friction laws take their levels per direction (real axes differ by 5-20 %): fc, fv (Coulomb),
fc, fs, fv (Stribeck) and fc, fs, sigma2 (LuGre) have a value for v > 0 (``fc_pos``, ...) and
one for v < 0 (``fc_neg``, ...), magnitudes all; a symmetric config (``fc``, ...) is the case of
equal sides, encoded to the same parameter vector and run by the same code. Below, fc+ and fc-
stand for the two sides of fc, and "the side" for the direction of the motion.

* ``coulomb`` F = fc+ + fv+ v for v > 0, -fc- + fv- v for v < 0, and any F in [-fc-, fc+] at
  v = 0 (symmetric: F = fc sign(v) + fv v, sign(0) the set [-1, 1]).
* ``stribeck`` F = (fc + (fs - fc) e^{-|v/vs|^delta}) sign(v) + fv v with fc, fs, fv those of the
  side (vs and delta common), and any F in [-fs-, fs+] at v = 0 (break-away forces fs+, fs-).

  Both are stepped with the force held over a sub-step equal to the law's mean over the
  sub-step's velocity path, taken as linear (a velocity ramp; the other forces on the mass held):

  - from rest (Moreau's time stepping, no chattering around v = 0): the mass sticks while
    -g_v fs- <= v_free <= g_v fs+ (fc for Coulomb; v+ = 0, F = v_free / g_v); otherwise it slides
    on the side s = sign(v_free), F the mean of the law over the speeds 0 .. w, w = |v+| the root
    of w = |v_free| - g_v |F(w)| (closed form for Coulomb; Newton's method with bisection for
    Stribeck, bracketed in (0, |v_free|) and robust where the curve is steeper than 1/g_v);
  - sliding on the side of v (the start velocity) and still on it at the end: the mean over the
    speeds |v| .. w, the same equation (for Coulomb the trapezoidal rule in the viscous term);
  - reaching v = 0 in the sub-step: the mass decelerates under the mean force over |v| .. 0,
    stops at the fraction tau of the sub-step where that linear velocity reaches zero, and the
    remaining (1 - tau) h is a step from rest (stick, or slip to either side); the force held is
    the time mean of the two parts.

  The Stribeck mean over a speed ramp uses the integral of e^{-(v/vs)^delta} (erf for delta = 2,
  otherwise vs Gamma(1 + 1/delta) P(1/delta, (w/vs)^delta), the regularised incomplete gamma
  function). The step is second order in h, at reversals through zero and at
  break-away too (tests/simulate/test_simulate_friction.py: 4x finer sub-steps divide the error of an
  event-located reference by about 16; Moreau's plain step, held at the end side's level over the
  whole sub-step, was first order at a reversal, 300x the error at one sub-step), and exact while
  sticking.
* ``lugre`` (Canudas de Wit, Olsson, Astrom, Lischinsky 1995): bristle state z,

      z' = v - lambda(v) z,   lambda(v) = sigma0 |v| / s(v),   s(v) = fc + (fs - fc) e^{-(v/vs)^2},
      F = sigma0 z + sigma1 z' + sigma2 v,

  with fc, fs and sigma2 those of the side of v. The law stays continuous at v = 0 with unequal
  sides (lambda -> 0 and sigma2 v -> 0 from both), and the Newton solve below works on one side
  of zero at a time, so the side's levels are fixed before it starts.

  Step over a sub-step with the velocity held at the weighted value vv = v + theta (v+ - v) and
  the rate lambda = lambda(vv): z' = vv - lambda z is linear, so exactly (x = lambda h)

      z+ = e^{-x} z + h m0 vv,   mean of z over the sub-step = m0 z + h r vv,
      m0 = (1 - e^{-x}) / x,     r = (1 - m0) / x,

  and the force held over the sub-step is F = sigma0 zF + sigma1 (z+ - z) / h + sigma2 vv with
  zF = (2 - 2 theta) mean(z) + (2 theta - 1) z+. With theta = 1/2 this is the sub-step mean of
  the force for a velocity ramp from v to v+ up to O(h^2): second order (tests: error ratio 16 per
  4x finer h; the closed-loop stage of configs/model_stage_lugre.yaml at 1 sub-step has the error
  the former first-order backward Euler step had at 4). The sliding relaxation is exact for any
  x (no stiffness limit from lambda). The bristle spring and damper are stiff when
  S = g_v (sigma0 h + sigma1 + sigma2) is large (the mode is not resolved by h); theta = 1/2 then
  rings at the Nyquist frequency (A- but not L-stable), so theta = max(1/2, 1 - 1/(2 S)): 1/2
  while S <= 1, tending to 1 (backward Euler in the spring and damper, L-stable) as S grows,
  continuous in the parameters (S with the larger of the two sides' sigma2). With
  v+ = v_free - g_v F the step is one equation in vv, solved by Newton's method on the side of
  zero where the root lies (with that side's levels), from the prediction
  v_free - g_v F_prev, until the step is below LUGRE_TOLERANCE (|vv| + vs) = 1e-5 (|vv| + vs);
  F and z+ are then carried to the last iterate to first order, which leaves an error O(step^2),
  about 1e-10 relative (the outputs move by 3e-13 against a 1e-10 step; on the sample stage
  1.07-1.10 evaluations per step instead of 1.19-1.23 under a sine, 1.40-1.51 instead of
  1.77-1.94 under a multisine). The rate is taken at vv, not at
  v_free: at standstill v_free - v+ = g_v F is not small, and a rate at v_free would let the
  bristles relax, an artificial creep of about g_v F^2 / s; at rest vv = 0 and z is held exactly.
* ``cubic_stiffness`` F = k3 p^3, evaluated at the sub-step midpoint estimate (p + p_free) / 2:
  second order for this smooth force (the Duffing oscillator of the book's Exercise 79, Eq. 5-12,
  is a unit mass with damping 1, stiffness -10 and k3 = 100).
* ``quadratic_damping`` F = c2 v |v| and ``cubic_damping`` F = c3 v^3 (c2, c3 > 0: a drag that
  grows faster than the viscous one, as a fluid's at high Reynolds number), one law
  F = c2 m |m| + c3 m^3 of the sub-step's mean velocity m = (v + v+) / 2. The force moves v+ by
  g_v F, a change of O(h) in m, so m is solved for with the force (the implicit midpoint rule:
  m = (v + v_free) / 2 - (g_v / 2) F(m), Newton's method, monotone for c2, c3 >= 0): second order
  in h. (The cubic spring's explicit midpoint, with v_free for v+, would be first order here: a
  force changes the velocity it reads by O(h) within the sub-step, the position only by O(h^2).)
* ``polynomial_stiffness`` F = k2 p^2 + k3 p^3 + ... + k10 p^10 (Horner), at the same midpoint
  estimate and so second order as well; with k3 alone it is ``cubic_stiffness``.
* ``bouc_wen`` (Bouc 1967, Wen 1976): a hysteretic restoring force F = k z with the internal state

      z' = A v - beta |v| |z|^(n-1) z - gamma v |z|^n,

  z in position units. The classical force alpha k0 x + (1 - alpha) k0 z is this law with
  k = (1 - alpha) k0 and the elastic part alpha k0 x the model's own stiffness (a linear spring
  the template or the transfer function already has: a second one would be the same parameter
  twice). A and k are one parameter for n = 1 (z -> c z maps (A, k) to (c A, k / c)), so a
  diagnosis holds A = 1. On a monotone stroke z tends to the bound (A / (beta + gamma))^(1/n),
  the force to k times it; the loop is bounded and dissipative for -beta < gamma <= beta
  (Ikhouane, Manosa and Rodellar 2007, J. Sound Vib. 302, the class of beta + gamma > 0,
  beta - gamma >= 0), which the config requires, and n >= 1 (|z|^(n-1) finite at z = 0).

  Step: the velocity is taken as linear over the sub-step, from v to v+ = v_free - g_v F, z is
  integrated along it by Heun's method (second order) on m equal parts, m the smallest count
  that keeps the relaxation rate (beta + |gamma|) n |z|^(n-1) |v| times the part below
  BOUC_WEN_PART (stability and accuracy of the explicit step however fast z saturates; at most
  BOUC_WEN_PARTS), and the force held is k times the trapezoidal mean of z over the parts. F
  enters v+, so the step is done twice, from F of the previous sub-step and then from the first
  result: the velocity's error after the second pass is (g_v dF/dv)^2 ~ (k h^2 / 4 m)^2 of the
  first guess's, far below the scheme's O(h^2). Second order in h, as the cubic spring.
* ``end_stop``: a one-sided spring and damper beyond ``upper`` and below ``lower`` (each optional),
  F = max(0, k (p - upper) + c v) while p > upper, min(0, k (p - lower) + c v) while p < lower, 0
  between: piecewise affine in (p, v), and never pulling (a contact only pushes, so the damper's
  force is cut at zero as the mass leaves the stop). Contacts are stiff (k h^2 / m need not be
  small), so the force is implicit. The free path over the sub-step, from p to p_free, is taken
  as linear: the stop is touched over the share phi of the sub-step where it lies beyond the edge
  (phi = 1 inside a contact; where the edge is crossed, the crossing's instant on that line), at
  the mean depth D of that part, and the force F_c of that part is the spring and damper at the
  depth and velocity it lowers itself (the implicit midpoint rule, A-stable for any k and c):

      F_c = (k D + c (p_free - p) / h) / (1 + phi g_p (k / 2 + c / h)),   F = phi F_c,

  for the upper stop (mirror image for the lower), cut at zero and at the force that brings the
  mean depth back to zero (the damper cannot pull the mass back across the edge). Second order
  in h inside and across contacts (tests/simulate/test_simulate_hysteresis_contact.py: 4x finer
  sub-steps divide the error of an event-located reference by about 15).

Kinds and parameter vectors (the numba kernel's encoding): the sided values are those for v > 0,
followed by the offsets d = (value for v < 0) - (value for v > 0) in the same order, so that a
symmetric law has zero offsets (and a vector of the symmetric layout, padded with zeros, is the
symmetric law). The kernel takes the v < 0 side as value + d, exact while the two sides are within
a factor 2 of each other (Sterbenz's lemma), within about one rounding otherwise.

    0 coulomb  [fc, fv, dfc, dfv]     1 stribeck [fc, fs, vs, delta, fv, dfc, dfs, dfv]
    2 lugre    [sigma0, sigma1, sigma2, fc, fs, vs, dsigma2, dfc, dfs]     3 cubic_stiffness [k3]
    4 polynomial_stiffness [k2, k3, ..., k10]     5 quadratic_damping [c2, 0], cubic_damping [0, c3]
    6 bouc_wen [k, A, beta, gamma, n]     7 end_stop [upper, lower, k, c, has_upper, has_lower]
"""

from __future__ import annotations

import numpy as np

# The kernels (nlsid/simulate/kernels.py) compile these constants in, and numba's disk cache is
# keyed on kernels.py alone: after editing a value here, touch kernels.py (or delete its
# __pycache__/*.nbi) or the old value stays in force. An installed package is unaffected.
COULOMB, STRIBECK, LUGRE, CUBIC, POLYNOMIAL = 0, 1, 2, 3, 4
DAMPING = 5  # quadratic and cubic damping, one law
BOUC_WEN, END_STOP = 6, 7
BOUC_WEN_PART = 0.5   # Bouc-Wen: the relaxation rate times a part of the sub-step at most (Heun's step)
BOUC_WEN_PARTS = 64   # and at most this many parts per sub-step
MAX_PARAMS = 9
MAX_ITERATIONS = 60   # Newton iterations (Stribeck, LuGre) at most, stopping
TOLERANCE = 1e-10     # when the velocity changes by less than TOLERANCE (|v| + vs)
LUGRE_TOLERANCE = 1e-5  # LuGre: its step is carried to first order, an error O(step^2) ~ TOLERANCE
POSITION_KINDS = (CUBIC, POLYNOMIAL, END_STOP)
START_KINDS = (COULOMB, STRIBECK, LUGRE, CUBIC, POLYNOMIAL, DAMPING, BOUC_WEN, END_STOP)  # laws that read their signal at the start of the sub-step too


def _pos(config, name: str) -> float:
    """The value of a sided quantity for v > 0."""
    return config.sides(name)[0]


def _offsets(config, *names: str) -> list[float]:
    """(value for v < 0) - (value for v > 0) of the sided quantities ``names``: 0 for a symmetric
    config and for an asymmetric one with equal sides."""
    return [neg - pos for pos, neg in map(config.sides, names)]


def encode(config) -> tuple[int, np.ndarray]:
    """(kind, parameter vector padded to MAX_PARAMS) of a force config (layout in the module
    docstring: a symmetric config and the asymmetric one with equal sides give the same vector)."""
    kind, values = {
        "coulomb": (COULOMB, lambda c: [_pos(c, "fc"), _pos(c, "fv"), *_offsets(c, "fc", "fv")]),
        "stribeck": (STRIBECK, lambda c: [_pos(c, "fc"), _pos(c, "fs"), c.vs, c.delta, _pos(c, "fv"),
                                          *_offsets(c, "fc", "fs", "fv")]),
        "lugre": (LUGRE, lambda c: [c.sigma0, c.sigma1, _pos(c, "sigma2"), _pos(c, "fc"), _pos(c, "fs"), c.vs,
                                    *_offsets(c, "sigma2", "fc", "fs")]),
        "cubic_stiffness": (CUBIC, lambda c: [c.k3]),
        "polynomial_stiffness": (POLYNOMIAL, lambda c: c.coefficients()),
        "quadratic_damping": (DAMPING, lambda c: [c.c2, 0.0]),
        "cubic_damping": (DAMPING, lambda c: [0.0, c.c3]),
        "bouc_wen": (BOUC_WEN, lambda c: [c.k, c.A, c.beta, c.gamma, c.n]),
        "end_stop": (END_STOP, lambda c: [0.0 if c.upper is None else c.upper, 0.0 if c.lower is None else c.lower,
                                          c.stiffness, c.damping, float(c.upper is not None),
                                          float(c.lower is not None)]),
    }[config.type]
    params = np.zeros(MAX_PARAMS)
    vals = values(config)
    params[: len(vals)] = vals
    return kind, params
