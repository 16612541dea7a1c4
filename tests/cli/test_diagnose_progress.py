"""The progress bar of ``nlsid diagnose`` counts work, not steps of very different cost.

A hypothesis' fit is told as the work of its free parameters + 1, a hypothesis not fitted takes its
share back without advancing (so instant steps do not inflate the speed the time remaining is
computed from), and the work done reaches the total exactly at the end, never beyond it.

The measurement is made without nlsid's simulator: the exact ZOH solution of 1e4 / (s^2 + 20 s +
4e4) (the transfer function of tests/generators/diagnose_cases.py, Van Loan's block exponential)
with a quadratic output term and white sensor noise. The quadratic output (one parameter) reaches
the noise floor, so every hypothesis of more parameters is not fitted (a simpler one suffices),
and the hypotheses of a closed loop or of a mass-spring-damper do not apply: skipped work of both
kinds.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml

from generators.diagnose_cases import FS, NOISE, TF, excitation  # noqa: E402
from generators.exact_zoh import zoh  # noqa: E402
from nlsid.cli import common
from nlsid.diagnose.hypotheses import LIBRARY
from nlsid.io.recording import write_recording
from nlsid.stages.diagnose import progress_calls

A2 = 0.06  # the quadratic output term: y = x + A2 x^2 (x about 0.45 rms: the term about -31 dB of x)


def plant(u: np.ndarray) -> np.ndarray:
    a = np.array([[0.0, 1.0], [-4e4, -20.0]])
    phi, gamma = zoh(a, np.array([0.0, 1.0]), 1 / FS)
    x, y = np.zeros(2), np.empty(u.size)
    for k, uk in enumerate(u):
        y[k] = 1e4 * x[0]
        x = phi @ x + gamma * uk
    return y


class _Bar:
    """rich's Progress as the command drives it, recording (completed, total) at each update."""

    states: list[tuple[float, float]] = []

    def __init__(self, *columns, **options):
        self.completed, self.total = 0, None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def add_task(self, description, total, **fields):
        self.total = total
        _Bar.states.append((self.completed, self.total))
        return 0

    def update(self, task, description=None, total=None, completed=None, **fields):
        self.total = self.total if total is None else total
        self.completed = self.completed if completed is None else completed
        _Bar.states.append((self.completed, self.total))

    def advance(self, task, advance):
        self.completed += advance
        _Bar.states.append((self.completed, self.total))


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    """``nlsid diagnose --json`` with the bar drawn (a terminal for rich), the bar's states and the
    diagnosis' own calls (name, work, planned change, the bar's state after it)."""
    import rich.progress
    from click.testing import CliRunner

    import nlsid.diagnose.diagnosis as diagnosis
    from nlsid.cli.main import cli

    folder = tmp_path_factory.mktemp("progress")
    rng = np.random.default_rng(5)
    runs = []
    for run in excitation(rng, realizations=2):
        x = plant(run.u)
        runs.append(dataclasses.replace(run, y=x + A2 * x**2 + NOISE * rng.standard_normal(run.n_samples)))
    write_recording(folder / "rec.h5", runs)
    (folder / "model.yaml").write_text(yaml.safe_dump(TF))
    calls = []
    real = diagnosis.diagnose

    def recorded(*args, step=None, **kwargs):
        def told(name, work, planned):
            step(name, work, planned)
            calls.append((name, work, planned, _Bar.states[-1]))

        return real(*args, step=told, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("FORCE_COLOR", "1")  # a terminal for rich: the bar is drawn
        patch.setattr(rich.progress, "Progress", _Bar)
        patch.setattr(diagnosis, "diagnose", recorded)
        _Bar.states = []
        result = CliRunner().invoke(cli, ["diagnose", "--model", str(folder / "model.yaml"), "--data",
                                          str(folder / "rec.h5"), "-o", str(folder / "out"), "--json"])
    assert result.exit_code == 0, (result.stdout, result.stderr, result.exception)
    return json.loads(result.stdout), list(_Bar.states), calls


def test_the_work_done_never_exceeds_the_total_and_reaches_it_at_the_end(diagnosed):
    summary, states, calls = diagnosed
    assert summary["chain"][0]["cause"] == "quadratic_output"
    assert all(done <= total for done, total in states), states
    done, total = states[-1]
    assert done == total > 0
    assert calls[-1][0] == "yardstick" and calls[-1][3] == states[-1]  # the last step ends the bar


def test_the_whole_plan_is_told_before_any_work(diagnosed):
    """The bar opens with the work the diagnosis plans (the first round's, here without the
    yardstick, which the suite does not fit) and keeps that total until the first work is done."""
    _, states, calls = diagnosed
    opened = states[0][1]
    first_work = next(i for i, state in enumerate(states) if state[0] > 0)
    assert {total for _, total in states[:first_work + 1]} == {opened}
    assert calls[0][:3] == ("round", 0, opened)


def test_a_hypothesis_not_fitted_takes_its_share_back_without_advancing(diagnosed):
    summary, _, calls = diagnosed
    outcomes = {h["name"]: h for h in summary["hypotheses"]}
    told = {name: (work, planned, state) for name, work, planned, state in calls if name in outcomes}
    # not fitted: ruled out by a simpler hypothesis at the floor, or by its signature (output
    # saturation: no flat ceiling in the record); a hypothesis that cannot apply to the model
    # (a closed loop's) is never planned, so never told
    skipped = [name for name, h in outcomes.items() if h["reason"].startswith(("not fitted", "does not apply"))
               and name in told]
    assert all(outcomes[name]["reason"].startswith("does not apply") for name in set(outcomes) - set(told))
    fitted = [name for name, h in outcomes.items() if h["scored"]]
    assert len(skipped) >= 5 and fitted, summary["hypotheses"]  # both kinds present, else the test tests nothing
    states = [state for *_, state in calls]
    for name in skipped:
        work, planned, state = told[name]
        before = states[[c[0] for c in calls].index(name) - 1]
        assert work == 0 and planned < 0, (name, work, planned)
        assert state == (before[0], before[1] + planned), (name, before, state)  # the total lowered, nothing done
    parameters = {h.name: len(h.parameters) for h in LIBRARY}
    for name in fitted:
        work, planned, _ = told[name]
        # its free parameters + 1: its own, and the output offset at least (free in open loop)
        assert work >= parameters[name] + 2, (name, work)
    assert set(outcomes) - set(told)  # some were never planned


def test_a_progress_callable_is_told_the_work_or_called_as_before():
    """``progress(advance=, total=)`` gets the work done since the last call and the total planned;
    a callable without those keywords is called without arguments after each step that did work,
    and after the yardstick."""
    steps = [("round", 0, 30), ("evidence", 4, 0), ("nuisances", 2, 0), ("coulomb", 7, 0),
             ("lugre", 0, -10), ("round", 0, 20), ("evidence", 4, 0), ("yardstick", 0, 0)]
    counted, plain = [], []
    for callback in (lambda advance=1, total=None: counted.append((advance, total)), lambda: plain.append(1)):
        step = progress_calls(callback)
        for name, work, planned in steps:
            step(name, work, planned)
    assert counted == [(0, 30), (4, 30), (2, 30), (7, 30), (0, 20), (0, 40), (4, 40), (0, 40)]
    assert len(plain) == 5  # evidence, nuisances, coulomb, evidence, yardstick


def test_the_time_remaining_is_the_work_left_at_the_speed_of_the_work_done():
    assert common.time_remaining(10, 5.0, 20) == pytest.approx(10.0)  # 2 units/s, 20 left
    assert common.time_remaining(0, 5.0, 20) is None  # nothing timed yet
    assert common.time_remaining(10, 5.0, 0) == 0.0
    assert common.remaining_text(None) == "-:--:--"
    assert common.remaining_text(3725.0) == "1:02:05"
    assert common.remaining_text(74.2) == "0:01:15"  # rounded up, as rich does
