"""Schemas of the model / simulation YAML read by ``nlsid simulate`` (``docs/configs.md``).

A model config has one required key, ``model``, and optional ``closed_loop``, ``disturbances``,
``sweep``, ``simulation`` and ``free`` (parameters that ``nlsid fit --model`` estimates). Every block is a mapping with a ``type`` key (a pydantic
discriminated union), so a typo in a type or a key is reported with its line number by
:func:`nlsid.io.config.load_config`.

Sign conventions checked here (a wrong sign is an :class:`~nlsid.errors.InputError`): masses,
friction levels, Stribeck velocities and LuGre stiffness are > 0; viscous and LuGre damping
coefficients are >= 0. A linear stiffness may be negative (an unstable spring, as in the Duffing
system of the book's Exercise 79, Eq. 5-12) and a cubic stiffness may be negative (softening).
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal, Optional, Union

from pydantic import BeforeValidator, ConfigDict, Discriminator, Field, Tag, field_validator, model_validator

from nlsid.errors import InputError
from nlsid.io import config as config_loader
from nlsid.io.config import StrictModel


class FiniteModel(StrictModel):
    """Base of every block of a model config: each number is finite. YAML's ``.nan``, ``.inf`` and
    ``-.inf`` are refused at the key that holds them (with its line), wherever the number sits (a
    coefficient, a root, a matrix entry, a gain, an initial state, a sweep value): past the loader a
    non-finite coefficient ends in a failed root finding or a diverged simulation that names no key.
    Only the bounds of a ``free`` parameter may be infinite (an infinite bound is no bound)."""

    model_config = ConfigDict(allow_inf_nan=False)

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
Domain = Literal["continuous", "discrete"]


class _LTIBase(FiniteModel):
    domain: Domain = "continuous"
    delay: NonNegative = 0.0  # dead time in seconds, a whole number of samples at the run's fs
    fs: Optional[Positive] = None  # a discrete model's sample rate (Hz): runs at another rate are refused

    @model_validator(mode="after")
    def _rate_of_discrete(self):
        if self.fs is not None and self.domain != "discrete":
            raise ValueError("fs is the sample rate a discrete model's z refers to; a continuous model runs at "
                             "any rate: remove fs, or set domain: discrete")
        return self


class TransferFunctionConfig(_LTIBase):
    """Continuous: ``num``/``den`` in descending powers of s. Discrete: ascending powers of z^-1."""

    type: Literal["transfer_function"]
    num: list[float] = Field(min_length=1)
    den: list[float] = Field(min_length=1)


class ModeRoots(FiniteModel):
    """A pair of roots given as a mode of natural ``frequency`` f (Hz) and ``damping`` ratio zeta:
    the roots of s^2 + 2 zeta w s + w^2, w = 2 pi f (a conjugate pair for zeta < 1, two real
    roots from zeta = 1 on). In a zpk it enters as the factor (s^2 + 2 zeta w s + w^2) / w^2, of
    unit gain at s = 0, so that moving a mode leaves the low-frequency gain alone."""

    frequency: Positive
    damping: NonNegative


def _root_shape(entry) -> str:
    return "mode" if isinstance(entry, dict) else "pair" if isinstance(entry, list) else "number"


# A zpk root, told apart by its shape so that a bad entry gets the one error of what it looks like
Root = Annotated[Union[Annotated[float, Tag("number")],
                       Annotated[list[float], Field(min_length=2, max_length=2), Tag("pair")],
                       Annotated[ModeRoots, Tag("mode")]], Discriminator(_root_shape)]


class ZPKConfig(_LTIBase):
    """Zeros and poles: a number is a real root, ``[re, im]`` the conjugate pair re +- j im, and
    ``{frequency, damping}`` a mode (:class:`ModeRoots`, continuous models only); each root
    contributes the factor (s - root), each mode its unit-DC-gain factor, times ``gain``."""

    type: Literal["zpk"]
    zeros: list[Root] = []
    poles: list[Root] = []
    gain: float

    @model_validator(mode="after")
    def _modes_continuous(self):
        if self.domain == "discrete" and any(isinstance(r, ModeRoots) for r in [*self.zeros, *self.poles]):
            raise ValueError("a {frequency, damping} mode needs a continuous zpk (its frequency is in Hz of "
                             "continuous time); give a discrete zpk's roots as numbers or [re, im] pairs in z")
        return self


class StateSpaceConfig(_LTIBase):
    """SISO state space x' = A x + B u (or x[k+1] = ...), y = C x + D u."""

    type: Literal["state_space"]
    A: list[list[float]]
    B: list[float]
    C: list[float]
    D: float = 0.0


LTIConfig = Annotated[Union[TransferFunctionConfig, ZPKConfig, StateSpaceConfig], Field(discriminator="type")]


def _matrix(rows: list[list[float]], n_rows: int | None, n_columns: int | None, what: str) -> list[list[float]]:
    """Check that ``rows`` is a matrix of ``n_rows`` rows of ``n_columns`` numbers each (None: any
    count, at least one, the same in every row); ``what`` says what the rows and columns stand for."""
    if not rows:
        raise ValueError(f"expected a matrix ({what}), got no rows")
    if n_rows is not None and len(rows) != n_rows:
        raise ValueError(f"expected {n_rows} rows ({what}), got {len(rows)}")
    lengths = sorted({len(row) for row in rows})
    width = n_columns if n_columns is not None else len(rows[0])
    if lengths != [width] or width == 0:
        raise ValueError(f"expected {width or 'at least one'} numbers in every row ({what}), got row lengths "
                         f"{[len(row) for row in rows]}")
    return rows


