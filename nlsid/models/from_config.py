"""Build the simulation objects from a validated model config (:mod:`nlsid.io.model_config`).

Two kinds of model come out:

* :class:`Plant`: a linear state-space plant, optionally with nonlinear forces fed back from an
  internal signal (mechanical templates, or ``nonlinear_feedback`` around any LTI from force to
  position) and with a nonlinear block at its input and at its output. It runs open loop or in a
  closed loop.
* :class:`Structure`: a block-structured model (Wiener, Hammerstein, Wiener-Hammerstein, the
  parallel LPL of seed 002 Definition 1): branches of LTI blocks and nonlinear blocks in series,
  summed. Open loop only.
* :class:`nlsid.models.equations.Equations`: a model written as equations (``type: equations``).
  Open loop only.
* :class:`nlsid.models.lti.MimoStateSpace`: a linear model of several inputs and outputs
  (``type: mimo_state_space``). Open loop only.
"""

from __future__ import annotations

import dataclasses

from dataclasses import dataclass, field
from typing import Union

import numpy as np

from nlsid.errors import InputError
from nlsid.io import model_config as mc
from nlsid.models import blocks, equations, forces
from nlsid.models.blocks import StaticBlock, static_block
from nlsid.models.controller import pid
from nlsid.models.hybrid import Hybrid
from nlsid.models.lti import (MimoStateSpace, StateSpace, check_stable, from_matrices, from_transfer_function,
                              from_zpk)
from nlsid.models.mechanical import MechanicalPlant, force_feedback, mass_spring_damper, two_mass_stage, with_points


@dataclass(frozen=True)
class Force:
    """A nonlinear force: its kernel encoding, the column it enters by and the row it reads."""

    kind: int
    params: np.ndarray
    column: np.ndarray
    row: np.ndarray
    difference: bool = False  # the row is a backward difference per sample (times fs: a velocity)
    output: float = 0.0  # its direct term in the output, y = ... - output F (an acceleration output)


@dataclass(frozen=True)
class Offsets:
    """Constant and measured terms at a model's input and output (:class:`nlsid.io.model_config._Offsets`):
    the plant gets u + input + sum gain * run.channels[name]; the recorded y is the output + output.
    ``zero_if_absent``: the channels a run may lack (taken as zero there; the others are required)."""

    input: float = 0.0
    output: float = 0.0
    channels: dict[str, float] = field(default_factory=dict)
    zero_if_absent: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Plant:
    """A state-space plant with forces fed back, and the blocks (kind, parameters) of
    :mod:`nlsid.models.blocks` at its input and output (identity by default).

    ``force_bias`` is a constant added to the plant input after the input block (a mechanical
    template's ``force_offset`` / ``gain``: a constant force on the driven mass); ``output_timing``
    the sampling instant of the output in samples (y[k] = y(t_k + t Ts)); ``difference_rows``:
    the velocity read-outs (and a velocity output) are backward differences per sample, to be
    multiplied by fs (a discrete linear part, :func:`nlsid.models.mechanical.force_feedback`).
    """

    ss: StateSpace
    x0: np.ndarray
    forces: list[Force] = field(default_factory=list)
    input_block: tuple[int, np.ndarray] = field(default_factory=lambda: blocks.encode(None))
    output_block: tuple[int, np.ndarray] = field(default_factory=lambda: blocks.encode(None))
    offsets: Offsets = field(default_factory=Offsets)
    force_bias: float = 0.0
    output_timing: float = 0.0
    difference_output: bool = False


Stage = Union[StateSpace, StaticBlock]


@dataclass(frozen=True)
class Structure:
    """Sum over branches of the series connection of each branch's stages (applied left to right)."""

    branches: list[list[Stage]]
    offsets: Offsets = field(default_factory=Offsets)


