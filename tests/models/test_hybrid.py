"""The hybrid model (nlsid/models/hybrid.py, ``type: hybrid``): a physical model with a PNLSS term
in parallel, y = y_physical(u) + y_black_box(u).

Each part is checked against an independent computation written here: the physical part, a
discrete transfer function, by scipy.signal.lfilter; the black box by a direct numpy loop of the
PNLSS equations (docs/pnlss.md; monomials in itertools order). Their sum must equal nlsid's
simulation of the hybrid config to rounding, from rest and in periodic steady state."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import signal

import nlsid
from nlsid.errors import InputError
from nlsid.io.recording import write_recording
from nlsid.io.run import Run

FS = 100.0
NUM, DEN = [0.0, 0.2, 0.1], [1.0, -1.2, 0.5]  # ascending powers of z^-1; poles |z| = 0.71
A = np.array([[0.6, 0.2], [-0.1, 0.5]])
B, C, D = np.array([1.0, 0.5]), np.array([0.3, -0.2]), 0.1
E = 0.05 * np.arange(1, 13).reshape(2, 6) / 12  # state monomials of degree 2 in (x1, x2, u): 6
F = 0.02 * np.linspace(-1, 1, 10)                  # output monomials of degree 3: 10
PHYSICAL = {"type": "transfer_function", "domain": "discrete", "fs": FS, "num": NUM, "den": DEN, "output_offset": 0.3}
BLACK_BOX = {"type": "pnlss", "fs": FS, "A": A.tolist(), "B": B.tolist(), "C": C.tolist(), "D": D,
             "state_degrees": [2], "output_degrees": [3], "E": E.tolist(), "F": F.tolist(),
             "input_offset": 0.05, "output_offset": -0.1}
CONFIG = {"model": {"type": "hybrid", "physical": PHYSICAL, "black_box": BLACK_BOX}}


def _monomials(v: np.ndarray, degree: int) -> np.ndarray:
    combos = itertools.combinations_with_replacement(range(v.size), degree)
    return np.array([np.prod([v[i] for i in combo]) for combo in combos])


def _black_box(u: np.ndarray) -> np.ndarray:
    """The PNLSS equations from rest, on u + input_offset, output offset added."""
    x, y = np.zeros(2), np.empty(u.size)
    for t, ut in enumerate(u + 0.05):
        v = np.append(x, ut)
        y[t] = C @ x + D * ut + F @ _monomials(v, 3) - 0.1
        x = A @ x + B * ut + E @ _monomials(v, 2)
    return y


def _physical(u: np.ndarray) -> np.ndarray:
    return signal.lfilter(NUM, DEN, u) + 0.3


def test_simulation_is_the_sum_of_the_parts_from_rest():
    u = 0.4 * np.random.default_rng(1).standard_normal(300)
    y = nlsid.Model.from_dict(CONFIG).simulate(u, fs=FS)
    np.testing.assert_allclose(y, _physical(u) + _black_box(u), rtol=1e-12, atol=1e-12)


def test_periodic_run_is_simulated_in_steady_state(tmp_path, run_cli):
    """``nlsid simulate --steady-state``: each part in its periodic steady state, here the last two
    of 30 periods simulated from rest by the independent loops (the slower part's modes, |z| <= 0.71,
    decay by 1e-130 over the 28 periods ahead). nlsid's lead-in runs until the slowest mode has
    decayed to 1e-6 (STEADY_TOLERANCE of both engines), so the start of the record may differ by up
    to 1e-6 of the signal; from rest it would differ by the whole transient (0.1 here)."""
    period = 50
    u = 0.4 * np.random.default_rng(2).standard_normal(period)
    excitation = write_recording(tmp_path / "exc.h5", [Run("m", FS, "multisine", np.tile(u, 2), period=period,
                                                                 excited_bins=np.arange(1, 25))],
                                 {"tool": "test"})
    config = tmp_path / "hybrid.yaml"
    import yaml

    config.write_text(yaml.safe_dump(CONFIG))
    out = run_cli("simulate", config, "--excitation", excitation, "-o", tmp_path / "sim.h5", "--steady-state")
    assert out.exit_code == 0, out.stderr
    simulated = nlsid.read(tmp_path / "sim.h5").runs[0].y
    long = np.tile(u, 30)
    expected = (_physical(long) + _black_box(long))[-2 * period:]
    np.testing.assert_allclose(simulated, expected, rtol=0, atol=1e-6 * np.max(np.abs(expected)))
    np.testing.assert_allclose(simulated[period:], expected[period:], rtol=1e-10, atol=1e-10)


def test_a_black_box_as_the_physical_part_is_refused_in_one_line(tmp_path, run_cli):
    config = tmp_path / "hybrid.yaml"
    import yaml

    config.write_text(yaml.safe_dump({"model": {"type": "hybrid", "physical": BLACK_BOX, "black_box": BLACK_BOX}}))
    excitation = write_recording(tmp_path / "exc.h5", [Run("a", FS, "arbitrary", np.zeros(20))], {"tool": "test"})
    out = run_cli("simulate", config, "--excitation", excitation, "-o", tmp_path / "sim.h5")
    out.assert_one_line_error("model.physical", "not a physical part")
    assert not (tmp_path / "sim.h5").exists()


def test_an_error_in_a_part_names_its_key():
    bad = {"model": {"type": "hybrid", "physical": PHYSICAL, "black_box": {**BLACK_BOX, "F": F[:-1].tolist()}}}
    with pytest.raises(InputError, match=r"model\.black_box\.F.*10 coefficients"):
        nlsid.Model.from_dict(bad).simulate(np.zeros(5), fs=FS)
    unstable = {"model": {"type": "hybrid", "physical": {**PHYSICAL, "den": [1.0, -2.5, 1.0]}, "black_box": BLACK_BOX}}
    with pytest.raises(InputError, match=r"model\.physical"):
        nlsid.Model.from_dict(unstable).simulate(np.zeros(5), fs=FS)


def test_fit_model_refines_a_physical_parameter_of_a_hybrid(tmp_path):
    """``nlsid.fit_model`` on a hybrid config with a free physical parameter: on noise-free data
    made by the independent loops with the physical numerator's b2 = 0.1, started 30 % off, the
    fit returns it to 1e-6 (the simulation error is zero there and quadratic around it); the
    periodic run is fitted whole, each part in its own steady state."""
    period = 64
    rng = np.random.default_rng(4)
    runs = []
    for i in range(2):
        u = 0.4 * rng.standard_normal(period)
        long = np.tile(u, 30)
        y = (_physical(long) + _black_box(long))[-2 * period:]
        runs.append(Run(f"m{i}", FS, "multisine", long[-2 * period:], y, period=period, realization=i, level=1.0,
                        excited_bins=np.arange(1, 25)))
    recording = write_recording(tmp_path / "rec.h5", runs, {"tool": "test"})
    config = {**CONFIG, "model": {**CONFIG["model"], "physical": {**PHYSICAL, "num": [0.0, 0.2, 0.13]}}}
    fit = nlsid.fit_model(config, recording, free={"model.physical.num[2]": {}}, validation=["m1"])
    assert fit.names == ["model.physical.num[2]"] and abs(fit.values[0] - 0.1) < 1e-6, fit.values
