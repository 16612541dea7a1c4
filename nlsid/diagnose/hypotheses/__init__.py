"""The library of causes: each a named physical or structural hypothesis with its signature, a first
estimate of its parameters from the residual, and its model extension.

Every hypothesis h adds a block with parameters theta to the user's model. For a small effect the
residual of the nominal model is, to first order in the effect (exactly for an input or output
block on a linear model in open loop),

    e(t) = y(t) - y_model(t) ~ S_h[ d_h(theta; signals of the model) ](t) + noise,

where d_h is the missing signal (a force at the driven mass, an input error at the actuator, an
output error) computed from the model's internal signals, and S_h the model's response to it at the
measured output (:meth:`~nlsid.diagnose.simulation.ModelRunner.response`: G d in open loop, the
loop's sensitivity in closed loop). This is the residual "against the model's internal signals"
made quantitative: parameters that enter linearly are the least-squares regression of e on the
responses (over the mean steady-state periods of the estimation runs), one shape parameter
is chosen by the same residual sum of squares: a threshold by a bounded scalar search, a Stribeck
velocity on a grid (:func:`_estimate_stribeck`). The standard errors are those of ordinary least squares, ``s^2 (X^T X)^-1``.

Library (signature = what the evidence shows when it is the cause; extension = the config keys):

=================== ========================================= ====================================
name                signature                                 extension (parameters)
=================== ========================================= ====================================
coulomb             odd distortion; BLA gain rises with       ``nonlinearities: coulomb`` (fc)
                    level; residual force jumps at v = 0
stribeck            as coulomb, with a break-away peak at     ``nonlinearities: stribeck``
                    low velocity                              (fs, fc, vs; delta = 2; fs refined
                                                              as peak = fs - fc > 0)
lugre               as stribeck, with presliding: a stiff     ``nonlinearities: lugre`` (sigma0,
                    force after each velocity reversal        fc, fs, vs; sigma1 = sigma2 = 0;
                                                              fs refined as peak)
coulomb_feedback    as coulomb, for a transfer function       ``nonlinear_feedback`` around the
                    model (its output read as position or     model (or model / s, ``output:
                    velocity, whichever explains more)        velocity``) with ``coulomb`` (fc,
                                                              the linear coefficients)
stribeck_feedback   as stribeck, for a transfer function      ``nonlinear_feedback`` with
                    model (from the coulomb_feedback fit)     ``stribeck`` (fs, fc, vs; fs refined
                                                              as peak; the linear coefficients)
lugre_feedback      as lugre, for a transfer function model   ``nonlinear_feedback`` with ``lugre``
                    (from the stribeck_feedback fit)          (sigma0, fc, fs, vs; the linear
                                                              coefficients)
quadratic_damping   odd distortion; damping grows with        ``nonlinearities: quadratic_damping``
                    level; residual like the response to      (c2), or fed back around a transfer
                    the force -v abs(v)                       function as coulomb_feedback
cubic_damping       as quadratic_damping, force -v^3          ``nonlinearities: cubic_damping``
                                                              (c3), or fed back likewise
cubic_stiffness     odd distortion; the resonance moves with  ``nonlinearities: cubic_stiffness``
                    level; residual force cubic in position   (k3; > 0 hardening, < 0 softening)
hysteresis          odd distortion; the resonance and the     ``nonlinearities: bouc_wen`` (k,
                    damping move with level; residual force   beta, gamma; A = n = 1), the
                    depends on the path since the last        elastic part the model's own
                    reversal (a loop growing with the stroke) stiffness
hysteresis_feedback as hysteresis, for a transfer function    ``nonlinear_feedback`` around the
                    model (its output read as position)       model with ``bouc_wen`` (k, beta,
                                                              gamma, the linear coefficients)
hysteresis_exponent as hysteresis, the force yielding more    ``bouc_wen`` (k, beta, gamma, n;
                    sharply (or smoothly) than n = 1 allows;  n >= 1; A = 1 / z0 held, the state
                    fitted where n = 1 stays above the floor  scaled to tend to 1), from the
                                                              hysteresis or hysteresis_feedback fit
end_stops           distortion at the largest levels only;    ``nonlinearities: end_stop`` (ks,
                    residual force where the position is      cs, upper_stop and/or lower_stop:
                    beyond an edge (contact)                  the keys stiffness, damping,
                                                              upper, lower)
end_stops_feedback  as end_stops, for a transfer function     ``nonlinear_feedback`` with
                    model (its output read as the position)   ``end_stop`` (ks, cs, the edges,
                                                              the linear coefficients; the edges
                                                              as recorded: upper_seen, lower_seen)
cubic_joint         odd distortion around the flexible mode   ``nonlinearities: cubic_stiffness``
                    of a two_mass_stage; residual like the    with ``at: joint`` (k3: k3 (p1 -
                    sensitivity to a cubic spring between     p2)^3 in the coupling, with the
                    the masses                                mechanics)
joint_feedback      as cubic_joint, for a transfer function   the two_mass_stage the transfer
                    from force to the motor's position or     function is (joint.two_mass_of,
                    velocity (a discrete one with its fs)     gain 1) with the cubic joint (k3,
                                                              the mechanics)
modal_joint         odd distortion; one mode of a multi-mode  ``nonlinear_feedback`` around the
                    LTI model (order >= 4) moves with the     model's modal state space (the
                    level (the BLA's modes compared), the     moving mode first) with
                    others stay                               ``cubic_stiffness`` at that mode's
                                                              ``points`` entry (k3: k3 q^3 on
                                                              its modal coordinate q; every
                                                              mode's coefficients refined;
                                                              modal_joint.py)
modal_damping       as modal_joint, the mode's damping        as modal_joint with ``cubic_damping``
                    growing with the level                    (c3: c3 q'^3 on its modal velocity)
cubic_feedback      as cubic_stiffness, for a transfer        ``nonlinear_feedback`` around the
                    function model (continuous or discrete)   model with ``cubic_stiffness`` (k3,
                                                              with the linear coefficients)
polynomial_feedback as cubic_feedback, with even distortion   ``nonlinear_feedback`` with
                    too: an asymmetric spring; fitted only    ``polynomial_stiffness`` (k2, k3,
                    where the cubic fit leaves a score along  the linear coefficients; the
                    -y^2 (starts from the cubic's fit)        force_offset held)
input_saturation    odd distortion; BLA gain falls with       ``input_nonlinearity: saturation``
                    level; residual where abs(u) is large     (limit a: lower = -a, upper = a)
deadzone            odd distortion; BLA gain rises with       ``input_nonlinearity: deadzone``
                    level; residual where abs(u) is small     (half width a: lower = -a, upper = a)
backlash            odd distortion and a phase lag that       ``input_nonlinearity: backlash``
                    shrinks with level                        (width)
actuator_polynomial odd and even distortion; residual like    ``input_nonlinearity: polynomial``
                    the responses to u^2 and u^3 at the       [0, 1, a2, a3] (a2, a3; a
                    plant input (Hammerstein)                 Hammerstein system)
quadratic_output    even distortion                           ``output_nonlinearity: polynomial``
                                                              [0, 1, a2] (a2)
output_saturation   the recorded output flat at a ceiling     ``output_nonlinearity: saturation``
                    or floor (many samples at its extreme     (limit: the flat side's; a side
                    value); not fitted without one            not flat far beyond the range)
missing_resonance   BLA differs from the model around one     the model as a ``zpk`` with the
                    frequency, no distortion                  pole mode ``{frequency: fr, damping:
                                                              zeta}`` and its ``gain`` refined:
                                                              times g wr^2 / (s^2 + 2 zeta wr s +
                                                              wr^2) (fr in Hz, zeta, gain); a
                                                              mass_spring_damper or two_mass_stage
                                                              becomes its transfer function (mode
                                                              in series)
wrong_mechanics     BLA differs around the model's own        ``mass``, ``damping``, ``stiffness``
                    resonance (height, frequency), no         of a mass_spring_damper corrected
                    distortion                                (main: damping)
wrong_dynamics      BLA differs from the model in shape or    a ``transfer_function``'s ``num``
                    gain, no distortion                       and ``den`` corrected (main: the
                                                              largest change of a pole's natural
                                                              frequency, %); the same coefficients
                                                              are refined with every block
coupled_mode        BLA differs by a resonance with an        the model as a ``zpk`` with the
                    anti-resonance below it (a second mass    modes ``{frequency: fa, damping:
                    on the driven one), no distortion         za}`` (zero) and ``{frequency: fr,
                                                              damping: zr}`` (pole): times (wr^2 /
                                                              wa^2) (s^2 + 2 za wa s + wa^2) /
                                                              (s^2 + 2 zr wr s + wr^2) (fr, fa in
                                                              Hz, zr, za; mass ratio (fr/fa)^2 - 1)
wiener_hammerstein  the BLA's shape the same at every level,   ``wiener_hammerstein``: the model's
                    its gain changing; odd and even          poles and zeros split over ``first``
                    distortion                                and ``second``, polynomial f between
                                                              (a1 .. aP, the filters' coefficients)
tank_outflow        even distortion; the BLA's gain and time  ``equations`` (one tank): dx/dt =
                    constants change with the operating       -k1 sqrt(x) + k4 u (k1, k4), from
                    level (a higher level, a slower tank);    the linearisation a 1st-order model
                    a 1st-order LTI model                     is (tank_outflow.py)
cascaded_tanks      as tank_outflow, for an LTI model with    ``equations`` (two tanks, Torricelli
                    two real poles                            outflow, k2 = k1: k1, k3, k4), from
                                                              the linearisation, both pole
                                                              assignments tried
cascaded_tanks_overflow
                    as cascaded_tanks; the response to a      ``equations``: the upper tank capped
                    rising input capped at the largest        at its rim (x1max, the spill share
                    levels (the upper tank spills)            frac into the lower tank, with k1,
                                                              k3, k4; tank_overflow.py)
delay               BLA phase error growing linearly with     ``delay`` (seconds, a real number
                    frequency, gain right, no distortion      of samples)
=================== ========================================= ====================================

Friction is one family of nested laws: Coulomb (fc) in Stribeck (fs = fc) in LuGre (sigma0 to
infinity); the verdict names the richer law only when it is significantly better
(:mod:`nlsid.diagnose.verdict`), and each richer law starts from the simpler one's fit. The
mechanics correction starts at the model's own values and is refined by the fit engine like the
forces. The delay and the missing resonance are linear: they are estimated from the ratio
``G_BLA / G_model`` of the measured and the model's BLA (evidence), the delay from the slope of its
phase (weighted least squares, weights ``2 |G|^2 / var(G)``, the inverse variance of the phase),
the resonance's start by Levy's linearised least squares on ``R(s) (s^2 + a1 s + a0) = b0`` (book
Section 7.2's linear-in-the-parameters weighting idea, here with weights ``1/std(R)``), the coupled
mode by the same on ``R(s) (s^2 + a1 s + a0) = b2 s^2 + b1 s + b0``
(:mod:`~nlsid.diagnose.hypotheses.coupled_mode`, which derives R from the two-mass equations). The
linear hypotheses are one family: the coupled mode (four parameters) is named over a missing
resonance or wrong mechanics (three) only when it is significantly better, and is not fitted when
one of them already reaches the noise floor.
"""