@dataclass(frozen=True)
class ClosedLoop:
    """The drive's computation (:mod:`nlsid.models.controller`):
    u = C(e) - M(y) + u_ff + sum gain * run.channels[name], e = F(r) - y.

    ``controller`` and ``measurement`` are stages in series (state-space models, continuous ones
    run as their Tustin equivalent, or the name of a velocity estimate of
    :func:`nlsid.models.controller.difference`); ``measurement`` is empty without terms on y.
    ``excitation``: the measured channels added to the drive's output (channel name: gain), of which
    a run may lack those in ``excitation_zero_if_absent`` (taken as zero there).
    """

    controller: list
    coulomb: float
    velocity: float
    measurement: list = field(default_factory=list)
    prefilter: StateSpace | None = None
    computation_delay: int = 0
    excitation: dict[str, float] = field(default_factory=dict)
    excitation_zero_if_absent: frozenset[str] = frozenset()


def channels(entries: dict) -> tuple[dict[str, float], frozenset[str]]:
    """(name: gain, the names a run may lack) of a config's channel entries
    (:data:`nlsid.io.model_config.Channel`: a gain, or ``{gain, absent}``)."""
    return ({name: mc.channel_gain(entry) for name, entry in entries.items()},
            frozenset(name for name, entry in entries.items() if mc.absent_as_zero(entry)))


def lti(config, where: str) -> StateSpace:
    """A generic LTI config (transfer function, zpk, state space) as a state-space model."""
    discrete = config.domain == "discrete"
    if config.type == "transfer_function":
        ss = from_transfer_function(config.num, config.den, discrete, config.delay, where)
    elif config.type == "zpk":
        ss = from_zpk(config.zeros, config.poles, config.gain, discrete, config.delay, where)
    else:
        ss = from_matrices(config.A, config.B, config.C, config.D, discrete, config.delay, where)
    return dataclasses.replace(ss, fs=config.fs) if config.fs is not None else ss


def _mechanical(config, where: str) -> MechanicalPlant:
    if config.type == "nonlinear_feedback":
        G = lti(config.linear, f"{where}.linear")
        plant = force_feedback(G, config.gain, config.output, config.delay, where)
        if config.points and (config.linear.type != "state_space" or G.discrete):
            raise InputError(f"{where}.points", "needs a continuous state_space linear part (the points are given "
                                                "in its state coordinates)")
        if G.D != 0:  # an acceleration output: no force where u enters (mechanical.py)
            if not config.points:
                raise InputError(f"{where}.linear", "the linear part must be strictly proper (D = 0), or with its "
                                                    "direct feedthrough (an acceleration output) have its forces at "
                                                    "points (model.points)")
            for i, force in enumerate(config.nonlinearities):
                if (force.at or "plant") == "plant":
                    raise InputError(f"{where}.nonlinearities[{i}].at",
                                     "the linear part has a direct feedthrough D: a force where u enters would reach "
                                     "the output through D in the instant it is read; expected one of the points "
                                     f"({', '.join(config.points)})")
        points = {name: (p.force, p.position, p.feedthrough) for name, p in config.points.items()}
        return with_points(plant, G.A, points, where) if points else plant
    if config.type == "mass_spring_damper":
        return mass_spring_damper(config.mass, config.damping, config.stiffness, config.gain, config.output,
                                  config.initial.position, config.initial.velocity, config.delay)
    return two_mass_stage(config.motor_mass, config.load_mass, config.stiffness, config.damping,
                          config.motor_damping, config.load_damping, config.gain, config.output,
                          config.output_at, config.delay)


def _force(config, plant: MechanicalPlant, where: str) -> Force:
    at = config.at or plant.masses[0]
    if at not in plant.force_columns:
        raise InputError(f"{where}.at", f"expected one of {', '.join(plant.masses)}, got {at!r}")
    kind, params = forces.encode(config)
    position = kind in forces.POSITION_KINDS
    rows = plant.position_rows if position else plant.velocity_rows
    if at not in rows:
        raise InputError(where, f"a {config.type} force reads the velocity, which "
                         + (plant.no_velocity or "needs a linear part of relative degree >= 2 (force to position; C B = 0)"))
    return Force(kind, params, plant.force_columns[at], rows[at], plant.difference and not position,
                 plant.force_outputs.get(at, 0.0))


def _offsets(config) -> Offsets:
    return Offsets(config.input_offset, config.output_offset, *channels(config.input_channels))


def _force_bias(config, where: str) -> float:
    """force_offset / gain: the constant force as a term of the plant input (which enters by gain)."""
    if not config.force_offset:
        return 0.0
    if config.gain == 0:
        raise InputError(f"{where}.force_offset", "needs a nonzero gain (the force enters where the actuator does)")
    return config.force_offset / config.gain