class MimoStateSpaceConfig(_LTIBase):
    """A linear model of several inputs and outputs: x' = A x + B u (or x[k+1] = ...), y = C x + D u
    with u = (inputs[0], inputs[1], ...) and y = (outputs[0], ...), the signals of a recording's run
    (``docs/configs.md``, ``docs/mimo.md``). A is n x n, B n x n_u, C n_y x n, D n_y x n_u
    (default zeros); ``inputs`` default to u, u2, ..., ``outputs`` to y, y2, ...; the first of each
    is u (y), the others channel names, no name twice."""

    type: Literal["mimo_state_space"]
    A: list[list[float]]
    B: list[list[float]]
    C: list[list[float]]
    D: Optional[list[list[float]]] = None
    inputs: Optional[list[str]] = None
    outputs: Optional[list[str]] = None
    # static blocks per signal: input name -> f_a on that input before B, output name -> f_i after C x + D u
    input_nonlinearity: dict[str, BlockConfig] = {}
    output_nonlinearity: dict[str, BlockConfig] = {}

    @field_validator("A")
    @classmethod
    def _square(cls, rows):
        return _matrix(rows, len(rows), len(rows), "A is square: n rows of n numbers, n the states")

    @field_validator("B")
    @classmethod
    def _input_columns(cls, rows, info):
        n = len(info.data["A"]) if "A" in info.data else None
        return _matrix(rows, n, None, f"B is n x n_u: {n if n is not None else 'n'} rows (one per state of A), "
                                      "one column per input")

    @field_validator("C")
    @classmethod
    def _output_rows(cls, rows, info):
        n = len(info.data["A"]) if "A" in info.data else None
        return _matrix(rows, None, n, f"C is n_y x n: one row per output, {n if n is not None else 'n'} numbers "
                                      "(one per state of A) in each")

    @field_validator("D")
    @classmethod
    def _feedthrough(cls, rows, info):
        if rows is None:
            return rows
        n_y = len(info.data["C"]) if "C" in info.data else None
        n_u = len(info.data["B"][0]) if "B" in info.data else None
        return _matrix(rows, n_y, n_u, f"D is n_y x n_u: {n_y if n_y is not None else 'n_y'} rows (one per row "
                                       f"of C), {n_u if n_u is not None else 'n_u'} columns (one per column of B)")

    @field_validator("inputs")
    @classmethod
    def _input_names(cls, names, info):
        if names is not None:
            count = len(info.data["B"][0]) if "B" in info.data else None
            _signal_names(names, "u", count, "the columns of B")
        return names

    @field_validator("outputs")
    @classmethod
    def _output_names(cls, names, info):
        if names is not None:
            count = len(info.data["C"]) if "C" in info.data else None
            _signal_names(names, "y", count, "the rows of C")
            both = sorted(set(names) & set(info.data.get("inputs") or ()))
            if both:
                raise ValueError(f"{both[0]!r} is an input too; give each signal one name")
        return names

    @field_validator("input_nonlinearity", "output_nonlinearity")
    @classmethod
    def _signal_blocks(cls, blocks, info):
        kind, first, rows = (("input", "u", "B") if info.field_name == "input_nonlinearity" else ("output", "y", "C"))
        names = info.data.get(kind + "s")
        if names is None and rows in info.data:
            count = len(info.data["B"][0]) if rows == "B" else len(info.data["C"])
            names = default_names(first, count)
        for name, block in blocks.items():
            if names is not None and name not in names:
                raise ValueError(f"{name!r} is not an {kind} of the model (its {kind}s: {', '.join(names)})")
            if block.type == "backlash":
                raise ValueError(f"{name}: a backlash has memory; a mimo_state_space model takes static blocks "
                                 "(polynomial, saturation, deadzone, piecewise_linear)")
        return blocks

    @property
    def n_inputs(self) -> int:
        return len(self.B[0])

    @property
    def n_outputs(self) -> int:
        return len(self.C)

    @property
    def input_names(self) -> list[str]:
        """``inputs``, or the default u, u2, ..., u<n_u>."""
        return list(self.inputs) if self.inputs is not None else default_names("u", self.n_inputs)

    @property
    def output_names(self) -> list[str]:
        """``outputs``, or the default y, y2, ..., y<n_y>."""
        return list(self.outputs) if self.outputs is not None else default_names("y", self.n_outputs)

    @model_validator(mode="after")
    def _default_names_free(self):
        if self.inputs is None or self.outputs is None:
            both = sorted(set(self.input_names) & set(self.output_names))
            if both:
                key = "inputs" if self.inputs is None else "outputs"
                raise ValueError(f"{both[0]!r} is both an input and an output (the default names of {key}); "
                                 f"give {key} other names")
        return self


def default_names(first: str, count: int) -> list[str]:
    """The default names of ``count`` inputs (``first`` u) or outputs (y): u, u2, u3, ..."""
    return [first] + [f"{first}{i}" for i in range(2, count + 1)]


def _signal_names(names: list[str], first: str, count: int | None, what: str) -> None:
    """Check a mimo model's input or output names: ``first`` (u or y) first, then names a channel
    of a recording may have (:func:`nlsid.io.run.check_channel_name`), none twice, ``count`` in all."""
    from nlsid.io.run import CHANNEL_NAME, RESERVED_CHANNEL_NAMES

    kind = "input" if first == "u" else "output"
    if not names or names[0] != first:
        raise ValueError(f"the first {kind} must be {first!r} (the run's signal {first}), got {names}")
    if len(set(names)) != len(names):
        twice = next(name for name in names if names.count(name) > 1)
        raise ValueError(f"{twice!r} is named twice")
    for name in names[1:]:
        if not CHANNEL_NAME.fullmatch(name) or name in RESERVED_CHANNEL_NAMES:
            raise ValueError(f"{name!r} cannot name a channel of a run (expected an identifier other than "
                             f"{', '.join(sorted(RESERVED_CHANNEL_NAMES))})")
    if count is not None and len(names) != count:
        raise ValueError(f"expected {count} names, one for each of {what}, got {len(names)}")


