"""Channels of the recording in a closed-loop model: ``closed_loop.excitation_channels`` (an
identification signal the drive adds to its output, which the recorded u includes) and channels a
run lacks (refused, or taken as zero where the model marks them ``absent: zero``).

The measured records come from an EMPS-like axis (tests/generators/emps_cases.py: the drive
u[k] = kp kv (r - y) - kv (y[k] - y[k-2]) fs / 2, the mass with viscous and Coulomb friction and an
offset force solved exactly between samples, stick events located in closed form, a quantised
encoder) whose drive adds a recorded pulse train p to its command: u[k] = C(...)[k] + p[k]. The
axis is re-implemented below with that one addition (:func:`drive`), independently of nlsid's
simulator.

What nlsid cannot see is the encoder: the drive reads y quantised to q = 5e-8 m, the model the
exact position. The quantisation error e (uniform, rms q / sqrt(12), white at this resolution)
enters the drive's output as -(kp kv + kv fs / 2) e[k] + kv fs / 2 e[k-2], of rms
sigma_u = q / sqrt(12) sqrt((kp kv + kv fs / 2)^2 + (kv fs / 2)^2) = 2.9e-3 V; the recorded y
differs from the exact position by e itself. The simulated u and y must match within 1.5 sigma
(the loop feeds part of it back; measured 0.92 sigma_u and 1.08 q / sqrt(12)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from generators import emps_cases as E
from nlsid.io import model_config as mc
from nlsid.io.recording import read_runs, write_recording
from nlsid.io.run import Run
from nlsid.models import from_config
from nlsid.simulate.runs import simulate_run

QUANT = E.ENCODER / math.sqrt(12.0)
SIGMA_U = QUANT * math.hypot(E.KP * E.KV + E.KV * E.FS / 2, E.KV * E.FS / 2)
PULSE = 1.0  # V: about half the drive's rms output on these moves


def _advance(p: float, v: float, force: float, h: float) -> tuple[float, float]:
    """The axis over h under a constant motor force, exactly (the generator's stick/slip solution)."""
    net, left = force - E.OFFSET, h
    tau = E.MASS / E.VISCOUS
    while left > 0.0:
        if v == 0.0:
            if abs(net) <= E.COULOMB:
                return p, 0.0
            s = math.copysign(1.0, net)
        else:
            s = math.copysign(1.0, v)
        v_inf = (net - s * E.COULOMB) / E.VISCOUS
        crossing = -tau * math.log(v_inf / (v_inf - v)) if v != 0.0 and v_inf * s < 0.0 else math.inf
        step = min(left, crossing)
        decay = math.exp(-step / tau)
        p += v_inf * step + (v - v_inf) * tau * (1.0 - decay)
        v = 0.0 if step == crossing else v_inf + (v - v_inf) * decay
        left -= step
    return p, v


def drive(r: np.ndarray, pulses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, y) of the drive that adds ``pulses`` to its command, the axis from rest."""
    p = v = y2 = y1 = 0.0
    u, y = np.empty(r.size), np.empty(r.size)
    for k in range(r.size):
        y[k] = round(p / E.ENCODER) * E.ENCODER
        u[k] = E.KP * E.KV * (r[k] - y[k]) - E.KV * (y[k] - y2) * E.FS / 2 + pulses[k]
        y2, y1 = y1, y[k]
        p, v = _advance(p, v, E.GAIN * u[k], 1.0 / E.FS)
    return u, y


def pulse_train(n: int, width: int = 10, spacing: int = 97, seed: int = 0) -> np.ndarray:
    """Pulses of +-PULSE, ``width`` samples each, every ``spacing`` samples, random signs."""
    signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=n // spacing + 1)
    x = np.zeros(n)
    for i, start in enumerate(range(spacing // 2, n - width, spacing)):
        x[start:start + width] = PULSE * signs[i]
    return x


def axis(excitation: dict | None = None, **model) -> dict:
    """The axis as its drive computes it (the truth unless ``model`` overrides keys)."""
    loop = {"controller": {"type": "cascade", "position": {"type": "pid", "kp": E.KP},
                           "velocity": {"type": "pid", "kp": E.KV}, "velocity_estimate": "two_tap"}}
    if excitation is not None:
        loop["excitation_channels"] = excitation
    return {"model": {"type": "mass_spring_damper", "mass": E.MASS, "damping": E.VISCOUS, "gain": E.GAIN,
                      "force_offset": -E.OFFSET, "nonlinearities": [{"type": "coulomb", "fc": E.COULOMB}], **model},
            "closed_loop": loop}


UNITS = {"u": "V", "y": "m", "r": "m"}


@pytest.fixture(scope="module")
def records() -> list[Run]:
    """A pulsed record (channel ``pulses``) and a plain one (no channels), about 5 s each."""
    r1 = E.move_profile([0.1, 0.0, 0.06, 0.0], [0.1, 0.12, 0.08, 0.1], dwell=0.3)
    r2 = E.move_profile([0.08, 0.02, 0.1, 0.0], [0.12, 0.06, 0.1, 0.09], dwell=0.3)
    pulses = pulse_train(r1.size)
    u1, y1 = drive(r1, pulses)
    u2, y2 = drive(r2, np.zeros(r2.size))
    return [Run("pulsed", E.FS, "arbitrary", u1, y=y1, r=r1, channels={"pulses": pulses}, units=UNITS),
            Run("plain", E.FS, "arbitrary", u2, y=y2, r=r2, units=UNITS)]


def _simulate(config: dict, run: Run) -> Run:
    validated = mc.SimulateConfig.model_validate(config)
    excitation = Run(run.run_id, run.fs, "arbitrary", run.r, channels=run.channels)
    return simulate_run(from_config.model(validated), from_config.closed_loop(validated), excitation, None)


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def test_the_simulated_command_includes_the_pulses(records):
    pulsed = records[0]
    simulated = _simulate(axis({"pulses": 1.0}), pulsed)
    assert _rms(simulated.u - pulsed.u) <= 1.5 * SIGMA_U  # 2.9e-3 V against the drive's 1.9 V rms
    assert _rms(simulated.y - pulsed.y) <= 1.5 * QUANT
    # the same drive without the pulses misses them in u (the loop rejects their effect on y)
    unpulsed = _simulate(axis(), pulsed)
    assert _rms(unpulsed.u - pulsed.u) >= 0.5 * _rms(pulsed.channels["pulses"])
    assert _rms(unpulsed.u - pulsed.u) >= 50 * SIGMA_U


@pytest.mark.parametrize("key", ["closed_loop.excitation_channels", "model.input_channels"])
def test_a_channel_marked_absent_zero_is_zero_on_a_run_without_it(records, key):
    plain = records[1]
    section, name = key.split(".")
    marked = axis()
    marked[section][name] = {"pulses": {"gain": 2.0, "absent": "zero"}}
    with_zero, without = _simulate(marked, plain), _simulate(axis(), plain)
    np.testing.assert_array_equal(with_zero.u, without.u)
    np.testing.assert_array_equal(with_zero.y, without.y)


@pytest.mark.parametrize("key", ["closed_loop.excitation_channels", "model.input_channels"])
def test_the_cli_refuses_a_channel_a_run_lacks_unless_marked_absent_zero(run_cli, tmp_path, records, key):
    data = write_recording(tmp_path / "records.h5", records, {"tool": "test"})
    section, name = key.split(".")
    config = axis()
    config[section][name] = {"pulses": 1.0}
    path = tmp_path / "axis.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    refused = run_cli("simulate", path, "--excitation", data, "-o", tmp_path / "refused.h5")
    refused.assert_one_line_error(f"{key}.pulses", "run plain records no channel 'pulses'")
    assert not (tmp_path / "refused.h5").exists()

    config[section][name] = {"pulses": {"gain": 1.0, "absent": "zero"}}
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    accepted = run_cli("--json", "simulate", path, "--excitation", data, "-o", tmp_path / "accepted.h5")
    assert accepted.exit_code == 0, accepted.stderr
    assert accepted.json()["notes"] == [f"run plain records no channel 'pulses': taken as zero ({key}.pulses.absent: zero)"]
    out = {run.run_id: run for run in read_runs(tmp_path / "accepted.h5")}
    np.testing.assert_array_equal(out["plain"].y, _simulate(axis(), records[1]).y)


def test_fit_on_u_recovers_the_axis_from_a_pulsed_record_in_motion(run_cli, tmp_path, records):
    """Mass, viscous, Coulomb and offset free, fitted on u of the pulsed record cut where the axis
    runs at full speed (the loop's state at its start fitted: nlsid.simulate.loop_state), validated
    on the plain record, which lacks the channel (taken as zero, stated): within 1 % of the truth
    (measured: 0.15 %)."""
    pulsed, plain = records
    k = int(np.argmax(np.abs(np.diff(pulsed.r)))) + 1  # where the reference moves fastest (0.12 m/s)
    assert abs(pulsed.y[k] - pulsed.y[k - 1]) * E.FS >= 0.1  # m/s: the axis is in motion there
    cut = Run("pulsed", E.FS, "arbitrary", pulsed.u[k:], y=pulsed.y[k:], r=pulsed.r[k:],
              channels={"pulses": pulsed.channels["pulses"][k:]}, units=UNITS)
    data = write_recording(tmp_path / "records.h5", [cut, plain], {"tool": "test"})
    config = axis({"pulses": {"gain": 1.0, "absent": "zero"}}, mass=70.0, damping=150.0, force_offset=0.0,
                  nonlinearities=[{"type": "coulomb", "fc": 10.0}])
    config["free"] = {"model.mass": {"lower": 1.0}, "model.damping": {"lower": 0.0},
                      "model.nonlinearities[0].fc": {"lower": 1e-3}, "model.force_offset": {}}
    path = tmp_path / "axis.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    result = run_cli("--json", "fit", "--model", path, "--data", data, "--fit-on", "u", "--validation", "plain",
                     "-o", tmp_path / "fitted.yaml")
    assert result.exit_code == 0, result.stderr
    summary = result.json()
    values = {name: p["value"] for name, p in summary["parameters"].items()}
    assert values["model.mass"] == pytest.approx(E.MASS, rel=0.01)
    assert values["model.damping"] == pytest.approx(E.VISCOUS, rel=0.01)
    assert values["model.nonlinearities[0].fc"] == pytest.approx(E.COULOMB, rel=0.01)
    assert values["model.force_offset"] == pytest.approx(-E.OFFSET, rel=0.01)
    assert ("run plain records no channel 'pulses': taken as zero "
            "(closed_loop.excitation_channels.pulses.absent: zero)") in summary["warnings"]


@pytest.mark.parametrize("form", ["number", "mapping"])
def test_an_excitation_gain_is_a_free_parameter(records, form):
    """The pulses' gain fitted from a start of 0.5, written as a number or as {gain: ...}, on the
    pulsed record's first 3000 samples (validated on the rest): the truth's 1 within 1 % (the
    quantisation's share of u, 2.9e-3 V rms against pulses of 1 V, moves it by about 1e-3)."""
    from nlsid.stages.fit import fit_model
    from nlsid.stages.recording import Recording

    entry = 0.5 if form == "number" else {"gain": 0.5, "absent": "zero"}
    key = "closed_loop.excitation_channels.pulses" + ("" if form == "number" else ".gain")
    config = axis({"pulses": entry})
    config["free"] = {key: {}}
    fitted = fit_model(config, Recording(records[:1]), fit_on="u", estimation_range="0:3000",
                       validation_range="3000:4884")
    assert fitted.names == [key]
    assert fitted.values[0] == pytest.approx(1.0, abs=0.01)


def test_forward_sensitivities_carry_the_excitation(records):
    """The forward sensitivities of u in the pulses' gain (a friction-free axis, whose loop is
    linear: u is affine in the gain, so a central difference of two simulations is its derivative
    up to rounding) and in the mass (central difference of step 1e-4 relative: O(h^2) ~ 1e-8)."""
    from nlsid.simulate import tangent

    pulsed = records[0]
    excitation = Run(pulsed.run_id, pulsed.fs, "arbitrary", pulsed.r, channels=pulsed.channels)

    def config(gain: float, mass: float) -> dict:
        return axis({"pulses": gain}, mass=mass, nonlinearities=[])

    def arguments_at(theta: np.ndarray) -> list[tuple]:
        validated = mc.SimulateConfig.model_validate(config(*theta))
        return tangent.run_arguments(from_config.model(validated), from_config.closed_loop(validated), [excitation], None)

    theta = np.array([0.8, E.MASS])
    found = tangent.derivatives(arguments_at, theta)
    assert found is not None  # smooth: no friction
    _, _, du, _ = tangent.simulate(*found[0])
    for i, h in enumerate((0.1, 1e-4 * E.MASS)):
        step = np.eye(2)[i] * h
        up, down = (_simulate(config(*(theta + s)), pulsed).u for s in (step, -step))
        difference = (up - down) / (2 * h)
        assert _rms(du[i] - difference) <= 1e-6 * _rms(difference)
    assert _rms(du[0]) >= 0.5 * _rms(pulsed.channels["pulses"])  # the pulses reach u through the gain


def test_a_pnlss_model_takes_the_channel_entries_and_writes_them_back():
    """A pnlss model's input_channels: on a run without the channel, absent: zero runs the model
    on u alone; with it, on u + gain * channel (both against the model's own simulation of the
    input formed here); to_config writes the entry back as it reads it; without absent: zero the
    run is refused, named."""
    from nlsid.errors import InputError
    from nlsid.models.pnlss import build, to_config
    from nlsid.simulate.pnlss_runs import fitted_input, simulate_measured

    data = {"type": "pnlss", "fs": 100.0, "A": [[0.9]], "B": [1.0], "C": [1.0], "D": 0.0, "state_degrees": [3],
            "E": [[-0.1, 0.02, 0.0, 0.01]], "input_channels": {"d": {"gain": 2.0, "absent": "zero"}}}
    model = build(mc.SimulateConfig.model_validate({"model": data}).model)
    rng = np.random.default_rng(1)
    u, d = rng.standard_normal(200), rng.standard_normal(200)
    plain = Run("plain", 100.0, "arbitrary", u)
    disturbed = Run("disturbed", 100.0, "arbitrary", u, channels={"d": d})
    np.testing.assert_array_equal(fitted_input(model, plain), u)
    np.testing.assert_allclose(fitted_input(model, disturbed), u + 2.0 * d, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(simulate_measured(model, plain, False), model.simulate(u))
    assert to_config(model)["input_channels"] == {"d": {"gain": 2.0, "absent": "zero"}}
    refused = build(mc.SimulateConfig.model_validate({"model": {**data, "input_channels": {"d": 2.0}}}).model)
    with pytest.raises(InputError, match="run plain records no channel 'd'") as error:
        fitted_input(refused, plain)
    assert error.value.where == "model.input_channels.d"
    assert to_config(refused)["input_channels"] == {"d": 2.0}


@pytest.mark.parametrize(("entry", "message"), [
    ({"gain": 1.0, "absent": "maybe"}, "excitation_channels.pulses.absent: expected 'error' or 'zero', got 'maybe'"),
    ({"gian": 1.0}, "excitation_channels.pulses.gian: unknown key"),
    ({"gain": float("inf")}, "excitation_channels.pulses.gain: expected a finite number"),
    ([1.0, 2.0], "excitation_channels.pulses: expected a gain (a number) or a mapping {gain, absent}"),
])
def test_a_bad_channel_entry_is_refused_at_its_key(entry, message):
    from nlsid.errors import InputError
    from nlsid.io.config import validate

    with pytest.raises(InputError) as error:
        validate(axis({"pulses": entry}), mc.SimulateConfig, "axis.yaml", {})
    assert message in str(error.value)