MECHANICAL = ("mass_spring_damper", "two_mass_stage", "nonlinear_feedback")


def plant(config, closed: bool) -> Plant:
    """The plant of an LTI or mechanical config; a plant without forces in open loop must be stable."""
    where = "model"
    ends = dict(input_block=blocks.encode(config.input_nonlinearity),
                output_block=blocks.encode(config.output_nonlinearity),
                offsets=_offsets(config), output_timing=config.output_timing)
    if config.type in MECHANICAL:
        mech = _mechanical(config, where)
        elements = [_force(f, mech, f"{where}.nonlinearities[{i}]") for i, f in enumerate(config.nonlinearities)]
        result = Plant(mech.ss, mech.x0, elements, force_bias=_force_bias(config, where),
                       difference_output=mech.difference and config.output == "velocity", **ends)
    else:
        ss = lti(config, where)
        result = Plant(ss, np.zeros(ss.order), **ends)
    if result.output_timing and result.ss.discrete:
        raise InputError(f"{where}.output_timing", "a discrete model has no values between its samples; "
                                                   "output_timing needs a continuous one")
    if not closed and not result.forces:
        check_stable(result.ss, where)
    return result


def _stage_lti(config, where: str) -> StateSpace:
    ss = lti(config, where)
    check_stable(ss, where)
    return ss


def structure(config) -> Structure:
    """The block structure of a wiener / hammerstein / wiener_hammerstein / lpl config."""
    where = "model"
    offsets = _offsets(config)
    if config.type == "wiener":
        return Structure([[_stage_lti(config.linear, f"{where}.linear"), static_block(config.nonlinear)]], offsets)
    if config.type == "hammerstein":
        return Structure([[static_block(config.nonlinear), _stage_lti(config.linear, f"{where}.linear")]], offsets)
    if config.type == "wiener_hammerstein":
        return Structure([[_stage_lti(config.first, f"{where}.first"), static_block(config.nonlinear),
                           _stage_lti(config.second, f"{where}.second")]], offsets)
    branches = []
    for i, branch in enumerate(config.branches):
        stages: list[Stage] = []
        if branch.before is not None:
            stages.append(_stage_lti(branch.before, f"{where}.branches[{i}].before"))
        stages.append(static_block(branch.nonlinear))
        if branch.after is not None:
            stages.append(_stage_lti(branch.after, f"{where}.branches[{i}].after"))
        branches.append(stages)
    return Structure(branches, offsets)


STRUCTURES = ("wiener", "hammerstein", "wiener_hammerstein", "lpl")


def model(config: mc.SimulateConfig) -> Union[Plant, Structure, equations.Equations, MimoStateSpace]:
    """The plant, structure or equations model of a whole config (a PNLSS model,
    :class:`nlsid.models.pnlss.Pnlss`; a hybrid one, :class:`nlsid.models.hybrid.Hybrid`; one of
    several inputs and outputs, :class:`MimoStateSpace`)."""
    if config.model.type == "pnlss":
        if config.closed_loop is not None:
            raise InputError("closed_loop", "a closed loop needs an LTI or mechanical plant, not a pnlss model")
        from nlsid.models.pnlss import build

        return build(config.model)
    if config.model.type == "hybrid":  # a physical model with a PNLSS term in parallel
        return hybrid(config)
    if config.model.type == "equations":
        if config.closed_loop is not None:
            raise InputError("closed_loop", "a closed loop needs an LTI or mechanical plant, not an equations model "
                                            "(write the controller into the equations, reading r)")
        if config.model.updates is not None and config.simulation.substeps not in (None, 1):
            raise InputError("simulation.substeps", "a discrete-time model runs one step per sample; remove substeps")
        return equations.build(config.model, _offsets(config.model))
    if config.model.type == "mimo_state_space":
        if config.closed_loop is not None:
            raise InputError("closed_loop", "a closed loop needs a plant of one input u and one output y, not a "
                                            "mimo_state_space model")
        if config.simulation.substeps not in (None, 1):
            raise InputError("simulation.substeps", "a linear model runs exactly for an input held between samples, "
                                                    "one step per sample; remove substeps")
        return mimo_state_space(config.model)
    if config.model.type in STRUCTURES:
        if config.closed_loop is not None:
            raise InputError("closed_loop", f"a closed loop needs an LTI or mechanical plant, not a {config.model.type} structure")
        return structure(config.model)
    return plant(config.model, closed=config.closed_loop is not None)