class PolynomialConfig(FiniteModel):
    """y = sum_p coefficients[p] x^p, p = 0, 1, 2, ... (any degree, odd and even terms)."""

    type: Literal["polynomial"]
    coefficients: list[float] = Field(min_length=1)


class SaturationConfig(FiniteModel):
    type: Literal["saturation"]
    lower: float
    upper: float

    @model_validator(mode="after")
    def _order(self):
        if not self.lower < self.upper:
            raise ValueError(f"lower ({self.lower}) must be < upper ({self.upper})")
        return self


class DeadzoneConfig(FiniteModel):
    type: Literal["deadzone"]
    lower: float = Field(le=0)
    upper: float = Field(ge=0)


class PiecewiseLinearConfig(FiniteModel):
    """Straight lines through (x[i], y[i]), extended beyond the ends by the end segments."""

    type: Literal["piecewise_linear"]
    x: list[float] = Field(min_length=2)
    y: list[float] = Field(min_length=2)

    @model_validator(mode="after")
    def _points(self):
        if len(self.x) != len(self.y):
            raise ValueError(f"x has {len(self.x)} points and y has {len(self.y)}")
        if any(b <= a for a, b in zip(self.x, self.x[1:])):
            raise ValueError("x must be strictly increasing")
        return self


class BacklashConfig(FiniteModel):
    """Play operator: the output stays until the input is more than width/2 away from it."""

    type: Literal["backlash"]
    width: Positive


BlockConfig = Annotated[
    Union[PolynomialConfig, SaturationConfig, DeadzoneConfig, PiecewiseLinearConfig, BacklashConfig],
    Field(discriminator="type"),
]


class ChannelConfig(FiniteModel):
    """A measured channel of the recording added to a signal of the model: ``gain`` times the
    channel, and what a run that does not record it gets (``absent``): ``error`` (the run is refused,
    named) or ``zero`` (an all-zero channel for that run, stated where the stage reports)."""

    gain: float = 1.0
    absent: Literal["error", "zero"] = "error"


def _channel_shape(entry) -> str | None:
    if isinstance(entry, dict):
        return "mapping"
    return "gain" if isinstance(entry, (int, float, str)) else None  # str: pydantic's own number message


ChannelName = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
# A channel's entry: a number (its gain; a run without it refused) or a ChannelConfig mapping, told
# apart by its shape so that a bad entry gets the one error of what it looks like
Channel = Annotated[Union[Annotated[float, Tag("gain")], Annotated[ChannelConfig, Tag("mapping")]],
                    Discriminator(_channel_shape, custom_error_type="channel_entry",
                                  custom_error_message="expected a gain (a number) or a mapping {gain, absent}")]


def channel_gain(entry) -> float:
    """The gain of a channel entry (:data:`Channel`), validated or as loaded: a number or its ``gain``."""
    if isinstance(entry, ChannelConfig):
        return float(entry.gain)
    if isinstance(entry, dict):
        return float(entry.get("gain", 1.0))
    return float(entry)


def absent_as_zero(entry) -> bool:
    """Whether a run without the channel of ``entry`` (:data:`Channel`) gets an all-zero channel."""
    if isinstance(entry, ChannelConfig):
        return entry.absent == "zero"
    return isinstance(entry, dict) and entry.get("absent") == "zero"


class _Offsets(FiniteModel):
    """Converter offsets of every model: the plant gets u + ``input_offset`` (a DAC or actuator
    offset; the recorded u stays the command) and the recorded y is the model output +
    ``output_offset`` (a sensor offset, seen by a controller too). ``input_channels`` adds measured
    channels of the recording to the plant input: u + input_offset + sum gain * channel, each
    ``name: gain`` or ``name: {gain, absent}`` (:class:`ChannelConfig`)."""

    input_offset: float = 0.0
    output_offset: float = 0.0
    input_channels: dict[ChannelName, Channel] = {}


class _PlantBlocks(_Offsets):
    """Static or hysteretic blocks at a plant's input and output, in open and closed loop, and the
    timing of the sampled output.

    ``input_nonlinearity`` maps the plant input (the actuator: the recorded u stays the command, the
    plant gets f(u)); ``output_nonlinearity`` maps the plant output before it is recorded and fed back.
    ``output_timing`` (samples, -1 < t < 1) is when the output is sampled against the held input:
    y[k] is the model output at t_k + t Ts (t > 0: the recorded output leads).
    """

    input_nonlinearity: Optional[BlockConfig] = None
    output_nonlinearity: Optional[BlockConfig] = None
    output_timing: Annotated[float, Field(gt=-1, lt=1)] = 0.0


class TransferFunctionPlant(TransferFunctionConfig, _PlantBlocks):
    """A transfer function as the model (``model:``), with optional input and output blocks."""


class ZPKPlant(ZPKConfig, _PlantBlocks):
    """Zeros, poles and gain as the model, with optional input and output blocks."""


class StateSpacePlant(StateSpaceConfig, _PlantBlocks):
    """A state-space model as the model, with optional input and output blocks."""


def _check_sides(config, name: str, required: bool) -> None:
    """A friction quantity is given either symmetric (``name``) or per direction (``name_pos`` for
    v > 0 and ``name_neg`` for v < 0, both), never both forms and never half a pair."""
    sym, pos, neg = (getattr(config, name + suffix) for suffix in ("", "_pos", "_neg"))
    if sym is not None and (pos is not None or neg is not None):
        raise ValueError(f"give {name} or {name}_pos and {name}_neg, not both")
    if (pos is None) != (neg is None):
        given, other = (f"{name}_pos", f"{name}_neg") if pos is not None else (f"{name}_neg", f"{name}_pos")
        raise ValueError(f"{given} without {other}: give both, or {name} alone")
    if required and sym is None and pos is None:
        raise ValueError(f"give {name}, or {name}_pos and {name}_neg")


