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

from typing import Annotated, Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from nlsid.io import config as config_loader
from nlsid.io.config import StrictModel

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
Domain = Literal["continuous", "discrete"]


class _LTIBase(StrictModel):
    domain: Domain = "continuous"
    delay: NonNegative = 0.0  # dead time in seconds, a whole number of samples at the run's fs


class TransferFunctionConfig(_LTIBase):
    """Continuous: ``num``/``den`` in descending powers of s. Discrete: ascending powers of z^-1."""

    type: Literal["transfer_function"]
    num: list[float] = Field(min_length=1)
    den: list[float] = Field(min_length=1)


class ZPKConfig(_LTIBase):
    """Zeros and poles: a number is a real root, ``[re, im]`` the conjugate pair re +- j im."""

    type: Literal["zpk"]
    zeros: list[Union[float, Annotated[list[float], Field(min_length=2, max_length=2)]]] = []
    poles: list[Union[float, Annotated[list[float], Field(min_length=2, max_length=2)]]] = []
    gain: float


class StateSpaceConfig(_LTIBase):
    """SISO state space x' = A x + B u (or x[k+1] = ...), y = C x + D u."""

    type: Literal["state_space"]
    A: list[list[float]]
    B: list[float]
    C: list[float]
    D: float = 0.0


LTIConfig = Annotated[Union[TransferFunctionConfig, ZPKConfig, StateSpaceConfig], Field(discriminator="type")]


class PolynomialConfig(StrictModel):
    """y = sum_p coefficients[p] x^p, p = 0, 1, 2, ... (any degree, odd and even terms)."""

    type: Literal["polynomial"]
    coefficients: list[float] = Field(min_length=1)


class SaturationConfig(StrictModel):
    type: Literal["saturation"]
    lower: float
    upper: float

    @model_validator(mode="after")
    def _order(self):
        if not self.lower < self.upper:
            raise ValueError(f"lower ({self.lower}) must be < upper ({self.upper})")
        return self


class DeadzoneConfig(StrictModel):
    type: Literal["deadzone"]
    lower: float = Field(le=0)
    upper: float = Field(ge=0)


class PiecewiseLinearConfig(StrictModel):
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


class BacklashConfig(StrictModel):
    """Play operator: the output stays until the input is more than width/2 away from it."""

    type: Literal["backlash"]
    width: Positive


BlockConfig = Annotated[
    Union[PolynomialConfig, SaturationConfig, DeadzoneConfig, PiecewiseLinearConfig, BacklashConfig],
    Field(discriminator="type"),
]


class _PlantBlocks(StrictModel):
    """Static or hysteretic blocks at a plant's input and output, in open and closed loop.

    ``input_nonlinearity`` maps the plant input (the actuator: the recorded u stays the command, the
    plant gets f(u)); ``output_nonlinearity`` maps the plant output before it is recorded and fed back.
    """

    input_nonlinearity: Optional[BlockConfig] = None
    output_nonlinearity: Optional[BlockConfig] = None


class TransferFunctionPlant(TransferFunctionConfig, _PlantBlocks):
    """A transfer function as the model (``model:``), with optional input and output blocks."""


class ZPKPlant(ZPKConfig, _PlantBlocks):
    """Zeros, poles and gain as the model, with optional input and output blocks."""


class StateSpacePlant(StateSpaceConfig, _PlantBlocks):
    """A state-space model as the model, with optional input and output blocks."""


class CoulombConfig(StrictModel):
    """Coulomb + viscous friction F = fc sign(v) + fv v on the velocity of mass ``at``."""

    type: Literal["coulomb"]
    fc: Positive
    fv: NonNegative = 0.0
    at: Optional[str] = None


class StribeckConfig(StrictModel):
    """Stribeck friction F = (fc + (fs - fc) exp(-|v/vs|^delta)) sign(v) + fv v."""

    type: Literal["stribeck"]
    fc: Positive
    fs: Positive
    vs: Positive
    delta: Positive = 2.0
    fv: NonNegative = 0.0
    at: Optional[str] = None


class LuGreConfig(StrictModel):
    """LuGre friction with bristle state z (Canudas de Wit et al. 1995)."""

    type: Literal["lugre"]
    sigma0: Positive
    sigma1: NonNegative = 0.0
    sigma2: NonNegative = 0.0
    fc: Positive
    fs: Positive
    vs: Positive
    at: Optional[str] = None


class CubicStiffnessConfig(StrictModel):
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


