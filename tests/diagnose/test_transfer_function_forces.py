"""Stribeck friction and end stops fed back around a transfer function a user fitted
(stribeck_feedback, end_stops_feedback), on records of tests/generators/effect_cases.py (random-odd
multisines at two levels, a sensor offset and coloured noise at -50 dB of the output).

The truths are the mass-spring-damper of effect_cases (m = 1 kg, c = 20 N s/m, k = 4e4 N/m,
gain 1e4 N per unit of u) with

- Stribeck friction fc = 1500 N, fs = 3000 N, vs = 5 m/s (break-away twice the sliding force),
  written in tests/generators/independent_friction.py (RK4, the instants the mass stops located by
  bisection; checked here by halving the step: 16 against 32 steps per sample);
- end stops at +0.5 m and -0.6 m, 4e5 N/m with a 200 N s/m damper, written in
  tests/generators/independent_forces.py (RK4 with the contact changes located, halved likewise);

and the user's model a second-order transfer function fitted here to the measured BLA (the mean
over the runs of Y/U at the excited lines of the last period; Sanathanan-Koerner iterations, not
nlsid's fit), biased by the effect as a user's fit would be: in z (b0 = 0, as ``nlsid fit
--domain z`` writes one) for the friction and the linear plant, in s for the stops (whose z fit
has a zero in the band: ``_fitted_continuous``). In units of u the truth is fc = 0.15, fs = 0.3;
ks = 40, cs = 0.02 per metre and metre per second.

Measured when written: Stribeck named, fc and fs within 0.1 %, 0.2 dB above the floor (the
Coulomb feedback 21.5 dB above it); end stops named, ks within 0.2 %, the edges as recorded
(edge + output offset: the force offset the nuisances fit moves the edges and the output offset
together) within 0.1 % of 0.502 and -0.598, 0.8 dB above the floor (the cubic feedback 43 dB
above it); the linear plant from its fitted transfer function: nothing beyond noise. And the
nuisances around a transfer function: a force offset is fitted only where the forces can tell it
from a sensor offset (nlsid/diagnose/nuisances.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from generators import effect_cases as cases
from generators import independent_forces, independent_friction
from nlsid.diagnose.diagnosis import diagnose

STRIBECK = {"type": "stribeck", "fc": 1500.0, "fs": 3000.0, "vs": 5.0}
STOPS = {"type": "end_stop", "upper": 0.5, "lower": -0.6, "stiffness": 4.0e5, "damping": 200.0}
NEW = ("stribeck_feedback", "lugre_feedback", "end_stops_feedback")


def _checked(simulate):
    """The response of ``simulate(U, substeps)`` at 32 steps per sample, its Runge-Kutta error
    checked against 16 (far below the noise)."""
    def response(U: np.ndarray) -> np.ndarray:
        fine, finer = simulate(U, 16), simulate(U, 32)
        assert np.max(np.abs(fine - finer)) < 1e-3 * cases.NOISE
        return finer
    return response


def _stribeck(U: np.ndarray, substeps: int) -> np.ndarray:
    truth = {**cases.MSD["model"], "nonlinearities": [STRIBECK]}
    return independent_friction.stribeck_response(truth, U, cases.FS, substeps)


def _stops(U: np.ndarray, substeps: int) -> np.ndarray:
    truth = {**cases.MSD["model"], "nonlinearities": [STOPS]}
    return independent_forces.end_stop_response(truth, U, cases.FS, substeps)


def _bla(runs) -> tuple[np.ndarray, np.ndarray]:
    """The excited lines and the measured BLA there: the mean of Y/U over the runs (last period)."""
    bins = runs[0].excited_bins
    return bins, np.mean([np.fft.fft(r.y[-r.period:])[bins] / np.fft.fft(r.u[-r.period:])[bins] for r in runs], axis=0)


def _sanathanan_koerner(G: np.ndarray, columns, rhs, den) -> np.ndarray:
    """theta of G den(theta) = num(theta) by Sanathanan-Koerner iterations: the equation error
    weighted by 1 / |den| of the previous iterate (Levy's unweighted start), real and imaginary
    parts stacked; ten iterations, near the output-error fit's fixed point. ``columns`` (lines x
    parameters) and ``rhs`` are the linear equation's, ``den(theta)`` the denominator at the lines."""
    weight = np.ones(G.size)
    for _ in range(10):
        A, b = columns * weight[:, None], rhs * weight
        theta = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.concatenate([b.real, b.imag]), rcond=None)[0]
        weight = 1.0 / np.abs(den(theta))
    return theta