class _SidedFriction(FiniteModel):
    """Friction whose levels may differ by direction (``docs/configs.md``, Nonlinear forces)."""

    SIDED: ClassVar[tuple[tuple[str, bool], ...]] = ()  # (quantity, required); not required: 0 if not given

    @model_validator(mode="after")
    def _sides(self):
        for name, required in self.SIDED:
            if name == "fs" and getattr(self, "peak", None) is not None:  # fs = fc + peak
                if any(getattr(self, "fs" + suffix) is not None for suffix in ("", "_pos", "_neg")):
                    raise ValueError("give fs (or fs_pos and fs_neg) or peak, not both")
                continue
            _check_sides(self, name, required)
        return self

    def sides(self, name: str) -> tuple[float, float]:
        """(value for v > 0, value for v < 0) of a sided quantity: the symmetric key for both
        directions, else its ``_pos`` and ``_neg`` keys; 0 for an optional quantity not given. The
        break-away fs given as ``peak`` is fc + peak on each side."""
        if name == "fs" and getattr(self, "peak", None) is not None:
            return tuple(level + float(self.peak) for level in self.sides("fc"))
        sym = getattr(self, name)
        if sym is not None:
            return float(sym), float(sym)
        pos, neg = getattr(self, name + "_pos"), getattr(self, name + "_neg")
        return (0.0, 0.0) if pos is None else (float(pos), float(neg))


class _Levels(FiniteModel):
    """The Coulomb level, symmetric or per direction."""

    fc: Optional[Positive] = None
    fc_pos: Optional[Positive] = None
    fc_neg: Optional[Positive] = None


class _BreakAway(FiniteModel):
    """Stribeck's break-away force, symmetric or per direction, or as its excess over the sliding
    level, ``peak`` = fs - fc >= 0 on both sides (a break-away that cannot fall below sliding)."""

    fs: Optional[Positive] = None
    fs_pos: Optional[Positive] = None
    fs_neg: Optional[Positive] = None
    peak: Optional[NonNegative] = None


class _Viscous(FiniteModel):
    """The viscous coefficient, symmetric or per direction; 0 when none is given."""

    fv: Optional[NonNegative] = None
    fv_pos: Optional[NonNegative] = None
    fv_neg: Optional[NonNegative] = None


class CoulombConfig(_SidedFriction, _Levels, _Viscous):
    """Coulomb + viscous friction F = fc sign(v) + fv v on the velocity of mass ``at``; per direction
    F = fc_pos + fv_pos v (v > 0), -fc_neg + fv_neg v (v < 0), sticking within [-fc_neg, fc_pos]."""

    SIDED = (("fc", True), ("fv", False))
    type: Literal["coulomb"]
    at: Optional[str] = None


class StribeckConfig(_SidedFriction, _Levels, _BreakAway, _Viscous):
    """Stribeck friction F = (fc + (fs - fc) exp(-|v/vs|^delta)) sign(v) + fv v; fc, fs and fv may be
    given per direction (``_pos`` for v > 0, ``_neg`` for v < 0), vs and delta are common."""

    SIDED = (("fc", True), ("fs", True), ("fv", False))
    type: Literal["stribeck"]
    vs: Positive
    delta: Positive = 2.0
    at: Optional[str] = None


class LuGreConfig(_SidedFriction, _Levels, _BreakAway):
    """LuGre friction with bristle state z (Canudas de Wit et al. 1995); the levels fc, fs and the
    viscous sigma2 may be given per direction (``_pos`` for v > 0, ``_neg`` for v < 0)."""

    SIDED = (("fc", True), ("fs", True), ("sigma2", False))
    type: Literal["lugre"]
    sigma0: Positive
    sigma1: NonNegative = 0.0
    sigma2: Optional[NonNegative] = None  # 0 when neither sigma2 nor sigma2_pos / sigma2_neg is given
    sigma2_pos: Optional[NonNegative] = None
    sigma2_neg: Optional[NonNegative] = None
    vs: Positive
    at: Optional[str] = None


class CubicStiffnessConfig(FiniteModel):
    """Cubic spring force F = k3 x^3 on the position of mass ``at`` (k3 > 0 hardening, < 0 softening)."""

    type: Literal["cubic_stiffness"]
    k3: float
    at: Optional[str] = None

    @field_validator("k3")
    @classmethod
    def _nonzero(cls, value: float) -> float:
        if value == 0:
            raise ValueError("must be nonzero (> 0 hardening, < 0 softening)")
        return value


class PolynomialStiffnessConfig(FiniteModel):
    """Polynomial spring force F = k2 x^2 + k3 x^3 + ... + k10 x^10 on the position of mass ``at``:
    the terms given (each 0 when not), at least one nonzero. An even term makes the spring
    asymmetric (k2 > 0: stiffer for x > 0), an odd one hardening (> 0) or softening (< 0); the
    linear term is the model's own stiffness."""

    DEGREES: ClassVar[range] = range(2, 11)  # the kernel's parameter vector holds k2 .. k10 (forces.MAX_PARAMS)
    type: Literal["polynomial_stiffness"]
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    k5: float = 0.0
    k6: float = 0.0
    k7: float = 0.0
    k8: float = 0.0
    k9: float = 0.0
    k10: float = 0.0
    at: Optional[str] = None

    def coefficients(self) -> list[float]:
        """[k2, k3, ..., k10]."""
        return [float(getattr(self, f"k{p}")) for p in self.DEGREES]

    @model_validator(mode="after")
    def _some_term(self):
        if not any(self.coefficients()):
            raise ValueError("give at least one nonzero coefficient of k2 .. k10 (F = k2 x^2 + k3 x^3 + ...)")
        return self


class QuadraticDampingConfig(FiniteModel):
    """Quadratic damping F = c2 v |v| on the velocity of mass ``at`` (c2 > 0: a drag)."""

    type: Literal["quadratic_damping"]
    c2: Positive
    at: Optional[str] = None