ForceConfig = Annotated[
    Union[CoulombConfig, StribeckConfig, LuGreConfig, CubicStiffnessConfig], Field(discriminator="type")
]


class InitialState(StrictModel):
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


class NonlinearFeedbackConfig(_PlantBlocks):
    """Forces fed back around a continuous LTI ``linear`` from force to position:
    p = G(s) (gain u - sum F), each F reading p (cubic stiffness) or v = p' (friction)."""

    type: Literal["nonlinear_feedback"]
    linear: LTIConfig
    gain: float = 1.0
    output: Literal["position", "velocity"] = "position"
    nonlinearities: list[ForceConfig] = []
    delay: NonNegative = 0.0


class WienerConfig(StrictModel):
    type: Literal["wiener"]
    linear: LTIConfig
    nonlinear: BlockConfig


class HammersteinConfig(StrictModel):
    type: Literal["hammerstein"]
    nonlinear: BlockConfig
    linear: LTIConfig


class WienerHammersteinConfig(StrictModel):
    type: Literal["wiener_hammerstein"]
    first: LTIConfig
    nonlinear: BlockConfig
    second: LTIConfig


class BranchConfig(StrictModel):
    """One branch G-(.) -> rho -> G+(.) of the parallel LPL structure (seed 002, Definition 1)."""

    before: Optional[LTIConfig] = None
    nonlinear: BlockConfig
    after: Optional[LTIConfig] = None


class LPLConfig(StrictModel):
    type: Literal["lpl"]
    branches: list[BranchConfig] = Field(min_length=1)


ModelConfig = Annotated[
    Union[
        TransferFunctionPlant, ZPKPlant, StateSpacePlant, MassSpringDamperConfig, TwoMassStageConfig,
        NonlinearFeedbackConfig, WienerConfig, HammersteinConfig, WienerHammersteinConfig, LPLConfig,
    ],
    Field(discriminator="type"),
]


class PIDConfig(StrictModel):
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


ControllerConfig = Annotated[
    Union[PIDConfig, TransferFunctionConfig, ZPKConfig, StateSpaceConfig], Field(discriminator="type")
]


class FeedforwardConfig(StrictModel):
    """u_ff = coulomb * sign(r') + velocity * r' (seed 003, Fig. 1: K_fc = coulomb)."""

    coulomb: NonNegative = 0.0
    velocity: NonNegative = 0.0


class ClosedLoopConfig(StrictModel):
    controller: ControllerConfig
    feedforward: FeedforwardConfig = FeedforwardConfig()


class DisturbancesConfig(StrictModel):
    """White Gaussian noise, standard deviations in the units of the signal they are added to."""

    u_noise: NonNegative = 0.0
    y_noise: NonNegative = 0.0
    process_noise: NonNegative = 0.0
    seed: Optional[Annotated[int, Field(ge=0)]] = None


class LinspaceConfig(StrictModel):
    start: float
    stop: float
    num: Annotated[int, Field(ge=1)]


class SweepConfig(StrictModel):
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


class SimulationConfig(StrictModel):
    substeps: Optional[Annotated[int, Field(ge=1)]] = None


class FreeParameterConfig(StrictModel):
    """A config value that ``nlsid fit --model`` estimates: start value (default: the value written
    at its key path) and bounds (default: unbounded)."""

    start: Optional[float] = None
    lower: Optional[float] = None
    upper: Optional[float] = None

    @model_validator(mode="after")
    def _bounds(self):
        lower = -float("inf") if self.lower is None else self.lower
        upper = float("inf") if self.upper is None else self.upper
        if not lower < upper:
            raise ValueError(f"lower ({lower}) must be < upper ({upper})")
        if self.start is not None and not lower <= self.start <= upper:
            raise ValueError(f"start ({self.start}) must lie within [lower, upper] = [{lower}, {upper}]")
        return self


class SimulateConfig(StrictModel):
    """The whole model / simulation config file."""

    model: ModelConfig
    closed_loop: Optional[ClosedLoopConfig] = None
    disturbances: DisturbancesConfig = DisturbancesConfig()
    sweep: Optional[SweepConfig] = None
    simulation: SimulationConfig = SimulationConfig()
    free: dict[str, FreeParameterConfig] = {}  # dotted key path -> start and bounds (nlsid fit --model)


def validate_simulate_config(data, path, lines: dict) -> SimulateConfig:
    """Validate a loaded model config; errors name the file, line and key path."""
    return config_loader.validate(data, SimulateConfig, path, lines)
