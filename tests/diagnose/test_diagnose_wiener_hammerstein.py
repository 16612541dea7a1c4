"""A static nonlinearity between two filters (issue 17, item 3): the Wiener-Hammerstein hypothesis
on a circuit made outside nlsid (tests/generators/wh_cases.py), through the commands a user types:
``bla`` -> ``fit`` -> ``diagnose --estimation-range --validation-range``, then the extended model
on samples neither range touched.

The truth is the discrete-time circuit: two Chebyshev filters (each its exact zero-order-hold
equivalent) around a smooth diode-resistor curve, which no polynomial or piecewise-linear curve
reproduces exactly; white sensor noise of 1 mV and a sensor offset of 20 mV. Its BLA fit (4/6, two
samples of delay) takes two real poles of different filters for one damped pair, so the split must
be found with the roots moving. Measured when this test was written: the linear model's error is
63 mV; with the true filters, the best 16-knot curve leaves 1.4 mV against the measured output
(noise 1 mV: about 1 mV of the regressed curve's own, which the refinement reduces; below); the diagnosis ended at 1.8 mV from the fit
with per-line LPM weights (its poles up to 0.12 off in |z|), and ends at 2.2 mV from the fit with
smoothed weights (poles within 0.01 in |z| of the truth's, two real poles taken as one pair): the
split search's optimum depends on where it starts (the same validation error, 2.35 mV, with 4x the
refinement budget, 4 finalists or 80 root-search steps). Measured in session 17 (the initial
states of session 15 and the whole model refined since): 1.36 mV against the noise-free output on
the test samples, 1.67 mV validation error against the measured output, diagnose in 18 s; a
refinement Jacobian step of 1e-5 instead of 1e-3 changes the test error by 0.002 mV. Since the
estimate's regression delays the input by the model's dead time as the extended structure does
(session 18): 0.97 mV, diagnose in 17 s. Since the root search moves the first filter's zeros at
the origin (session 19; the first filter's own zeros, -3.10 and -0.23 in the truth, are sampling
zeros that the BLA's fit cannot assign): 0.23 mV, the first filter's real pole 0.8 % off instead
of 4 %, diagnose in 13 s. So the curve was not the limit: the filters were.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.signal import cont2discrete, freqz

from generators import wh_cases  # noqa: E402
from nlsid.diagnose.hypotheses import filter_split, static_curve  # noqa: E402
from nlsid.diagnose.simulation import ModelRunner  # noqa: E402
from nlsid.io.recording import write_recording  # noqa: E402
from nlsid.io.run import Run  # noqa: E402

N, ESTIMATION, VALIDATION = 24000, "0:16000", "16000:20000"
TEST = slice(20000, N)
NOISE, OFFSET, KNEE = 1e-3, 0.02, 0.1


# one worker runs the module (xdist --dist loadgroup; pytest below 9.2, see pyproject), and its
# fixture lives for the session: the worker may run other modules' tests between these, which
# tears a module fixture down
pytestmark = pytest.mark.xdist_group("wiener_hammerstein")


@pytest.fixture(scope="session")
def chain(tmp_path_factory):
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    rng = np.random.default_rng(2)
    u = wh_cases.excitation(N, rng)
    clean = wh_cases.sampled_circuit(u, KNEE)
    y = clean + NOISE * rng.standard_normal(N) + OFFSET
    folder = tmp_path_factory.mktemp("wh")
    recording = folder / "circuit.h5"
    write_recording(recording, [Run("circuit", wh_cases.FS, "arbitrary", u, y=y)])

    def nlsid(*args):
        result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
        assert result.exit_code == 0, result.output
        return result.stdout

    nlsid("bla", recording, "-o", folder / "bla.h5")
    nlsid("fit", folder / "bla.h5", "--order", "4/6", "--delay", "2", "-o", folder / "linear.yaml")
    summary = json.loads(nlsid("diagnose", "--model", folder / "linear.yaml", "--data", recording, "-o",
                               folder / "diagnosis", "--estimation-range", ESTIMATION, "--validation-range",
                               VALIDATION, "--json"))
    extended = yaml.safe_load((folder / "diagnosis" / "extended_model.yaml").read_text())
    linear = yaml.safe_load((folder / "linear.yaml").read_text())
    return summary, extended, linear, Run("circuit", wh_cases.FS, "arbitrary", u, y=y), clean


@pytest.mark.slow
def test_names_a_saturating_asymmetric_curve_between_two_filters(chain):
    summary, extended, *_ = chain
    assert summary["verdict"]["winner"] == "wiener_hammerstein", summary["headline"]
    note = next(h for h in summary["hypotheses"] if h["name"] == "wiener_hammerstein")["note"]
    assert "saturating, asymmetric" in note
    assert extended["model"]["type"] == "wiener_hammerstein"


@pytest.mark.slow
def test_first_filter_poles_are_the_circuits(chain):
    """Between the filters the static curve makes them identifiable: the first filter's poles are
    the Chebyshev I's (a pair at 4703 Hz, a real pole at 2756 Hz), within 2 %. Measured: 2733 and
    4699 Hz, 0.8 % and 0.1 % off. With the first filter's zeros held at the origin (before session
    19) its real pole was 4.2 % off (2640 Hz), standing in for the zeros it lacked; on the analog
    stand-in at the benchmark's size, from a BLA of the estimation samples alone (which merges two
    real poles of different filters into a pair), 2613 Hz then and 2764 Hz now."""
    _, extended, *_ = chain
    b, a, _ = cont2discrete(wh_cases.FIRST, 1 / wh_cases.FS, method="zoh")
    truth = sorted(abs(np.log(np.roots(np.ravel(a)))) * wh_cases.FS / (2 * np.pi))
    poles = [complex(*p) if isinstance(p, list) else complex(p) for p in extended["model"]["first"]["poles"]]
    fitted = sorted({round(abs(np.log(p)) * wh_cases.FS / (2 * np.pi), 3) for p in poles if p != 0})
    assert len(fitted) == 2
    assert np.allclose(fitted, sorted(set(np.round(truth, 3))), rtol=0.02), (fitted, truth)


@pytest.mark.slow
def test_held_out_error_near_the_noise(chain):
    """On the last 4000 samples (neither fitted nor validated on) the extended model's error
    against the noise-free output is below half the sensor noise (1 mV; measured 0.23 mV, module
    docstring; 0.97 mV with the first filter's zeros held at the origin), 25 times below the
    linear model's (63 mV)."""
    _, extended, linear, run, clean = chain
    model = ModelRunner.from_data(extended, "extended_model.yaml").simulate(run).y
    start = ModelRunner.from_data(linear, "linear.yaml").simulate(run).y
    error = np.sqrt(np.mean((model[TEST] - clean[TEST] - OFFSET) ** 2))
    linear_error = np.sqrt(np.mean((start[TEST] - clean[TEST] - OFFSET) ** 2))
    assert error < 0.5e-3, error
    assert linear_error > 25 * error, (linear_error, error)


def test_every_split_multiplies_back_to_the_model():
    """G1 G2 of every split (but those that turn a pole pair into two real poles) is the model's G
    up to a gain: frequency responses by scipy's freqz, the model's from its own coefficients."""
    model = {"type": "transfer_function", "domain": "discrete", "num": [0.0, 0.2, -0.1, 0.05],
             "den": [1.0, -1.2, 0.8, -0.15]}
    f = filter_split.factors(model)
    w = np.linspace(0.1, 3.0, 7)
    _, G = freqz(model["num"], model["den"], worN=w)
    plain = [s for s in filter_split.splits(f) if all(p in f.poles for p in s[1] + s[3])]
    assert len(plain) == 2 ** (len(f.zeros) + len(f.poles))
    for split in plain:
        z1, p1, z2, p2 = filter_split.realisable(split, f.origin)
        g1, g2 = (freqz(*filter_split.z_coefficients(filter_split.zpk(z, p, 1.0, True), 1.0), worN=w)[1]
                  for z, p in ((z1, p1), (z2, p2)))
        ratio = g1 * g2 / G
        assert np.allclose(ratio, ratio[0], rtol=1e-8), split


@pytest.mark.parametrize("f, words", [
    (np.tanh, "saturating, symmetric"),
    (lambda x: x + 0.3 * x**2, "asymmetric"),
    (lambda x: x + 0.2 * x**3, "expanding, symmetric"),
    (lambda x: wh_cases.diode(x, 0.1), "saturating, asymmetric"),
])
def test_reading_of_known_curves(f, words):
    """The reading of a curve sampled on 41 knots over [-2, 2] (slopes and even part as defined)."""
    knots = np.linspace(-2, 2, 41)
    block = {"type": "piecewise_linear", "x": list(knots), "y": list(f(knots))}
    assert words in static_curve.reading(block, (-2.0, 2.0))


def test_piecewise_linear_basis_is_the_block_law():
    """The hats times the knot values equal the ``piecewise_linear`` block of the simulator,
    beyond the end knots too (the end segments continued)."""
    from nlsid.io.model_config import PiecewiseLinearConfig
    from nlsid.models.blocks import static_block
    from nlsid.simulate.engine import apply_static

    curve = static_curve.PiecewiseLinear((-1.0, -0.2, 0.3, 1.5))
    theta = np.array([-0.7, 0.4, 1.1])
    block = static_curve.block(curve.values(theta))
    x = np.linspace(-3, 3, 301)
    expected = apply_static(static_block(PiecewiseLinearConfig(**block)), x)
    assert np.allclose(theta @ curve.basis(x), expected, atol=1e-12)


def test_not_fitted_where_the_detection_lines_show_no_distortion():
    """A linear truth (the model with a missing resonance) measured with random-odd multisines:
    no odd or even distortion, so a static nonlinearity between filters is not fitted (the
    resonance is the cause)."""
    import copy

    from generators.diagnose_cases import TF, excitation, measure

    from nlsid.diagnose.diagnosis import diagnose

    rng = np.random.default_rng(11)
    wr = 2 * np.pi * 75
    true = copy.deepcopy(TF)
    true["model"]["num"] = [1e4 * wr * wr]
    true["model"]["den"] = [float(c) for c in np.convolve([1, 20, 4e4], [1, 0.1 * wr, wr * wr])]
    result = diagnose(TF, "tf.yaml", measure(true, excitation(rng), rng), "rec")
    assert result.verdict.winner == "missing_resonance"
    outcome = next(o for o in result.outcomes if o.hypothesis.name == "wiener_hammerstein")
    assert outcome.reason.startswith("not fitted: the detection lines show no nonlinear distortion")


@pytest.mark.parametrize("dead_time", [0, 2])
def test_the_start_simulates_as_its_regression_predicts(dead_time):
    """The estimate's extended model, simulated by nlsid from rest, leaves the residual its own
    regression predicted (the same filters, curve and offset; the model's dead time, moved into the
    first filter, included in both). The truth is written here with scipy's lfilter: discrete
    filters around tanh, ``dead_time`` samples of dead time, 0.1 % noise; the user's model is the
    product of the filters with that dead time (their exact BLA shape). Measured before the dead
    time was in the regression: with 2 samples the simulation's error power was 12x the
    regression's (the root search makes the dead time up by moving zeros towards infinity, -1.7e5
    and -1.9e4 on a circuit stand-in, and the extension then delayed the output again)."""
    from scipy.signal import lfilter

    from nlsid.diagnose.hypotheses import wiener_hammerstein as wh
    from nlsid.diagnose.hypotheses.base import Context
    from nlsid.diagnose.simulation import steady_mean
    from nlsid.io.ranges import part

    b1, a1 = [0.0, 0.3, 0.15], [1.0, -1.1, 0.45]
    b2, a2 = [0.0, 0.5], [1.0, -0.6]
    rng = np.random.default_rng(7)
    n, fs = 6000, 1000.0
    u = lfilter([0.5], [1.0, -0.5], rng.standard_normal(n))
    shifted = np.concatenate([np.zeros(dead_time), u[:n - dead_time]])
    clean = lfilter(b2, a2, np.tanh(lfilter(b1, a1, shifted)))
    y = clean + 1e-3 * np.std(clean) * rng.standard_normal(n)
    model = {"model": {"type": "transfer_function", "domain": "discrete", "num": list(np.convolve(b1, b2)),
                       "den": list(np.convolve(a1, a2)), "delay": dead_time / fs}}
    run = part(Run("r", fs, "arbitrary", u, y=y), 0, n)  # the whole record, as diagnose cuts a range
    runner = ModelRunner.from_data(model, "model.yaml")
    residual = steady_mean(run, run.y) - steady_mean(run, runner.simulate(run).y)
    ctx = Context(runner, [run], [residual], [runner.internal(run)])
    estimate = wh.HYPOTHESES[0].estimate(ctx)
    predicted = float(np.sum(residual**2)) / 10 ** (estimate.explained_db / 10)
    extended = runner.with_changes(wh.HYPOTHESES[0].extend(model, estimate.values))
    simulated = float(np.sum((steady_mean(run, run.y) - steady_mean(run, extended.simulate(run).y)) ** 2))
    assert simulated == pytest.approx(predicted, rel=1e-3)  # measured 4e-5: state-space form against lfilter
    assert simulated < 0.01 * float(np.sum(residual**2))


@pytest.mark.slow
def test_continuous_filters_are_refitted_at_the_step_the_circuit_needs(tmp_path):
    """The analog circuit (wh_cases.circuit: its diode between the filters acts on the signal
    sampled 8 times finer, so the curve's output varies within a sample) and the model of the
    circuit's own orders in continuous time (``fit --order 2/6 --domain s``: the Chebyshev I's
    three poles, the inverse Chebyshev's three poles and two zeros). Simulated at one sub-step, the
    curve's output is held over each sample into the second filter, an error the filters of these
    orders cannot absorb: measured 1.45 mV on the held-out samples (here and at the SYSID 2009
    benchmark's size), above the issue's 1 mV for this circuit. The accuracy check
    (nlsid/diagnose/accuracy.py) finds the step's error above a tenth of the floor and the model is
    re-fitted at finer sub-steps (16 at most): below 1 mV (measured 0.18 mV against 0.1 mV of
    noise, diagnose in 16 s), the summary saying which step was used."""
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    n, lead = 24000, 2000
    rng = np.random.default_rng(3)
    u = wh_cases.excitation(n + lead, rng)
    clean, u = wh_cases.circuit(u)[lead:], u[lead:]
    y = clean + 1e-4 * rng.standard_normal(n) + OFFSET
    write_recording(tmp_path / "circuit.h5", [Run("circuit", wh_cases.FS, "arbitrary", u, y=y)])

    def nlsid(*args):
        result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
        assert result.exit_code == 0, result.output
        return result.stdout

    nlsid("bla", tmp_path / "circuit.h5", "-o", tmp_path / "bla.h5")
    nlsid("fit", tmp_path / "bla.h5", "--order", "2/6", "--domain", "s", "-o", tmp_path / "linear.yaml")
    summary = json.loads(nlsid("diagnose", "--model", tmp_path / "linear.yaml", "--data", tmp_path / "circuit.h5",
                               "-o", tmp_path / "diagnosis", "--estimation-range", "0:16000",
                               "--validation-range", "16000:20000", "--json"))
    assert summary["verdict"]["winner"] == "wiener_hammerstein", summary["headline"]
    accuracy = summary["simulation_accuracy"]
    assert accuracy["refit"] and accuracy["substeps"] > 1, accuracy
    extended = yaml.safe_load((tmp_path / "diagnosis" / "extended_model.yaml").read_text())
    assert extended["simulation"]["substeps"] == accuracy["substeps"]
    model = ModelRunner.from_data(extended, "extended_model.yaml").simulate(Run("c", wh_cases.FS, "arbitrary", u, y=y)).y
    error = np.sqrt(np.mean((model[20000:] - clean[20000:] - OFFSET) ** 2))
    assert error < 1e-3, error