class CubicDampingConfig(FiniteModel):
    """Cubic damping F = c3 v^3 on the velocity of mass ``at`` (c3 > 0)."""

    type: Literal["cubic_damping"]
    c3: Positive
    at: Optional[str] = None


class BoucWenConfig(FiniteModel):
    """Bouc-Wen hysteretic force F = k z on the velocity of mass ``at``, with the internal state
    z' = A v - beta |v| |z|^(n-1) z - gamma v |z|^n (z in position units; the elastic part alpha k x
    of the classical form alpha k x + (1 - alpha) k z is the model's own stiffness)."""

    type: Literal["bouc_wen"]
    k: Positive
    A: Positive = 1.0
    beta: Positive
    gamma: float = 0.0
    n: float = Field(1.0, ge=1.0)
    at: Optional[str] = None

    @model_validator(mode="after")
    def _bounded(self):
        if not -self.beta < self.gamma <= self.beta:
            raise ValueError(f"expected -beta < gamma <= beta (a bounded, dissipative loop), got beta = {self.beta:g}, "
                             f"gamma = {self.gamma:g}")
        return self


class EndStopConfig(FiniteModel):
    """End stops on the position p of mass ``at``: a one-sided spring and damper beyond ``upper``
    (F = max(0, stiffness (p - upper) + damping v) while p > upper) and below ``lower`` (the mirror
    image, F <= 0), either side optional."""

    type: Literal["end_stop"]
    upper: Optional[float] = None
    lower: Optional[float] = None
    stiffness: Positive
    damping: NonNegative = 0.0
    at: Optional[str] = None

    @model_validator(mode="after")
    def _sides(self):
        if self.upper is None and self.lower is None:
            raise ValueError("give upper, lower or both (the positions where the stops begin)")
        if self.upper is not None and self.lower is not None and not self.lower < self.upper:
            raise ValueError(f"expected lower < upper, got lower = {self.lower:g}, upper = {self.upper:g}")
        return self


ForceConfig = Annotated[
    Union[CoulombConfig, StribeckConfig, LuGreConfig, CubicStiffnessConfig, PolynomialStiffnessConfig,
          QuadraticDampingConfig, CubicDampingConfig, BoucWenConfig, EndStopConfig],
    Field(discriminator="type")
]


class InitialState(FiniteModel):
    position: float = 0.0
    velocity: float = 0.0


class MassSpringDamperConfig(_PlantBlocks):
    """m x'' + c x' + k x = gain u - sum of nonlinear forces."""

    type: Literal["mass_spring_damper"]
    mass: Positive
    damping: NonNegative = 0.0
    stiffness: float = 0.0
    gain: float = 1.0
    output: Literal["position", "velocity"] = "position"
    initial: InitialState = InitialState()
    nonlinearities: list[ForceConfig] = []
    delay: NonNegative = 0.0
    force_offset: float = 0.0  # a constant force on the driven mass (where the actuator acts)


class TwoMassStageConfig(_PlantBlocks):
    """Motor mass (driven) coupled to a load mass by a spring and damper (one flexible mode)."""

    type: Literal["two_mass_stage"]
    motor_mass: Positive
    load_mass: Positive
    stiffness: Positive
    damping: NonNegative = 0.0
    motor_damping: NonNegative = 0.0
    load_damping: NonNegative = 0.0
    gain: float = 1.0
    output: Literal["position", "velocity"] = "position"
    output_at: Literal["motor", "load"] = "load"
    nonlinearities: list[ForceConfig] = []
    delay: NonNegative = 0.0
    force_offset: float = 0.0  # a constant force on the driven mass (where the actuator acts)


class ForcePoint(FiniteModel):
    """A point of a ``nonlinear_feedback``'s continuous ``state_space`` where a force may act: it
    enters x' = ... - force F and reads the position ``position`` . x (a modal coordinate), and
    reaches the output directly by y = ... - feedthrough F (an acceleration output: the force
    accelerates the coordinate the output reads)."""

    force: list[float] = Field(min_length=1)
    position: list[float] = Field(min_length=1)
    feedthrough: float = 0.0


class NonlinearFeedbackConfig(_PlantBlocks):
    """Forces fed back around an LTI ``linear`` from force to position: p = G (gain u - sum F), each
    F reading p (cubic or polynomial stiffness) or the velocity v (friction): v = p' for a continuous G, the
    backward difference (p[k] - p[k-1]) fs for a discrete one."""

    type: Literal["nonlinear_feedback"]
    linear: LTIConfig
    gain: float = 1.0
    output: Literal["position", "velocity"] = "position"
    nonlinearities: list[ForceConfig] = []
    points: dict[str, ForcePoint] = {}  # further force points inside a continuous state_space (``at``)
    delay: NonNegative = 0.0
    force_offset: float = 0.0  # a constant force on the driven mass (where the actuator acts)


class WienerConfig(_Offsets):
    type: Literal["wiener"]
    linear: LTIConfig
    nonlinear: BlockConfig


class HammersteinConfig(_Offsets):
    type: Literal["hammerstein"]
    nonlinear: BlockConfig
    linear: LTIConfig


class WienerHammersteinConfig(_Offsets):
    type: Literal["wiener_hammerstein"]
    first: LTIConfig
    nonlinear: BlockConfig
    second: LTIConfig


class BranchConfig(FiniteModel):
    """One branch G-(.) -> rho -> G+(.) of the parallel LPL structure (seed 002, Definition 1)."""

    before: Optional[LTIConfig] = None
    nonlinear: BlockConfig
    after: Optional[LTIConfig] = None


class LPLConfig(_Offsets):
    type: Literal["lpl"]
    branches: list[BranchConfig] = Field(min_length=1)


