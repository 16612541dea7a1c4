"""The user's model (a model config as plain data) run on measured runs, with probes of its insides.

``diagnose`` simulates the model exactly as ``nlsid simulate`` would (the same validation, the same
engine), noise-free, on the measured excitation: in open loop on the recorded plant input ``u``, in
closed loop (a ``closed_loop:`` section) on the recorded reference ``r``. A periodic run without
transient periods is simulated in its periodic steady state, as it was measured
(:func:`nlsid.simulate.engine.lead_periods`), and an arbitrary record from the initial state fitted
to its measured output (:mod:`nlsid.simulate.initial_state`; the probes below from rest). Extensions of the model
are new config data (:mod:`nlsid.diagnose.hypotheses`) and run through the same path, so an
extended model YAML that ``diagnose`` writes is what ``simulate`` runs.

Two probes serve the evidence and the signature estimates:

- :meth:`ModelRunner.internal`: the model's position and velocity of its driven mass (mechanical
  templates), by running a copy of the config whose ``output`` is that signal;
- :meth:`ModelRunner.response`: the response of the recorded output to a disturbance added at the
  plant input (``process``) or to the measured output (``output``) with the excitation set to zero.
  For a linear model this is the exact small-signal sensitivity of the output to a force (or input
  error) at the actuator and to an output error, in open loop (G d) and in closed loop (the loop's
  input and output sensitivities), because the engine adds ``process`` to the held plant input
  after the dead time and the controller reads the output with ``y_noise`` added. A nonlinear model
  (forces, blocks: an extended model in a later round of the diagnosis) responds differently where
  it is: at rest a friction force holds the mass against a small disturbance, so the response from
  rest would be zero. Its response is taken along its own trajectory, a finite difference with a
  disturbance of RESPONSE_STEP times the signal's rms (the first-order sensitivity where the model
  is smooth, a secant across the friction's events).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from nlsid.errors import InputError
from nlsid.io.run import Run

MECHANICAL = ("mass_spring_damper", "two_mass_stage")
RESPONSE_STEP = 1e-3  # a disturbance's size, relative to the signal it acts on, for a nonlinear model's response
LTI = ("transfer_function", "zpk", "state_space")


@dataclass(frozen=True)
class ModelRunner:
    """A validated model config and its simulation objects (``data`` is the config as plain data)."""

    data: dict
    source: str
    config: object
    plant: object
    loop: object
    trajectories: dict = field(default_factory=dict, compare=False, repr=False)  # id(run) -> (run, y): :meth:`_along`

    @classmethod
    def from_data(cls, data: dict, source: str) -> "ModelRunner":
        """Validate ``data`` as a model config (errors name ``source``) and build the model."""
        from nlsid.io.model_config import validate_simulate_config
        from nlsid.models import from_config

        config = validate_simulate_config(data, source, {})
        if config.sweep is not None:
            raise InputError(f"{source}: sweep", "diagnose compares one model with the data; remove the sweep")
        try:
            return cls(data, source, config, from_config.model(config), from_config.closed_loop(config))
        except InputError as exc:
            raise InputError(source, f"{exc.where}: {exc.what}") from None

    @property
    def kind(self) -> str:
        return self.config.model.type

    @property
    def closed(self) -> bool:
        return self.loop is not None

    @property
    def mechanical(self) -> bool:
        return self.kind in MECHANICAL

    def excitation(self, run: Run) -> Run:
        """The run the engine needs: u is the excitation (the reference r in closed loop); a range
        part is simulated as the record it was cut from (:func:`nlsid.io.ranges.record`)."""
        from nlsid.io.ranges import record
        from nlsid.simulate.loop_state import loop_excitation

        run = record(run)
        if not self.closed:
            return dataclasses.replace(run, r=None)
        if run.r is None:
            raise InputError(f"run {run.run_id}", "the model has a closed_loop section but the run records "
                                                  "no reference r")
        return loop_excitation(run)  # the recorded command kept for the loop's initial state (nlsid.simulate.loop_state)

    def simulate(self, run: Run, process: np.ndarray | None = None, output: np.ndarray | None = None,
                 excite: bool = True) -> Run:
        """The model's noise-free response to ``run`` (plus the optional disturbances, see module)."""
        from nlsid.simulate.runs import simulate_run
        from nlsid.simulate.noise import Noise

        source = self.excitation(run)
        if not excite:  # a probe from rest: no initial state fitted to the measured output
            source = dataclasses.replace(source, u=np.zeros_like(source.u), y=None)
        zero = np.zeros(run.n_samples)
        noise = Noise(zero, zero if output is None else output, zero if process is None else process)
        try:
            return simulate_run(self.plant, self.loop, source, self.config.simulation.substeps, noise, steady=True)
        except InputError as exc:
            raise InputError(self.source, f"run {run.run_id}: {exc.where}: {exc.what}") from None

    def simulate_each(self, runs: list[Run], signal: str = "y") -> list[np.ndarray]:
        """The simulated ``signal`` of every run (:meth:`simulate`): the output ``y``, or in closed
        loop ``u``, the plant input as the simulated controller computes it; in parallel threads
        (:func:`~nlsid.simulate.threads.in_threads`)."""
        from nlsid.simulate.threads import in_threads

        return in_threads(lambda run: getattr(self.simulate(run), signal), runs)

    def initial_state(self, run: Run):
        """The initial state fitted to the start of an arbitrary record as the model simulates it
        (:func:`nlsid.simulate.runs.fitted_initial_state`: a plant's, a closed loop's with its drive,
        a block structure's filters', a model written as equations' states), None where none is
        fitted (a periodic run, a mode too slow for the record)."""
        from nlsid.simulate.runs import fitted_initial_state

        try:
            return fitted_initial_state(self.plant, self.loop, self.excitation(run), self.config.simulation.substeps)
        except InputError as exc:
            raise InputError(self.source, f"run {run.run_id}: {exc.where}: {exc.what}") from None

    def response(self, run: Run, process: np.ndarray | None = None, output: np.ndarray | None = None,
                 signal: str = "y") -> np.ndarray:
        """Response of the recorded ``signal`` (the output ``y``, or in closed loop the command
        ``u``, through the loop) to a plant-input and/or output disturbance: of a linear model
        with the excitation zero (less the response to the model's own offsets and input
        channels, when it has any); of a nonlinear one along its own trajectory
        (:meth:`_along`)."""
        if self.nonlinear:
            return self._along(run, process, output, signal)
        x = getattr(self.simulate(run, process, output, excite=False), signal)
        if self.has_offsets:
            x = x - getattr(self.simulate(run, excite=False), signal)
        return x

    @property
    def nonlinear(self) -> bool:
        """The model has forces, blocks or a block structure: its response to a disturbance
        depends on where it is (a friction force at rest holds the mass against a small one)."""
        from nlsid.models import blocks
        from nlsid.models.from_config import Plant

        if not isinstance(self.plant, Plant):
            return True
        identity = blocks.encode(None)[0]
        return bool(self.plant.forces) or self.plant.input_block[0] != identity or self.plant.output_block[0] != identity

    def _along(self, run: Run, process: np.ndarray | None, output: np.ndarray | None, signal: str = "y") -> np.ndarray:
        """The first-order response of a nonlinear model's ``signal`` to the disturbances along
        its own trajectory on ``run``: for each disturbance d (scaled to RESPONSE_STEP times the
        rms of the excitation, respectively of the model's output, that scale s divided out
        again), (x(u; s d) - x(u)) / s, summed. Simulated as the model runs on ``run`` (its
        periodic steady state), from rest where the record is arbitrary. The trajectory of each
        run is simulated once per model (a signature's scan asks for many disturbances on the
        same runs)."""
        quiet = dataclasses.replace(run, y=None)
        kept = self.trajectories.get(id(run))
        if kept is None or kept[0] is not run:
            kept = self.trajectories[id(run)] = (run, self.simulate(quiet))
        nominal = kept[1]
        total = np.zeros(run.n_samples)
        for name, disturbance, reference in (("process", process, self.excitation(run).u),
                                             ("output", output, nominal.y)):
            size = _rms(disturbance) if disturbance is not None else 0.0
            if size == 0:
                continue
            scale = RESPONSE_STEP * (_rms(reference) or 1.0) / size
            moved = self.simulate(quiet, **{name: scale * disturbance})
            total += (getattr(moved, signal) - getattr(nominal, signal)) / scale
        return total

    @property
    def has_offsets(self) -> bool:
        """The model moves without excitation: offsets or measured channels at its input or output,
        or channels its drive adds to its command."""
        m, loop = self.config.model, self.config.closed_loop
        return bool(m.input_offset or m.output_offset or getattr(m, "force_offset", 0.0) or m.input_channels
                    or (loop is not None and loop.excitation_channels))

    def internal(self, run: Run) -> dict[str, np.ndarray]:
        """Signals inside the model on ``run``: ``input`` (the plant input), and for a mechanical
        template ``position`` and ``velocity`` of the driven mass where they can be had.

        Open loop: by running copies of the config that output them (exact). Closed loop: changing
        the output would change the loop, so they come from the model's own output when it is the
        driven mass's: the position itself and its central-difference derivative as the velocity
        (its zero crossings, which friction depends on, are not delayed), or the velocity alone.
        """
        nominal = self.simulate(run)
        out = {"input": nominal.u}
        if not self.mechanical:
            return out
        if not self.closed:
            for signal in ("position", "velocity"):  # from rest: the measured y is not this signal
                out[signal] = self.with_changes(_probe(self.data, signal)).simulate(dataclasses.replace(run, y=None)).y
            return out
        model = self.config.model
        if model.type == "two_mass_stage" and model.output_at != "motor" or model.output_nonlinearity is not None:
            return out
        if model.output == "position":
            out["position"] = nominal.y
            out["velocity"] = np.gradient(nominal.y, 1.0 / run.fs)
        else:
            out["velocity"] = nominal.y
        return out

    def with_changes(self, data: dict) -> "ModelRunner":
        return ModelRunner.from_data(data, self.source)

    @property
    def actuator_gain(self) -> float:
        """Force per unit of plant input on the driven mass (mechanical templates)."""
        return float(self.config.model.gain)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _probe(data: dict, signal: str) -> dict:
    """A copy of ``data`` whose model outputs ``signal`` of the driven mass, without output block."""
    out = copy.deepcopy(data)
    model = out["model"]
    model["output"] = signal
    if model["type"] == "two_mass_stage":
        model["output_at"] = "motor"
    model.pop("output_nonlinearity", None)
    return out


def steady_periods(run: Run, signal: np.ndarray) -> np.ndarray:
    """The steady-state periods (P, N) of a signal of ``run``'s length: its last P periods (the
    transient periods dropped; of a range part, :mod:`nlsid.io.ranges`, its range)."""
    return signal[run.n_samples - run.n_periods * run.period:].reshape(run.n_periods, run.period)


def steady_mean(run: Run, signal: np.ndarray) -> np.ndarray:
    """The mean steady-state period (N,) of a signal of ``run``'s length."""
    return steady_periods(run, signal).mean(axis=0)