from __future__ import annotations

from nlsid.diagnose.hypotheses import (coupled_mode, delay, feedback, friction, input_blocks, linear_dynamics, mechanics,
                                       output_blocks, resonance, stiffness)
from nlsid.diagnose.hypotheses import tank_outflow, tank_overflow, wiener_hammerstein
from nlsid.diagnose.hypotheses import end_stops, hysteresis, joint, modal_joint
from nlsid.diagnose.hypotheses import actuator_polynomial, friction_feedback, nonlinear_damping, output_saturation
from nlsid.diagnose.hypotheses.base import Context, Estimate, Hypothesis

__all__ = ["LIBRARY", "Context", "Estimate", "Hypothesis", "by_name"]

#: The hypotheses in the order they are tried (a family's simpler members first).
LIBRARY: tuple[Hypothesis, ...] = (friction.HYPOTHESES + friction_feedback.HYPOTHESES + nonlinear_damping.HYPOTHESES
                                   + stiffness.HYPOTHESES + hysteresis.HYPOTHESES + end_stops.HYPOTHESES + joint.HYPOTHESES + modal_joint.HYPOTHESES + feedback.HYPOTHESES
                                   + input_blocks.HYPOTHESES + actuator_polynomial.HYPOTHESES
                                   + output_blocks.HYPOTHESES + output_saturation.HYPOTHESES + wiener_hammerstein.HYPOTHESES + tank_outflow.HYPOTHESES + tank_overflow.HYPOTHESES
                                   + resonance.HYPOTHESES + mechanics.HYPOTHESES
                                   + linear_dynamics.HYPOTHESES
                                   + coupled_mode.HYPOTHESES + delay.HYPOTHESES)


def by_name(name: str) -> Hypothesis:
    return next(h for h in LIBRARY if h.name == name)