def _expression_text(value):
    """An expression of :mod:`nlsid.models.expressions` as its text (a number is a constant one),
    checked for its syntax here so that an error names its key; its names are checked by
    :class:`EquationsConfig`."""
    from nlsid.models.expressions import parse

    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise ValueError(f"expected an expression (a text or a number), got {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {value!r}")
    try:
        parse(value, "")
    except ValueError as exc:  # InputError: "column C: what"
        raise ValueError(getattr(exc, "what", str(exc))) from None
    return str(value)


Name = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")]
ExpressionText = Annotated[str, BeforeValidator(_expression_text)]
StateBounds = Annotated[list[Optional[float]], Field(min_length=2, max_length=2)]


class EquationsConfig(_Offsets):
    """A grey-box model written as equations (``docs/configs.md``, "Models written as equations").

    ``states``: name -> initial value; ``parameters``: name -> value; ``derivatives`` (continuous:
    dx/dt in the recording's time unit) or ``updates`` (discrete: x[k+1]), one expression per
    state; ``output``: y as an expression; ``bounds``: state -> [lower, upper] (null: no bound),
    the state clipped into them; ``delay``: dead time of the command u in seconds (whole
    samples); ``input_nonlinearity`` and ``output_nonlinearity`` blocks as a plant has them
    (:class:`_PlantBlocks`). Expressions read the states, the parameters, ``u`` (the plant input), ``r`` and the
    recording's channels (:mod:`nlsid.models.expressions`, :mod:`nlsid.models.equations`)."""

    RESERVED: ClassVar[tuple[str, ...]] = ("u", "r")
    type: Literal["equations"]
    states: dict[Name, float] = Field(min_length=1)
    parameters: dict[Name, float] = {}
    derivatives: Optional[dict[Name, ExpressionText]] = None
    updates: Optional[dict[Name, ExpressionText]] = None
    bounds: dict[Name, StateBounds] = {}
    output: ExpressionText
    delay: NonNegative = 0.0
    input_nonlinearity: Optional[BlockConfig] = None   # on the plant input u, as a plant's
    output_nonlinearity: Optional[BlockConfig] = None  # on the output expression's value, before output_offset

    @property
    def equations(self) -> dict[str, str]:
        """State -> its expression (the derivatives, or the updates)."""
        return self.derivatives if self.derivatives is not None else self.updates

    @property
    def section(self) -> str:
        return "derivatives" if self.derivatives is not None else "updates"

    @model_validator(mode="after")
    def _consistent(self):
        from nlsid.models.expressions import FUNCTIONS

        if (self.derivatives is None) == (self.updates is None):
            raise ValueError("give derivatives (continuous time) or updates (discrete time), one of them")
        for section, names in (("states", self.states), ("parameters", self.parameters)):
            for name in names:
                if name in self.RESERVED or name in FUNCTIONS:
                    what = "a function" if name in FUNCTIONS else ("the plant input" if name == "u" else "the reference")
                    raise ValueError(f"{section}.{name}: {name!r} is {what} in expressions; choose another name")
        both = sorted(set(self.states) & set(self.parameters))
        if both:
            raise ValueError(f"parameters.{both[0]}: {both[0]!r} is a state too; give it one meaning")
        for name in self.equations:
            if name not in self.states:
                raise ValueError(f"{self.section}.{name}: no state {name!r} (states: {', '.join(self.states)})")
        missing = [name for name in self.states if name not in self.equations]
        if missing:
            raise ValueError(f"{self.section}: no expression for state {missing[0]!r}; give one per state")
        for name, (lower, upper) in self.bounds.items():
            if name not in self.states:
                raise ValueError(f"bounds.{name}: no state {name!r} (states: {', '.join(self.states)})")
            lo = -math.inf if lower is None else lower
            hi = math.inf if upper is None else upper
            if not lo < hi:
                raise ValueError(f"bounds.{name}: lower ({lo:g}) must be < upper ({hi:g})")
            if not lo <= self.states[name] <= hi:
                raise ValueError(f"states.{name}: initial value {self.states[name]:g} outside its bounds "
                                 f"[{lo:g}, {hi:g}]")
        return self


class PnlssNonlinearity(FiniteModel):
    """The form of a PNLSS model's monomials: ``full`` (of the states and u) or ``lfr`` (of the
    ``inputs`` combinations z = Cz x + Dz u; Cz, Dz default to the start rows of
    :func:`nlsid.models.pnlss.lfr_start_rows`); sizes are checked when the model is built."""

    form: Literal["full", "lfr"] = "full"
    inputs: Optional[Annotated[int, Field(ge=1)]] = None
    Cz: Optional[list[list[float]]] = None
    Dz: Optional[list[float]] = None

    @model_validator(mode="after")
    def _consistent(self):
        given = [key for key in ("inputs", "Cz", "Dz") if getattr(self, key) is not None]
        if self.form == "full" and given:
            raise ValueError(f"{given[0]} belongs to form: lfr (the full form's monomials are of the states and u)")
        if self.form == "lfr" and self.inputs is None and self.Cz is None:
            raise ValueError("form: lfr needs inputs (the number of combinations z) or Cz")
        if self.Dz is not None and self.Cz is None:
            raise ValueError("Dz needs Cz (the states' part of each combination z)")
        return self


class PnlssConfig(_Offsets):
    """A polynomial nonlinear state-space model, discrete at ``fs`` (``docs/configs.md``, "PNLSS";
    ``docs/pnlss.md``): x[t+1] = A x + B u + E zeta(x, u), y = C x + D u + F eta(x, u), zeta and
    eta the monomials of the states (and of u, ``with_input``) of total degrees ``state_degrees``
    and ``output_degrees``, or with ``nonlinearity: {form: lfr}`` of z = Cz x + Dz u. E (n rows,
    one coefficient per monomial of zeta) and F (one per monomial of eta) default to zeros; their
    sizes are checked when the model is built."""

    type: Literal["pnlss"]
    fs: Positive
    A: list[list[float]]
    B: list[float]
    C: list[float]
    D: float = 0.0
    state_degrees: list[Annotated[int, Field(ge=2)]] = []
    output_degrees: list[Annotated[int, Field(ge=2)]] = []
    with_input: bool = True
    E: Optional[list[list[float]]] = None
    F: Optional[list[float]] = None
    nonlinearity: Optional[PnlssNonlinearity] = None


