"""The fit engine forms its finite-difference Jacobian itself (its columns simulated together), so
its steps must be scipy's forward-difference rule: the Jacobian (f(x + h_i e_i) - f(x)) / h_i with
:func:`nlsid.fit.extension.forward_steps` is compared with scipy's own
``approx_derivative(method="2-point", rel_step=...)`` (the Jacobian ``least_squares`` forms with
``diff_step``), bit for bit, at points inside, near and on the bounds, at zero and at negative
values. The function is analytic, so a wrong step (size, sign or bound rule) changes the numbers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from nlsid.fit.extension import forward_steps


def f(x: np.ndarray) -> np.ndarray:
    return np.array([np.sin(3 * x[0]) + x[1] ** 3, np.exp(0.5 * x[1]) * x[2], x[0] * x[2] ** 2 + np.cos(x[1])])


CASES = [
    (np.array([0.7, -1.3, 2.0]), np.full(3, -np.inf), np.full(3, np.inf)),         # no bounds
    (np.array([0.0, -1e-12, 1e5]), np.full(3, -np.inf), np.full(3, np.inf)),       # zero, tiny, large
    (np.array([0.9999, -1.3, 2.0]), np.array([-1.0, -5.0, 0.0]), np.array([1.0, 5.0, 2.0])),  # at and near upper bounds
    (np.array([0.001, -1.3, 0.0015]), np.array([0.0, -1.3005, 0.0]), np.array([0.0015, 0.0, 0.0016])),  # narrow boxes
]


@pytest.mark.parametrize("x, lower, upper", CASES)
@pytest.mark.parametrize("rel_step", [1e-3, 1e-6])
def test_the_steps_give_scipys_forward_difference_jacobian(x, lower, upper, rel_step):
    h = forward_steps(x, rel_step, lower, upper)
    f0 = f(x)
    ours = np.empty((3, 3))
    for i in range(3):
        shifted = x + np.where(np.arange(3) == i, h, 0.0)
        assert lower[i] <= shifted[i] <= upper[i]
        ours[:, i] = (f(shifted) - f0) / (shifted[i] - x[i])
    theirs = approx_derivative(f, x, method="2-point", rel_step=rel_step, f0=f0, bounds=(lower, upper))
    np.testing.assert_array_equal(ours, theirs)


def _offset_runs(closed: bool = False, periodic: bool = True):
    """Two runs of 4 periods of 512 samples (a transient one, or the same samples as arbitrary
    records), the output a random signal (the residual's algebra does not need a model's)."""
    from nlsid.io.run import Run

    rng = np.random.default_rng(3)
    period = 512
    runs = []
    for i in range(2):
        u = np.tile(rng.standard_normal(period), 4)
        y = 1e-3 * rng.standard_normal(u.size)
        extra = {"period": period, "transient_periods": 1} if periodic else {}
        runs.append(Run(f"r{i}", 1000.0, "multisine" if periodic else "arbitrary", u, y=y, r=u if closed else None,
                        **extra))
    return runs


def _offset_problem(closed: bool, periodic: bool, force: dict | None = None):
    """A mass-spring-damper with ``force`` (Coulomb friction) and a free output offset on
    :func:`_offset_runs`."""
    from nlsid.fit.free_parameters import FreeParameter
    from nlsid.fit.simulation_cost import Cost, Problem

    model = {"type": "mass_spring_damper", "mass": 1.0, "damping": 400.0, "stiffness": 40000.0, "output_offset": 1e-4,
             "nonlinearities": [force or {"type": "coulomb", "fc": 0.3}]}
    data = {"model": model}
    if closed:
        data["closed_loop"] = {"controller": {"type": "pid", "kp": 2000.0}}
    runs = _offset_runs(closed, periodic)
    key = "fc" if "fc" in model["nonlinearities"][0] else "k3"
    free = {f"model.nonlinearities[0].{key}": FreeParameter(), "model.output_offset": FreeParameter()}
    problem = Problem(data, free, "m", {}, None)
    return problem, Cost.of(problem, runs, problem.inputs(runs))


def test_the_output_offset_column_is_the_simulated_derivative():
    # The offset enters the open-loop output additively, so its exact column must equal the
    # difference of two simulations (linear in the offset: equal up to rounding), with the runs'
    # sqrt(P) weights of the compact periodic fit (3 steady periods: sqrt 3; the critically damped
    # mode at 200 /s settles within the transient period).
    problem, cost = _offset_problem(closed=False, periodic=True)
    index, column = cost.offset_column(problem, "y")
    assert problem.names[index] == "model.output_offset"
    step = 1e-6
    base, shifted = cost.residuals(problem, [problem.start, problem.start + step * np.eye(2)[index]], "y")
    np.testing.assert_allclose(column, (shifted - base) / step, rtol=1e-6)
    assert column[0] == pytest.approx(np.sqrt(3))


@pytest.mark.parametrize("closed, periodic", [(True, True), (False, False)])
def test_no_exact_offset_column_where_the_offset_is_not_additive(closed, periodic):
    # closed loop: the controller reads the offset; arbitrary records: the fitted initial state takes part of it
    problem, cost = _offset_problem(closed, periodic)
    assert cost.offset_column(problem, "y") is None


@pytest.mark.parametrize("force, lead", [({"type": "cubic_stiffness", "k3": 1e9}, 70),
                                         ({"type": "coulomb", "fc": 0.3}, 512)])
def test_the_compact_residual_is_the_whole_runs_mean_period(force, lead):
    # A periodic run is fitted on its mean period: sqrt(P) (s_sim - mean_p s_p), simulated from
    # rest a lead ahead of one period: the samples in which the model settles to the engine's
    # 1e-6 (the critically damped mode at 200 /s: ln(1e6) / 200 s, 70 samples), and a whole
    # period at least for friction, whose stuck positions its decay does not erase (with 70
    # samples the error periods differed by 0.5 % of the output after a stick). Against the
    # engine's whole run, simulated as recorded from the run's start: the mean of its P = 3
    # steady-state error periods times sqrt(3), to that tolerance of the simulated output.
    problem, cost = _offset_problem(closed=False, periodic=True, force=force)
    assert all(run.n_samples == 512 + lead for run in cost.inputs)
    compact = cost.residuals(problem, [problem.start], "y")[0]
    runs = _offset_runs()
    whole = problem.errors(problem.start, runs, problem.inputs(runs))["y"]
    expected = np.concatenate([np.sqrt(3) * e.reshape(3, 512).mean(axis=0) for e in whole])
    simulated = max(float(np.max(np.abs(e + _steady_y(run)))) for e, run in zip(whole, runs))
    np.testing.assert_allclose(compact, expected, rtol=0, atol=1e-5 * np.sqrt(3) * simulated)


def _steady_y(run):
    return run.y[run.transient_periods * run.period:]
