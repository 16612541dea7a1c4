"""A closed loop's record that starts in motion (nlsid.simulate.loop_state).

The truth is the EMPS stand-in (tests/generators/emps_cases.py: the axis solved exactly between
samples with stick events, its drive's two-tap velocity estimate, a quantised encoder), run from
rest and cut where the axis moves at a constant reference speed: at the cut the axis moves, the
drive's velocity estimate holds the two previous encoder readings, and nothing of this is in the
record. nlsid's model is the same axis written as its drive computes it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from generators import emps_cases as E
from nlsid.io import model_config as mc
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate.loop_state import estimate, loop_excitation
from nlsid.simulate.runs import simulate_run

AXIS = {"model": {"type": "mass_spring_damper", "mass": E.MASS, "damping": E.VISCOUS, "gain": E.GAIN,
                  "force_offset": -E.OFFSET, "nonlinearities": [{"type": "coulomb", "fc": E.COULOMB}]},
        "closed_loop": {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                                       "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"}}}


def cut_in_motion(profile, coulomb=E.COULOMB, offset=E.OFFSET, encoder=E.ENCODER):
    """(record cut in motion, the cut index, the measured (u, y) before the cut)."""
    r = E.move_profile(*profile)
    u, y = E.closed_loop(r, coulomb=coulomb, offset=offset, encoder=encoder)
    speed = np.abs(np.gradient(r) * E.FS)
    first = int(np.argmax(speed > 0.99 * speed.max()))  # the first move at its top speed
    k0 = first + 30
    return Run("moving", E.FS, "arbitrary", u[k0:], y=y[k0:], r=r[k0:]), k0, (u[:k0], y[:k0])


def model(data):
    config = mc.SimulateConfig.model_validate(data)
    return from_config.model(config), from_config.closed_loop(config)


def rel_rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def test_the_drive_memory_and_the_motion_are_recovered_from_the_first_samples():
    run, k0, (u_before, y_before) = cut_in_motion(E.ESTIMATION_MOVES)
    plant, loop = model(AXIS)
    state = estimate(plant, loop, loop_excitation(run), None)
    assert state is not None
    # the two-tap estimate's memory is the encoder's two readings before the cut: they are exact
    # numbers of the truth (no quantisation error on them), up to the fit's noise (the encoder's
    # 5e-8 m steps in y and the differentiated steps in u)
    assert state.controller == pytest.approx([y_before[-1], y_before[-2]], abs=5 * E.ENCODER)
    # position and velocity at the cut: the truth's, replayed from the commands before it
    p = v = 0.0
    for command in u_before:
        p, v = E._advance(p, v, E.GAIN * command, 1 / E.FS, E.MASS, E.VISCOUS, E.COULOMB, E.OFFSET)
    assert state.x0[1] == pytest.approx(v, rel=0.002)
    assert state.x0[0] == pytest.approx(p, abs=10 * E.ENCODER)


def test_the_record_simulated_from_its_start_matches_the_measured_command():
    run, _, _ = cut_in_motion(E.ESTIMATION_MOVES)
    plant, loop = model(AXIS)
    excitation = loop_excitation(run)
    moving = simulate_run(plant, loop, excitation, None, steady=True)
    rest = simulate_run(plant, loop, dataclasses.replace(excitation, y=None, command=None), None, steady=True)
    # the only model error left is the encoder's quantisation the truth's drive reads: its steps
    # of 5e-8 m differentiated by the two-tap estimate (x kv fs / 2) give about 6 mV rms on a
    # command of 0.9 V rms; from rest the loop's start-up errs by volts in the first samples
    assert rel_rms(moving.u, run.u) < 0.01
    assert rel_rms(rest.u, run.u) > 1.0
    assert rel_rms(moving.y, run.y) < 1e-5


def test_without_friction_the_loop_state_is_exact():
    """A linear loop (no Coulomb friction nor offset, an encoder of 1e-15 m): the least-squares
    start is exact, so the simulated command matches to rounding."""
    run, _, (_, y_before) = cut_in_motion(E.VALIDATION_MOVES, coulomb=0.0, offset=0.0, encoder=1e-15)
    linear = {**AXIS, "model": {**AXIS["model"], "force_offset": 0.0, "nonlinearities": []}}
    plant, loop = model(linear)
    out = simulate_run(plant, loop, loop_excitation(run), None, steady=True)
    assert np.max(np.abs(out.u - run.u)) < 1e-6 * np.max(np.abs(run.u))
    state = estimate(plant, loop, loop_excitation(run), None)
    assert state.controller == pytest.approx([y_before[-1], y_before[-2]], rel=1e-9)