ModelConfig = Annotated[
    Union[
        TransferFunctionPlant, ZPKPlant, StateSpacePlant, MassSpringDamperConfig, TwoMassStageConfig,
        NonlinearFeedbackConfig, WienerConfig, HammersteinConfig, WienerHammersteinConfig, LPLConfig,
        EquationsConfig, PnlssConfig, "HybridConfig", MimoStateSpaceConfig,
    ],
    Field(discriminator="type"),
]


class HybridConfig(FiniteModel):
    """A physical model with a black-box term in parallel (``docs/configs.md``, "Hybrid";
    ``docs/pnlss.md``): y = y_physical(u) + y_black_box(u), both driven by the same u. ``physical``
    is any model of this language but a pnlss or hybrid one (the readable part); ``black_box`` a
    pnlss model (its offsets and input channels its own), discrete at the runs' rate."""

    type: Literal["hybrid"]
    physical: ModelConfig
    black_box: PnlssConfig

    @field_validator("physical")
    @classmethod
    def _physical_part(cls, physical):
        if physical.type == "mimo_state_space":
            raise ValueError("a mimo_state_space model has several inputs or outputs; a hybrid model has one "
                             "input u and one output y")
        if physical.type in ("pnlss", "hybrid"):
            raise ValueError(f"a {physical.type} model is not a physical part; give the physical model here (a "
                             "transfer function, a mechanical template, a block structure, equations) and the PNLSS "
                             "model under black_box")
        return physical


HybridConfig.model_rebuild()


class PIDConfig(FiniteModel):
    """C(s) = kp + ki/s + kd s / (tau s + 1): P (ki = kd = 0), PD, PI or PID with derivative filter."""

    type: Literal["pid"]
    kp: float
    ki: NonNegative = 0.0
    kd: NonNegative = 0.0
    tau: NonNegative = 0.0

    @model_validator(mode="after")
    def _filter(self):
        if self.kd > 0 and self.tau <= 0:
            raise ValueError("a derivative action (kd > 0) needs a filter time constant tau > 0")
        return self


LinearControllerConfig = Annotated[
    Union[PIDConfig, TransferFunctionConfig, ZPKConfig, StateSpaceConfig], Field(discriminator="type")
]


class CascadeConfig(FiniteModel):
    """A position loop inside a velocity loop, as a drive computes it:
    u = C_v(C_p(e) - v_hat), e = r - y, v_hat a causal difference of the measured y:
    ``backward`` (y[k] - y[k-1]) fs, ``two_tap`` (y[k] - y[k-2]) fs / 2."""

    type: Literal["cascade"]
    position: LinearControllerConfig
    velocity: LinearControllerConfig
    velocity_estimate: Literal["backward", "two_tap"] = "two_tap"


ControllerConfig = Annotated[
    Union[PIDConfig, TransferFunctionConfig, ZPKConfig, StateSpaceConfig, CascadeConfig], Field(discriminator="type")
]


class FeedforwardConfig(FiniteModel):
    """u_ff = coulomb * sign(r') + velocity * r' (seed 003, Fig. 1: K_fc = coulomb); signed gains."""

    coulomb: float = 0.0
    velocity: float = 0.0


AUTO_DELAY_MAX = 3     # the largest computation delay ``auto`` tries unless told
AUTO_DELAY_LIMIT = 20  # the largest ``{auto: {max: D}}`` accepted (each candidate is a fit)


class AutoDelayConfig(FiniteModel):
    """``computation_delay: auto`` (or ``{auto: {max: D}}``): the delay estimated from measured data
    among the whole numbers 0..``max`` (:mod:`nlsid.fit.computation_delay`)."""

    max: Annotated[int, Field(ge=0, le=AUTO_DELAY_LIMIT)] = AUTO_DELAY_MAX


def _delay_or_auto(value):
    """A computation delay as written: a whole number >= 0 as it is, ``auto`` and ``{auto: {max: D}}``
    as :class:`AutoDelayConfig`; anything else refused in one message naming the three forms."""
    if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
        return value
    if value == "auto":
        return AutoDelayConfig()
    if isinstance(value, AutoDelayConfig):
        return value
    if isinstance(value, dict) and list(value) == ["auto"]:
        inner = value["auto"]
        if inner is None or inner == {}:
            return AutoDelayConfig()
        largest = inner.get("max") if isinstance(inner, dict) and list(inner) == ["max"] else None
        if isinstance(largest, int) and not isinstance(largest, bool) and 0 <= largest <= AUTO_DELAY_LIMIT:
            return AutoDelayConfig(max=largest)
    raise ValueError(f"expected a whole number of samples >= 0, auto, or {{auto: {{max: D}}}} with D a whole "
                     f"number from 0 to {AUTO_DELAY_LIMIT}; got {value!r}")


ComputationDelay = Annotated[Union[int, AutoDelayConfig], BeforeValidator(_delay_or_auto)]


class ClosedLoopConfig(FiniteModel):
    """u[k] = C(e)[k] - M(y)[k] + u_ff[k] + sum gain * channel[k], e = F(r) - y, applied after
    ``computation_delay`` samples. ``excitation_channels``: measured channels of the recording the
    drive adds to its output (an identification signal on the command; the recorded u includes
    them), each ``name: gain`` or ``name: {gain, absent}`` (:class:`ChannelConfig`)."""

    controller: ControllerConfig               # on the error e
    measurement: Optional[LinearControllerConfig] = None  # on the measured y, subtracted from u
    prefilter: Optional[LTIConfig] = None      # on the reference r before the error
    computation_delay: ComputationDelay = 0  # whole samples from u[k] to the plant input, or auto
    feedforward: FeedforwardConfig = FeedforwardConfig()
    excitation_channels: dict[ChannelName, Channel] = {}

    @model_validator(mode="after")
    def _one_measurement_path(self):
        if self.controller.type == "cascade" and self.measurement is not None:
            raise ValueError("a cascade controller already acts on the measurement (its velocity estimate); "
                             "remove measurement")
        return self