def _fitted_discrete(runs) -> dict:
    """(b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2) fitted to the measured BLA (a sampled record's
    FRF: that of the plant's ZOH equivalent), strictly proper as a force-to-position mechanics'
    ZOH equivalent is, as ``nlsid fit --domain z`` writes a model."""
    bins, G = _bla(runs)
    q = np.exp(-2j * np.pi * bins / cases.N)  # z^-1 at the lines
    a1, a2, b1, b2 = _sanathanan_koerner(G, np.column_stack([G * q, G * q**2, -q, -q**2]), -G,
                                         lambda t: 1 + t[0] * q + t[1] * q**2)
    return {"model": {"type": "transfer_function", "domain": "discrete", "num": [0.0, float(b1), float(b2)],
                      "den": [1.0, float(a1), float(a2)]}}


def _fitted_continuous(runs) -> dict:
    """b / (s^2 + a1 s + a0) fitted to the measured BLA (biased besides by the sampling: the FRF is
    the ZOH equivalent's). On the end stops' record a discrete 2/2 fit has a zero at 180 Hz (its
    continuous equivalent relative degree 1: the force then acts over whole samples, and the
    refinement stops short), so that test starts from this form."""
    bins, G = _bla(runs)
    s = 2j * np.pi * bins * cases.FS / cases.N
    a1, a0, b = _sanathanan_koerner(G, np.column_stack([G * s, G, -np.ones_like(G)]), -G * s**2,
                                    lambda t: s**2 + t[0] * s + t[1])
    return {"model": {"type": "transfer_function", "num": [float(b)], "den": [1.0, float(a1), float(a0)]}}


def test_stribeck_friction_is_fed_back_around_a_fitted_transfer_function_not_coulomb():
    runs = cases.recording(41, _checked(_stribeck))
    result = diagnose(_fitted_discrete(runs), "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "stribeck_feedback", result.headline()
    values = result.winner.estimate.values
    assert values["fc"] == pytest.approx(STRIBECK["fc"] / cases.GAIN, rel=0.10), values
    assert values["fs"] == pytest.approx(STRIBECK["fs"] / cases.GAIN, rel=0.10), values
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_end_stops_are_fed_back_around_a_fitted_transfer_function_at_their_positions():
    runs = cases.recording(45, _checked(_stops))
    result = diagnose(_fitted_continuous(runs), "model.yaml", runs, "recording.h5")
    assert result.verdict.winner == "end_stops_feedback", result.headline()
    values = result.winner.estimate.values
    assert values["upper_seen"] == pytest.approx(STOPS["upper"] + cases.OFFSET, rel=0.10), values
    assert values["lower_seen"] == pytest.approx(STOPS["lower"] + cases.OFFSET, rel=0.10), values
    assert values["ks"] == pytest.approx(STOPS["stiffness"] / cases.GAIN, rel=0.10), values
    assert abs(result.final_score().above_floor_db) < 3.0, result.headline()


def test_a_linear_plant_from_its_fitted_transfer_function_gets_no_force_fed_back():
    runs = cases.recording(46, cases.linear)
    result = diagnose(_fitted_discrete(runs), "model.yaml", runs, "recording.h5")
    assert result.verdict.status == "no_discrepancy", result.headline()
    assert result.verdict.winner is None and not set(NEW) & set(result.verdict.explaining), result.verdict


@pytest.mark.parametrize("num, den, force, seen", [
    ([1e4], [1.0, 20.0, 4e4], {"type": "coulomb", "fc": 0.01}, False),                # a sprung mass
    ([1e4, 0.0], [1.0, 20.0, 4e4, 0.0], {"type": "coulomb", "fc": 0.01}, False),      # its velocity reading, G / s
    ([1e4], [1.0, 20.0, 0.0], {"type": "coulomb", "fc": 0.01}, True),                 # a free mass
    ([1e4], [1.0, 20.0, 4e4], {"type": "end_stop", "upper": 0.5, "stiffness": 40.0}, True),  # the edges' direction
])
def test_a_force_offset_is_fitted_around_a_transfer_function_only_where_the_forces_can_see_it(num, den, force, seen):
    """A constant force f0 on a linear part with a static gain G(0) moves the motion to the rest
    position f0 G(0), which a sensor offset gives as well where the forces read the velocity alone:
    then only the output offset is fitted (fitted both, the fit took a force offset of 0.12 with
    fc_pos and fc_neg 0.42 and 0.18 on LuGre data of fc = 0.3, a reading of unequal sides the data
    do not hold)."""
    from nlsid.diagnose.nuisances import free_nuisances
    from nlsid.diagnose.simulation import ModelRunner

    data = {"model": {"type": "nonlinear_feedback", "linear": {"type": "transfer_function", "num": num, "den": den},
                      "output": "velocity" if den[-1] == 0.0 and num[-1] == 0.0 else "position",
                      "nonlinearities": [force]}}
    free = free_nuisances(ModelRunner.from_data(data, "model.yaml"), cases.recording(47, cases.linear))
    assert ("model.force_offset" in free) is seen, free
    assert "model.output_offset" in free