def mimo_state_space(config: mc.MimoStateSpaceConfig, where: str = "model") -> MimoStateSpace:
    """The :class:`MimoStateSpace` of a validated ``mimo_state_space`` block (its shapes checked by
    the schema; D zeros where not given, the default names where none are given); an unstable
    model is refused (:func:`nlsid.models.lti.check_stable`: it runs open loop)."""
    A, B, C = (np.asarray(getattr(config, name), dtype=float) for name in ("A", "B", "C"))
    D = np.zeros((C.shape[0], B.shape[1])) if config.D is None else np.asarray(config.D, dtype=float)
    out = MimoStateSpace(A, B, C, D, config.domain, config.fs, tuple(config.input_names),
                         tuple(config.output_names), config.delay,
                         {name: static_block(c) for name, c in config.input_nonlinearity.items()},
                         {name: static_block(c) for name, c in config.output_nonlinearity.items()})
    check_stable(out, where)
    return out


def _controller(c, where: str) -> StateSpace:
    """One linear controller config (pid or an LTI without dead time) as a state-space model."""
    if c.type == "pid":
        return pid(c.kp, c.ki, c.kd, c.tau)
    if c.delay:
        raise InputError(f"{where}.delay", "a controller has no dead time; put it on closed_loop.computation_delay")
    return lti(c, where)


def closed_loop(config: mc.SimulateConfig) -> ClosedLoop | None:
    """The drive's computation of a closed-loop config (None in open loop).

    A cascade u = C_v(C_p(e) - v_hat) is the two-degree-of-freedom law with C = C_v C_p on the
    error and M = C_v D on the measurement, D the velocity estimate: the same numbers, sample by
    sample, as the drive's nested computation (the loops are linear).
    """
    loop = config.closed_loop
    if loop is None:
        return None
    if not isinstance(loop.computation_delay, int):  # auto: a choice among whole numbers that needs data
        raise InputError("closed_loop.computation_delay", "auto is estimated from measured data (nlsid fit --model, "
                                                          "nlsid diagnose); to simulate, give a whole number of samples")
    where = "closed_loop.controller"
    c = loop.controller
    measurement = []
    if c.type == "cascade":
        inner = _controller(c.velocity, f"{where}.velocity")
        error = [_controller(c.position, f"{where}.position"), inner]
        measurement = [c.velocity_estimate, inner]
    else:
        error = [_controller(c, where)]
        if loop.measurement is not None:
            measurement = [_controller(loop.measurement, "closed_loop.measurement")]
    prefilter = None
    if loop.prefilter is not None:
        prefilter = _stage_lti(loop.prefilter, "closed_loop.prefilter")
        if prefilter.delay:
            raise InputError("closed_loop.prefilter.delay", "a prefilter has no dead time")
    return ClosedLoop(error, loop.feedforward.coulomb, loop.feedforward.velocity, measurement, prefilter,
                      loop.computation_delay, *channels(loop.excitation_channels))


def hybrid(config: mc.SimulateConfig) -> Hybrid:
    """The :class:`Hybrid` of a validated :class:`nlsid.io.model_config.SimulateConfig` whose model
    is a :class:`~nlsid.io.model_config.HybridConfig` (open loop only). An error in either part
    names its key under ``model.physical`` or ``model.black_box``."""
    from nlsid.models import pnlss

    if config.closed_loop is not None:
        raise InputError("closed_loop", "a closed loop needs an LTI or mechanical plant, not a hybrid model")
    physical_config = config.model_copy(update={"model": config.model.physical})
    try:
        physical = model(physical_config)
    except InputError as exc:
        where = exc.where
        where = "model.physical" + where[len("model"):] if where.startswith("model") else where
        raise InputError(where, exc.what) from None
    return Hybrid(physical, pnlss.build(config.model.black_box, "model.black_box"))