def _std_shape(entry) -> str | None:
    if isinstance(entry, list):
        return "list"
    return "number" if isinstance(entry, (int, float, str)) else None  # str: pydantic's own number message


# A noise level: one standard deviation for every signal of its kind, or (a mimo_state_space model)
# a list of one per input or output, told apart by its shape so that a bad entry gets one error
NoiseStd = Annotated[Union[Annotated[NonNegative, Tag("number")],
                           Annotated[list[NonNegative], Field(min_length=1), Tag("list")]],
                     Discriminator(_std_shape, custom_error_type="noise_std",
                                   custom_error_message="expected a standard deviation (a number), or a list of one "
                                                        "per input or output")]


class DisturbancesConfig(FiniteModel):
    """White Gaussian noise, standard deviations in the units of the signal they are added to: one
    number for every signal of its kind, or for a ``mimo_state_space`` model a list of one per input
    (``u_noise``, ``process_noise``) or output (``y_noise``), checked by :meth:`SimulateConfig.check`."""

    u_noise: NoiseStd = 0.0
    y_noise: NoiseStd = 0.0
    process_noise: NoiseStd = 0.0
    seed: Optional[Annotated[int, Field(ge=0)]] = None


class LinspaceConfig(FiniteModel):
    start: float
    stop: float
    num: Annotated[int, Field(ge=1)]


class SweepConfig(FiniteModel):
    """One run per value of the config key ``parameter`` (a dotted path such as closed_loop.feedforward.coulomb)."""

    parameter: str = Field(min_length=1)
    name: Optional[str] = None
    values: Optional[list[float]] = Field(default=None, min_length=1)
    linspace: Optional[LinspaceConfig] = None

    @model_validator(mode="after")
    def _one_source(self):
        if (self.values is None) == (self.linspace is None):
            raise ValueError("give exactly one of 'values' or 'linspace'")
        return self


class SimulationConfig(FiniteModel):
    substeps: Optional[Annotated[int, Field(ge=1)]] = None


class FreeParameterConfig(FiniteModel):
    """A config value that ``nlsid fit --model`` estimates: start value (default: the value written
    at its key path) and bounds (default: unbounded)."""

    start: Optional[float] = None
    lower: Optional[Annotated[float, Field(allow_inf_nan=True)]] = None  # -.inf: no bound, as when left out
    upper: Optional[Annotated[float, Field(allow_inf_nan=True)]] = None  # .inf: no bound

    @field_validator("lower", "upper")
    @classmethod
    def _not_nan(cls, value: Optional[float]) -> Optional[float]:
        if value is not None and math.isnan(value):
            raise ValueError("expected a number (or .inf / -.inf for no bound), got .nan")
        return value

    @model_validator(mode="after")
    def _bounds(self):
        lower = -float("inf") if self.lower is None else self.lower
        upper = float("inf") if self.upper is None else self.upper
        if not lower < upper:
            raise ValueError(f"lower ({lower}) must be < upper ({upper})")
        if self.start is not None and not lower <= self.start <= upper:
            raise ValueError(f"start ({self.start}) must lie within [lower, upper] = [{lower}, {upper}]")
        return self


class SimulateConfig(FiniteModel):
    """The whole model / simulation config file."""

    model: ModelConfig
    closed_loop: Optional[ClosedLoopConfig] = None
    disturbances: DisturbancesConfig = DisturbancesConfig()
    sweep: Optional[SweepConfig] = None
    simulation: SimulationConfig = SimulationConfig()
    free: dict[str, FreeParameterConfig] = {}  # dotted key path -> start and bounds (nlsid fit --model)

    def check(self) -> None:
        """Noise levels given per signal (lists) belong to a ``mimo_state_space`` model: one per input
        (``u_noise``, ``process_noise``) or output (``y_noise``)."""
        for key, kind in (("u_noise", "inputs"), ("y_noise", "outputs"), ("process_noise", "inputs")):
            value = getattr(self.disturbances, key)
            if not isinstance(value, list):
                continue
            if self.model.type != "mimo_state_space":
                raise config_loader.ConfigValueError(("disturbances", key), "a list of standard deviations (one per "
                                                     "signal) needs a mimo_state_space model; give one number")
            names = self.model.input_names if kind == "inputs" else self.model.output_names
            if len(value) != len(names):
                raise config_loader.ConfigValueError(("disturbances", key), f"expected {len(names)} standard "
                                                     f"deviations, one for each of the model's {kind} "
                                                     f"({', '.join(names)}), got {len(value)}")


def refuse_several_inputs_outputs(config: SimulateConfig, source: str, stage: str) -> None:
    """Refuse a ``mimo_state_space`` model in ``stage`` (e.g. ``nlsid hosidf --model``), which takes a
    model of one input u and one output y: one message at ``SOURCE: model.type``."""
    model = config.model
    if model.type != "mimo_state_space":
        return
    names = f"inputs {', '.join(model.input_names)}; outputs {', '.join(model.output_names)}"
    raise InputError(f"{source}: model.type", f"{stage} takes the models of one input u and one output y (a linear "
                                              f"one as state_space), not a mimo_state_space model ({names}); "
                                              "nlsid simulate runs it (docs/mimo.md)")


def validate_simulate_config(data, path, lines: dict) -> SimulateConfig:
    """Validate a loaded model config; errors name the file, line and key path."""
    return config_loader.validate(data, SimulateConfig, path, lines)
