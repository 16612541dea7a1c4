"""The diagnosis of a linear model of several inputs and outputs (``mimo_state_space``), one output at a time,
then one input at a time.

The model is simulated on the measured inputs of every run (:func:`nlsid.simulate.mimo.simulate_mimo`,
periodic runs in their steady state) and each output i is judged on its own:

1. **The simulation error against the noise** (the first numbers of a SISO diagnosis, per output).
   A periodic run of P >= 2 steady periods is compared on its mean period, whose noise variance per
   sample is sigma_i^2 / P; an arbitrary run on its whole record. On the validation runs
   S_i = sum_r P_r sum_n e_rn^2 (P_r = 1 for an arbitrary run) and, with the noise variance
   sigma_i^2 estimated from the period-to-period scatter of every run of P >= 2 periods
   (nu = sum_r N_r (P_r - 1) degrees of freedom, independent of the period means for Gaussian noise),

       ratio_i = S_i / (n_i sigma_i^2) ~ F(n_i, nu)

   if the model is right (n_i the samples compared). The error is significant where the p-value is
   below :data:`nlsid.diagnose.significance.ALPHA` (0.001), and ``above_noise_db`` is 10 log10 ratio_i.
   Without two periods in any run the noise is unknown (NaN) and the error is not judged.
   The F law assumes white noise; coloured noise makes it optimistic.

2. **The frequency response matrix of the data against the model's**, where the runs are orthogonal
   multisines or arbitrary records (:class:`nlsid.analysis.frm_levels.MimoRuns`: the FRM, or the
   LPM for several inputs): per entry (i, a) and level, the share of lines where the model's G_ia
   lies outside the 95 % circle (of the total variance: noise and stochastic nonlinear distortion)
   around the measured G_ia (a continuous model's through the
   zero-order hold: :func:`sampled_model`). A right model leaves about 5 %.

3. **Static output hypotheses, one output at a time**. Each maps the model's simulated output x_i
   to the measured z_i; it changes output i only, so the other outputs are held as simulated:

   * ``output_offset``: z = x + c;
   * ``output_gain``: z = g x;
   * ``output_saturation`` (a sensor's range, or a saturation at the output): z = min(max(x, lo), hi),
     each level fitted exactly by a scan of the sorted samples (:func:`fit_saturation`);
   * ``output_polynomial``: z = c + g x + a2 x^2 + a3 x^3 (a quadratic or cubic sensor curve).

   Each is fitted by weighted least squares (weights P_r) on the estimation runs and scored on the
   validation runs: with SSE_0 and SSE_1 the weighted squared errors before and after, p parameters
   and n samples, ``gain_db`` = 10 log10(SSE_0 / SSE_1) and

       F = ((SSE_0 - SSE_1) / p) / (SSE_1 / (n - p)),

   the F test of the reduction against the error left (it needs no noise level; errors the
   hypothesis does not explain count as noise, which makes it conservative). A hypothesis is
   significant where its p-value is below ALPHA. Of the significant ones the cause named for output
   i is the one with the fewest parameters whose SSE_1 is not significantly above the best one's
   ((SSE_1 - SSE_best) / (SSE_best / n) below the F(1, n) quantile at 1 - ALPHA): the simplest
   explanation the data cannot tell from the best.

4. **The extended model** (:func:`extended_config`): the user's config with each named cause as a
   static block of its output (``output_nonlinearity``, ``docs/configs.md``): an offset c as the
   polynomial [c, 1], a gain g as [0, g], the cubic as [c, g, a2, a3], a saturation of two finite
   levels as a ``saturation``, of one (the other side clips nothing) as the ``piecewise_linear``
   through (l - 1, l), (l, l), (l + 1, l + 1) (upper level l: slope 1 below it, 0 above; the lower
   side mirrored). Where the output already has a block f, the cause h acts after it and the
   block is h o f where that is one block of the config: a polynomial after a polynomial (the
   composed polynomial), an offset or gain after a saturation, deadzone or piecewise-linear
   block (the piecewise-linear block through f's corners with h applied to its values); for
   other pairs that output's cause is not added and the summary says why. The output blocks do
   not act on the state, so the extended model reproduces the hypothesis' fitted outputs h(x_i)
   exactly on periodic runs (in their steady state); an arbitrary run's start state is fitted
   again through the block (first order). Its validation error is reported per output.

5. **Static input hypotheses, one input at a time, on every output at once**
   (:func:`score_input`), where some output's error is significant or has a cause (or the noise
   is unknown), on each input j without a block: an actuator saturation p_j = min(max(u_j, lower),
   upper) (``input_saturation``) and the input polynomial p_j = u_j + a2 u_j^2 + a3 u_j^3 (the
   quadratic and odd cubic terms, ``input_polynomial``) before B. An input block moves every output
   u_j drives through the dynamics, so it is fitted by output error on all outputs together
   (:func:`fit_input`: the model simulated with the block, the matrices and other blocks held),
   minimising the noise-weighted cost

       S = sum_i sum_runs sum_n w (x_i - z_i)^2 / sigma_i^2,

   the Gaussian negative log-likelihood up to constants (sigma_i the output's noise, else its error
   rms). It is scored on the validation runs by the same F test as an output hypothesis, over all
   outputs (``gain_db``) and on each output alone (the outputs it is ``gained_on``).
   **Input or outputs** (:func:`choose_side`): an input saturation distorts every output its input
   drives, a sensor saturation one. The outputs' named causes together (their parameters summed,
   S with each output's cause) and each significant input hypothesis are compared on S as the
   per-output verdict compares its hypotheses: of those whose S is not significantly above the
   best's (F test of (S - S_best) / dp against S_best / (n - p_best), dp = max(p_best - p, 1),
   n the validation samples of all outputs) the one of fewest parameters is named. A named input
   cause replaces the outputs' causes (each output's remainder is what it leaves), and the extended
   model carries it as the input's ``input_nonlinearity`` block (a saturation, or the piecewise-linear
   block of one level; the polynomial [0, 1, a2, a3]).

The SISO hypotheses that act inside a mechanical, tank or transfer-function model (friction,
stiffness, hysteresis, feedback around a transfer function, a deadzone or backlash at the input,
missing resonance, wrong mechanics or dynamics, a delay) are not tested: they act inside a model of
one input and one output (:data:`NOT_TESTED`). The SISO output blocks (quadratic output, output
saturation) are tested here, per output; the input saturation and actuator polynomial per input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from nlsid.diagnose.significance import ALPHA
from nlsid.errors import InputError
from nlsid.io.run import Run

#: The SISO hypotheses tested here on each output, under the per-output names.
TESTED_PER_OUTPUT = {"quadratic_output": "output_polynomial", "output_saturation": "output_saturation"}
#: The SISO hypotheses tested here on each input, fitted on every output at once, under their names here.
TESTED_PER_INPUT = {"input_saturation": "input_saturation", "actuator_polynomial": "input_polynomial"}
#: Why the library's other hypotheses are not tested on a mimo_state_space model.
NOT_TESTED = ("a single-input single-output hypothesis: it acts inside a mechanical, tank or transfer-function "
              "model (a force, the input u, the dynamics between one input and one output), which a "
              "mimo_state_space model is not; its dynamics are refitted by fit --model of its matrices, a block "
              "given in its input_nonlinearity by fit --model of the block's numbers")

#: Why the black-box yardstick is not fitted.
NO_YARDSTICK = ("the yardstick's black box (a PNLSS model) is fitted to one input and one output; without it the "
                "status rests on the noise floor alone")


@dataclass(frozen=True)
class OutputHypothesis:
    """A static map of one simulated output x to the measured one: its name, title, parameter
    names, ``fit(x, z, w) -> values`` (weighted least squares) and ``apply(x, values) -> z``."""

    name: str
    title: str
    parameters: tuple[str, ...]
    fit: Callable[[np.ndarray, np.ndarray, np.ndarray], dict]
    apply: Callable[[np.ndarray, dict], np.ndarray]


def _weighted_lstsq(X: np.ndarray, z: np.ndarray, w: np.ndarray) -> np.ndarray:
    root = np.sqrt(w)
    return np.linalg.lstsq(X * root[:, None], z * root, rcond=None)[0]


def _offset(x, z, w) -> dict:
    return {"offset": float(np.sum(w * (z - x)) / np.sum(w))}


def _gain(x, z, w) -> dict:
    denominator = float(np.sum(w * x * x))
    return {"gain": float(np.sum(w * x * z)) / denominator if denominator > 0 else 1.0}


def _polynomial(x, z, w) -> dict:
    scale = float(np.sqrt(np.mean(x * x))) or 1.0  # conditioning: the powers of x / rms(x)
    s = x / scale
    c = _weighted_lstsq(np.stack([np.ones_like(s), s, s * s, s ** 3], axis=1), z, w)
    return {"offset": float(c[0]), "gain": float(c[1] / scale), "a2": float(c[2] / scale ** 2),
            "a3": float(c[3] / scale ** 3)}


def _apply_polynomial(x, v) -> np.ndarray:
    return v["offset"] + x * (v["gain"] + x * (v["a2"] + x * v["a3"]))


def fit_saturation(x: np.ndarray, z: np.ndarray, w: np.ndarray) -> dict:
    """The levels ``lower`` <= ``upper`` of z = min(max(x, lower), upper) that minimise
    sum w (z_model - z)^2, exactly.

    The two sides separate: samples above ``upper`` change by ``upper`` alone, those below
    ``lower`` by ``lower`` alone. For the upper side, with x sorted downwards, a level between
    x_(k+1) and x_(k) clips the k largest samples; the cost change
    sum_{j <= k} w_j ((upper - z_j)^2 - (x_j - z_j)^2) is a parabola in ``upper`` with its minimum
    at the weighted mean of their z, clipped into [x_(k+1), x_(k)]. Every k is evaluated with
    cumulative sums and the best taken; a side where no level lowers the cost does not clip
    (``upper`` = +inf, ``lower`` = -inf). The lower side is the same on -x, -z."""
    return {"lower": -_upper_level(-x, -z, w), "upper": _upper_level(x, z, w)}


def _upper_level(x: np.ndarray, z: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(-x, kind="stable")
    xs, zs, ws = x[order], z[order], w[order]
    W, Wz, Wzz = np.cumsum(ws), np.cumsum(ws * zs), np.cumsum(ws * zs * zs)
    base = np.cumsum(ws * (xs - zs) ** 2)
    below = np.append(xs[1:], -np.inf)  # the next sample down: the clipped set's lower edge
    level = np.clip(Wz / W, below, xs)
    change = W * level ** 2 - 2 * level * Wz + Wzz - base
    k = int(np.argmin(change))
    return float(level[k]) if change[k] < 0 else math.inf


def _apply_saturation(x, v) -> np.ndarray:
    return np.clip(x, v["lower"], v["upper"])


HYPOTHESES: tuple[OutputHypothesis, ...] = (
    OutputHypothesis("output_offset", "Output offset", ("offset",), _offset, lambda x, v: x + v["offset"]),
    OutputHypothesis("output_gain", "Output gain", ("gain",), _gain, lambda x, v: v["gain"] * x),
    OutputHypothesis("output_saturation", "Sensor saturation (output range)", ("lower", "upper"), fit_saturation,
                     _apply_saturation),
    OutputHypothesis("output_polynomial", "Output polynomial (quadratic and cubic)", ("offset", "gain", "a2", "a3"),
                     _polynomial, _apply_polynomial),
)


@dataclass
class Samples:
    """One output's compared samples over a set of runs: simulated x, measured z, weights w (P of
    a mean period's sample, 1 of a whole record's)."""

    x: np.ndarray
    z: np.ndarray
    w: np.ndarray

    def sse(self, model: np.ndarray | None = None) -> float:
        e = (self.x if model is None else model) - self.z
        return float(np.sum(self.w * e * e))


@dataclass
class HypothesisScore:
    """One hypothesis fitted on one output: its values, and its validation score (module docstring)."""

    output: str
    hypothesis: OutputHypothesis
    values: dict
    sse_before: float
    sse_after: float
    samples: int
    gain_db: float
    p_value: float
    significant: bool

    def describe(self, unit: str = "") -> str:
        """The fitted values in words, e.g. ``sensor saturation at -4.1 and 4.1 V``."""
        u = f" {unit}" if unit else ""
        v = self.values
        if self.hypothesis.name == "output_saturation":
            sides = [f"{v[side]:.4g}{u}" for side in ("lower", "upper") if math.isfinite(v[side])]
            return f"sensor saturation at {' and '.join(sides) or 'no level (nothing clipped)'}"
        if self.hypothesis.name == "output_offset":
            return f"output offset {v['offset']:+.4g}{u}"
        if self.hypothesis.name == "output_gain":
            return f"output gain {v['gain']:.4g}"
        return (f"output polynomial {v['offset']:+.3g} + {v['gain']:.4g} x + {v['a2']:.3g} x^2 + {v['a3']:.3g} x^3")

    def summary(self) -> dict:
        return {"hypothesis": self.hypothesis.name, "title": self.hypothesis.title, "values": dict(self.values),
                "validation_sse_before": self.sse_before, "validation_sse_after": self.sse_after,
                "samples": self.samples, "gain_db": self.gain_db, "p_value": self.p_value,
                "significant": self.significant}


@dataclass
class OutputDiagnosis:
    """One output's numbers: its noise, its error against it, the hypotheses and the named cause."""

    name: str
    noise: float
    noise_dof: int
    error_rms: float
    samples: int
    above_noise_db: float
    p_value: float
    significant: bool
    scores: list[HypothesisScore] = field(default_factory=list)
    cause: HypothesisScore | None = None
    remainder_above_noise_db: float = math.nan
    remainder_significant: bool = False
    unit: str = ""
    input_cause: "InputScore | None" = None

    @property
    def status(self) -> str:
        if self.cause is not None or self.input_cause is not None:
            return "partly_explained" if self.remainder_significant else "explained"
        if not math.isfinite(self.noise):
            return "undetermined"
        return "unexplained" if self.significant else "no_discrepancy"

    def statement(self) -> str:
        """One line: ``output y2: sensor saturation at ... , 12.0 dB gained`` or the error against the noise."""
        if self.cause is not None:
            rest = (f"; {self.remainder_above_noise_db:.1f} dB above the noise left"
                    if self.remainder_significant else "")
            return f"output {self.name}: {self.cause.describe(self.unit)}, {self.cause.gain_db:.1f} dB gained{rest}"
        if self.input_cause is not None:
            rest = (f"; {self.remainder_above_noise_db:.1f} dB above the noise left"
                    if self.remainder_significant else "")
            gained = self.input_cause.outputs[self.name]["gain_db"]
            return (f"output {self.name}: the input {self.input_cause.input}'s {self.input_cause.describe()}, "
                    f"{gained:.1f} dB gained{rest}")
        if not math.isfinite(self.noise):
            return f"output {self.name}: noise unknown (no run of two periods), no hypothesis significant"
        size = f"{self.above_noise_db:+.1f} dB against the noise (p = {self.p_value:.2g})"
        return (f"output {self.name}: significant error, {size}, no output hypothesis explains it" if self.significant
                else f"output {self.name}: no significant discrepancy ({size})")

    def summary(self) -> dict:
        return {"name": self.name, "status": self.status, "statement": self.statement(), "noise": self.noise,
                "noise_dof": self.noise_dof, "error_rms": self.error_rms, "samples": self.samples,
                "above_noise_db": self.above_noise_db, "p_value": self.p_value, "significant": self.significant,
                "cause": (None if self.cause is None
                          else {**self.cause.summary(), "description": self.cause.describe(self.unit)}),
                "remainder_above_noise_db": self.remainder_above_noise_db,
                "remainder_significant": self.remainder_significant,
                "input_cause": None if self.input_cause is None else self.input_cause.input,
                "hypotheses": [s.summary() for s in self.scores]}


def _order(statuses: list[str]) -> str:
    """The diagnosis' status from its outputs' (module docstring of the verdict: the worst first)."""
    named = any(s in ("explained", "partly_explained") for s in statuses)
    if "unexplained" in statuses or "partly_explained" in statuses:
        return "partly_explained" if named else "unexplained"
    if named:
        return "explained"
    return "undetermined" if "undetermined" in statuses else "no_discrepancy"


@dataclass
class MimoDiagnosis:
    """The diagnosis of a ``mimo_state_space`` model (:func:`diagnose_mimo`)."""

    model_source: str
    inputs: tuple[str, ...]
    outputs: list[OutputDiagnosis]
    frm: list[dict]
    frm_note: str
    not_tested: list[dict]
    estimation: list[str]
    validation: list[str]
    extended: "ExtendedModel | None" = None
    input_scores: list[InputScore] = field(default_factory=list)
    input_cause: InputScore | None = None
    side: dict = field(default_factory=dict)
    input_notes: list[str] = field(default_factory=list)

    @property
    def status(self) -> str:
        return _order([o.status for o in self.outputs])

    def headline(self) -> str:
        """Each output with a named cause or a significant error (:meth:`OutputDiagnosis.statement`),
        else the verdict in words."""
        named = [o for o in self.outputs if o.cause is not None or o.significant and o.input_cause is None
                 or o.remainder_significant]
        first = [] if self.input_cause is None else [self.input_cause.statement()]
        if named or first:  # the input cause, then each output with a cause or a significant error
            return "; ".join([*first, *(o.statement() for o in named)])
        if self.status == "undetermined":
            return "No noise level to judge the error by (no run of two periods), and no output hypothesis significant"
        return "No significant discrepancy on any output"

    def lines(self) -> list[str]:
        """What the terminal shows under the headline: each output, the FRM, what is not tested."""
        out = [] if self.input_cause is None else [self.input_cause.statement()]
        out += [o.statement() for o in self.outputs]
        out += [f"input {s.input}: {s.describe()}: {s.gain_db:.1f} dB over all outputs (p = {s.p_value:.2g}"
                f"{', significant' if s.significant else ''})" for s in self.input_scores]
        out += self.input_notes
        if self.side.get("candidates"):
            words = ", ".join(f"{c['name']} ({c['parameters']} parameters, weighted error {c['weighted_sse']:.4g})"
                              for c in self.side["candidates"])
            out.append(f"input or output causes: compared {words} on {self.side['samples']} samples: "
                       f"{self.side['chosen']} chosen")
        out += [f"FRM entry {e['output']} <- {e['input']} ({e['level']}): {100 * e['outside']:.0f} % of "
                f"{e['lines']} lines outside the data's 95 % circles" for e in self.frm]
        if self.frm_note:
            out.append(f"FRM: {self.frm_note}")
        if self.extended is not None:
            out += self.extended.lines()
        tested = ", ".join(f"{siso} as {mine}" for siso, mine in TESTED_PER_OUTPUT.items())
        out.append(f"tested on each output: {tested}, with output_offset and output_gain")
        out.append("tested on each input without a block, on all outputs at once: "
                   + ", ".join(f"{siso} as {mine}" for siso, mine in TESTED_PER_INPUT.items()))
        for reason in dict.fromkeys(item["reason"] for item in self.not_tested):
            names = ", ".join(item["hypothesis"] for item in self.not_tested if item["reason"] == reason)
            out.append(f"not tested: {names}: {reason}")
        return out

    def summary(self) -> dict:
        """``summary.json`` of ``nlsid diagnose`` of such a model (``docs/formats.md``, "several outputs")."""
        worst = max(self.outputs, key=lambda o: o.above_noise_db if math.isfinite(o.above_noise_db) else -math.inf)
        return {"kind": "mimo", "headline": self.headline(), "findings": self.lines(),
                "verdict": {"status": self.status}, "model_source": self.model_source,
                "inputs": list(self.inputs), "outputs": [o.summary() for o in self.outputs],
                "input_hypotheses": [s.summary() for s in self.input_scores],
                "input_cause": None if self.input_cause is None else self.input_cause.summary(),
                "cause_comparison": dict(self.side), "input_notes": list(self.input_notes),
                "frm": list(self.frm), "frm_note": self.frm_note, "not_tested": list(self.not_tested),
                "split": {"estimation": list(self.estimation), "validation": list(self.validation)},
                "evidence": {"error_above_noise": {
                    "output": worst.name, "above_noise_db": worst.above_noise_db, "p_value": worst.p_value,
                    "significant": any(o.significant for o in self.outputs),
                    "noise_known": all(math.isfinite(o.noise) for o in self.outputs)}, "lines": []},
                "extended_model": None if self.extended is None else self.extended.summary(),
                "models": [] if self.extended is None or self.extended.config is None else [
                    {"file": EXTENDED, "kind": "extended",
                     "outputs": [o["name"] for o in self.extended.outputs if o["block"] is not None],
                     **({"inputs": [o["name"] for o in self.extended.inputs]} if self.extended.inputs else {})}]}


EXTENDED = "extended_model.yaml"  # the file of the extended model in the diagnosis folder


def cause_block(score: HypothesisScore) -> dict | None:
    """The output block config of a named cause h (module docstring, 4.); None for a saturation
    that clips nothing on either side."""
    v = score.values
    name = score.hypothesis.name
    if name == "output_offset":
        return {"type": "polynomial", "coefficients": [v["offset"], 1.0]}
    if name == "output_gain":
        return {"type": "polynomial", "coefficients": [0.0, v["gain"]]}
    if name == "output_polynomial":
        return {"type": "polynomial", "coefficients": [v["offset"], v["gain"], v["a2"], v["a3"]]}
    return saturation_block(v["lower"], v["upper"])


def saturation_block(lower: float, upper: float) -> dict | None:
    """The block of z = min(max(x, lower), upper) (module docstring, 4.): a saturation of two
    finite levels, a piecewise-linear block of one, None of none."""
    if math.isfinite(lower) and math.isfinite(upper):
        return {"type": "saturation", "lower": lower, "upper": upper}
    if math.isfinite(upper):  # slope 1 below the level, 0 above: the end segments continue the line
        return {"type": "piecewise_linear", "x": [upper - 1.0, upper, upper + 1.0], "y": [upper - 1.0, upper, upper]}
    if math.isfinite(lower):
        return {"type": "piecewise_linear", "x": [lower - 1.0, lower, lower + 1.0], "y": [lower, lower, lower + 1.0]}
    return None


def _corners(block: dict) -> tuple[list[float], list[float]]:
    """(x, y) of a saturation, deadzone or piecewise-linear block as the piecewise-linear block's
    points (the end segments continued), each x once."""
    if block["type"] == "piecewise_linear":
        return list(block["x"]), list(block["y"])
    lo, hi = float(block["lower"]), float(block["upper"])
    x = [lo - 1.0, lo, hi, hi + 1.0] if hi > lo else [lo - 1.0, lo, lo + 1.0]
    if block["type"] == "saturation":
        y = [min(max(t, lo), hi) for t in x]
    else:  # deadzone: x - upper above, x - lower below, 0 between
        y = [t - hi if t > hi else (t - lo if t < lo else 0.0) for t in x]
    return x, y


def composed(cause: dict, existing: dict | None) -> tuple[dict | None, str]:
    """The block h o f of a cause h (:func:`cause_block`) after the output's block f (None: h
    itself), or None and why where h o f is not one block of the config."""
    from numpy.polynomial import Polynomial

    if existing is None:
        return cause, ""
    if cause["type"] == "polynomial" and existing["type"] == "polynomial":
        h, f = Polynomial(cause["coefficients"]), Polynomial(existing["coefficients"])
        return {"type": "polynomial", "coefficients": [float(c) for c in h(f).coef]}, ""
    affine = cause["type"] == "polynomial" and len(cause["coefficients"]) == 2
    if affine and existing["type"] in ("saturation", "deadzone", "piecewise_linear"):
        x, y = _corners(existing)
        c, g = cause["coefficients"]
        return {"type": "piecewise_linear", "x": x, "y": [c + g * t for t in y]}, ""
    return None, (f"the output already has a {existing['type']} block, and a {cause['type']} after it is not one "
                  "block of the config: fit the block's numbers by fit --model")


@dataclass
class ExtendedModel:
    """The user's config with each named cause as its output's block (:func:`extended_config`):
    ``config`` (None where no cause could be added), per output its ``block`` (the added one,
    None), ``reason`` (why not, or "") and ``error_rms`` (the extended model's validation error)."""

    config: dict | None
    outputs: list[dict]
    inputs: list[dict] = field(default_factory=list)

    def header(self, source: str, statements: Sequence[str]) -> list[str]:
        """The YAML's header comment: what it extends and the named causes."""
        return [f"Extended model of {source}: each named cause added as its output's block", *statements]

    def lines(self) -> list[str]:
        """The terminal's line naming the file and the causes left out, with why."""
        added = [f"output_nonlinearity of {o['name']}" for o in self.outputs if o["block"] is not None]
        added += [f"input_nonlinearity of {o['name']}" for o in self.inputs]
        out = [f"extended model: {EXTENDED} ({', '.join(added)})"] if added else []
        out += [f"output {o['name']}: cause not added to the extended model: {o['reason']}"
                for o in self.outputs if o["reason"]]
        return out

    def summary(self) -> dict:
        return {"file": EXTENDED if self.config is not None else None, "outputs": [dict(o) for o in self.outputs],
                "inputs": [dict(o) for o in self.inputs]}


def extended_config(config_data: dict, outputs: Sequence[OutputDiagnosis],
                    input_cause: "InputScore | None" = None) -> tuple[dict | None, list[dict], list[dict]]:
    """The config with each output's named cause as its ``output_nonlinearity`` block (module
    docstring, 4.) and an input cause as its input's ``input_nonlinearity`` block (5.), without
    ``free``; None where no cause was added. Also, per output with a cause: ``name``, ``block``
    (None where not added) and ``reason``; per input cause: ``name`` and ``block``."""
    from nlsid.models.key_paths import deep_copy

    data = {key: deep_copy(value) for key, value in config_data.items() if key != "free"}
    blocks = data["model"].setdefault("output_nonlinearity", {}) or {}
    data["model"]["output_nonlinearity"] = blocks
    added = []
    for o in outputs:
        if o.cause is None:
            continue
        cause = cause_block(o.cause)
        block, why = (None, "the saturation clips nothing") if cause is None else composed(cause, blocks.get(o.name))
        if block is not None:
            blocks[o.name] = block
        added.append({"name": o.name, "block": block, "reason": why})
    inputs = []
    if input_cause is not None:
        v = input_cause.values
        block = (saturation_block(v["lower"], v["upper"]) if input_cause.hypothesis == "input_saturation"
                 else {"type": "polynomial", "coefficients": [0.0, 1.0, v["a2"], v["a3"]]})
        if block is not None:  # the input had no block: its hypotheses are tested only there
            data["model"]["input_nonlinearity"] = {**(data["model"].get("input_nonlinearity") or {}),
                                                   input_cause.input: block}
            inputs.append({"name": input_cause.input, "block": block})
    if not blocks:
        del data["model"]["output_nonlinearity"]
    return (data if inputs or any(a["block"] is not None for a in added) else None), added, inputs


def compared(model, runs: Sequence[Run]) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Per run (simulated outputs, measured outputs, weight): a periodic run of P >= 2 steady
    periods as its mean period (weight P), any other over its steady part (weight 1)."""
    from nlsid.fit.mimo_output_error import compact_runs, measured_outputs, steady_columns
    from nlsid.io.ranges import record
    from nlsid.simulate.mimo import simulate_mimo

    names = [*model.inputs, *model.outputs]
    compact, weights = compact_runs(runs, names)
    measured = measured_outputs(compact, model.outputs)
    out = []
    for run, z, w in zip(compact, measured, weights):
        x = steady_columns(run, simulate_mimo(model, record(run), steady=True).output_matrix())
        out.append((x, z, float(w) ** 2))
    return out


def samples_of(pairs: list[tuple[np.ndarray, np.ndarray, float]], i: int) -> Samples:
    """Output i's :class:`Samples` over the runs of :func:`compared`."""
    return Samples(np.concatenate([x[i] for x, _, _ in pairs]), np.concatenate([z[i] for _, z, _ in pairs]),
                   np.concatenate([np.full(x.shape[1], w) for x, _, w in pairs]))


def output_noise_variance(runs: Sequence[Run], name: str) -> tuple[float, int]:
    """The pooled period-to-period variance of output ``name`` over the runs of P >= 2 steady
    periods and its degrees of freedom (NaN, 0 without such a run)."""
    from nlsid.fit.mimo_output_error import steady_periods

    periodic = [run for run in runs if run.period is not None and run.n_periods >= 2]
    dof = sum(run.period * (run.n_periods - 1) for run in periodic)
    if not dof:
        return math.nan, 0
    ss = sum(float(np.sum(np.var(steady_periods(run, name), axis=0, ddof=1))) * (run.n_periods - 1) for run in periodic)
    return ss / dof, dof


def score(hypothesis: OutputHypothesis, name: str, estimation: Samples, validation: Samples) -> HypothesisScore:
    """Fit ``hypothesis`` on the estimation samples of one output, score it on the validation ones."""
    from scipy import stats

    values = hypothesis.fit(estimation.x, estimation.z, estimation.w)
    before, after = validation.sse(), validation.sse(hypothesis.apply(validation.x, values))
    n, p = validation.x.size, len(hypothesis.parameters)
    gain = 10 * math.log10(before / after) if after > 0 and before > 0 else (math.inf if before > 0 else 0.0)
    if after > 0 and n > p and before > after:
        F = ((before - after) / p) / (after / (n - p))
        p_value = float(stats.f.sf(F, p, n - p))
    else:
        p_value = 0.0 if (after == 0 and before > 0) else 1.0
    return HypothesisScore(name, hypothesis, values, before, after, n, gain, p_value, p_value < ALPHA)


def choose(scores: list[HypothesisScore]) -> HypothesisScore | None:
    """The named cause among the significant scores: the fewest parameters not significantly worse
    than the best (module docstring); None where none is significant."""
    from scipy import stats

    significant = [s for s in scores if s.significant]
    if not significant:
        return None
    best = min(significant, key=lambda s: s.sse_after)
    limit = float(stats.f.ppf(1 - ALPHA, 1, best.samples))
    close = [s for s in significant
             if best.sse_after == 0 and s.sse_after == 0
             or best.sse_after > 0 and (s.sse_after - best.sse_after) / (best.sse_after / best.samples) < limit]
    return min(close, key=lambda s: (len(s.hypothesis.parameters), s.sse_after))


def sampled_model(model, fs: float):
    """The model as it runs on data sampled at ``fs``: a continuous one as its exact zero-order-hold
    equivalent (the input held between samples, as :func:`nlsid.simulate.mimo.simulate_mimo`
    runs it), whose response the measured FRM is; a discrete one as it is."""
    import dataclasses

    if model.discrete:
        return model
    Phi, Gamma = model.stepped(1.0 / fs)
    return dataclasses.replace(model, A=np.asarray(Phi), B=np.asarray(Gamma), domain="discrete", fs=fs)


def frm_comparison(model, runs: Sequence[Run], where: str) -> tuple[list[dict], str]:
    """Per level and entry (output, input): the share of lines where the model's G lies outside the
    data's 95 % circle (module docstring), and a note where no FRM is formed (why). The FRM is that
    of orthogonal multisines where every run is a multisine, that of the LPM for several inputs
    (its band's lines) where every run is arbitrary."""
    from nlsid.analysis.frm_levels import MimoRuns
    from nlsid.io.ranges import RangeRun

    kinds = {run.kind for run in runs}
    if kinds not in ({"multisine"}, {"arbitrary"}):
        return [], f"not compared: the runs are of kinds {', '.join(sorted(kinds))}, not all multisines or all arbitrary"
    if any(isinstance(run, RangeRun) for run in runs):
        return [], "not compared: sample ranges cut the records into the estimation and validation parts"
    mimo = MimoRuns()
    try:
        list(mimo.take((run, f"{where}:/runs/{run.run_id}") for run in runs))
        if kinds == {"multisine"}:
            levels = [(level.level, level.inputs, level.outputs, level.fs, level.frm.frequency, level.frm.G,
                       level.frm.bounds.radius) for level in mimo.levels(0.95, where)]
        else:  # the LPM for several inputs: its variance holds the nonlinear distortion too
            levels = [(level.level, level.inputs, level.outputs, level.result.fs,
                       level.result.frequencies[level.band], level.result.G[level.band],
                       level.result.bounds(0.95).radius[level.band]) for level in mimo.lpm_levels(0.95, where)]
    except InputError as error:
        return [], f"not formed: {error.where}: {error.what}"
    out = []
    for value, inputs, outputs, fs, frequency, G, radius in levels:
        if tuple(inputs) != tuple(model.inputs) or tuple(outputs) != tuple(model.outputs):
            return [], "not compared: the runs' inputs and outputs are not the model's, in order"
        G_model = sampled_model(model, fs).frequency_response(frequency, fs=fs)
        name = "no level" if value is None else f"level {value:g}"
        for i, output in enumerate(outputs):
            for a, source in enumerate(inputs):
                r = radius[:, i, a]
                known = np.isfinite(r)
                outside = np.abs(G[:, i, a] - G_model[:, i, a])[known] > r[known]
                out.append({"level": name, "output": output, "input": source, "lines": int(known.sum()),
                            "outside": float(outside.mean()) if known.any() else math.nan})
    return out, ""


INPUT_HYPOTHESES = {
    "input_saturation": ("Actuator saturation (input range)", ("lower", "upper")),
    "input_polynomial": ("Input polynomial (quadratic and odd cubic)", ("a2", "a3")),
}


@dataclass
class InputScore:
    """A static block h on one input, fitted on every output at once (module docstring, 5.): its
    values, its noise-weighted validation errors over all outputs (``sse_before``, ``sse_after``,
    sum_i SSE_i / sigma_i^2), per output the dB gained, the F test of the reduction."""

    input: str
    hypothesis: str
    values: dict
    sse_before: float
    sse_after: float
    samples: int
    gain_db: float
    p_value: float
    significant: bool
    outputs: dict[str, dict] = field(default_factory=dict)

    @property
    def parameters(self) -> tuple[str, ...]:
        return INPUT_HYPOTHESES[self.hypothesis][1]

    def gained_on(self) -> list[str]:
        """The outputs whose own error it lowers significantly (F test of its parameters, p < ALPHA)."""
        return [name for name, o in self.outputs.items() if o["significant"]]

    def describe(self) -> str:
        """E.g. ``actuator saturation at -0.8 and 0.8``."""
        v = self.values
        if self.hypothesis == "input_saturation":
            sides = [f"{v[side]:.4g}" for side in ("lower", "upper") if math.isfinite(v[side])]
            return f"actuator saturation at {' and '.join(sides) or 'no level (nothing clipped)'}"
        return f"input polynomial u + {v['a2']:.3g} u^2 + {v['a3']:.3g} u^3"

    def statement(self) -> str:
        """``input u2: actuator saturation at -0.8 and 0.8, 15.0 dB gained on y, y2``."""
        on = ", ".join(self.gained_on()) or "no output alone"
        return f"input {self.input}: {self.describe()}, {self.gain_db:.1f} dB gained on {on}"

    def summary(self) -> dict:
        return {"input": self.input, "hypothesis": self.hypothesis, "title": INPUT_HYPOTHESES[self.hypothesis][0],
                "values": dict(self.values), "validation_weighted_sse_before": self.sse_before,
                "validation_weighted_sse_after": self.sse_after, "samples": self.samples, "gain_db": self.gain_db,
                "p_value": self.p_value, "significant": self.significant, "description": self.describe(),
                "outputs": {name: dict(o) for name, o in self.outputs.items()}}


def input_block(hypothesis: str, values: dict):
    """The :class:`~nlsid.models.blocks.StaticBlock` of an input hypothesis: the saturation
    p = min(max(u, lower), upper), or the polynomial p = u + a2 u^2 + a3 u^3."""
    from nlsid.models.blocks import POLYNOMIAL, SATURATION, StaticBlock

    if hypothesis == "input_saturation":
        return StaticBlock(SATURATION, np.array([values["lower"], values["upper"]], dtype=float))
    return StaticBlock(POLYNOMIAL, np.array([0.0, 1.0, values["a2"], values["a3"]]))


def with_input_block(model, name: str, hypothesis: str, values: dict):
    """The model with the block of an input hypothesis on input ``name``."""
    import dataclasses

    return dataclasses.replace(model, input_blocks={**model.input_blocks, name: input_block(hypothesis, values)})


def _weighted_errors(pairs, scales: np.ndarray) -> np.ndarray:
    """The residuals sqrt(w) (x_i - z_i) / sigma_i of every run and output, stacked."""
    return np.concatenate([(np.sqrt(w) * (x - z) / scales[:, None]).ravel() for x, z, w in pairs])


def _steady_input(model, runs: Sequence[Run], j: int) -> np.ndarray:
    from nlsid.io.ranges import record

    return np.concatenate([record(run).named_signal(model.inputs[j]) for run in runs])


def fit_input(model, j: int, hypothesis: str, estimation: Sequence[Run], scales: np.ndarray) -> dict:
    """Fit an input hypothesis on input j by output error on every output at once, the matrices and
    other blocks held: least squares of the noise-weighted residuals (trust region within bounds).
    The saturation starts from the best of the symmetric quantile levels of the input (60 % to
    99 %), as its cost is flat where nothing is clipped; the polynomial from zero."""
    from scipy.optimize import least_squares

    name = model.inputs[j]
    keys = INPUT_HYPOTHESES[hypothesis][1]

    def residuals(theta):
        values = dict(zip(keys, (float(t) for t in theta)))
        if hypothesis == "input_saturation" and values["lower"] >= values["upper"]:
            values["lower"] = values["upper"] - 1e-9  # the cost stays defined at the bound
        return _weighted_errors(compared(with_input_block(model, name, hypothesis, values), estimation), scales)

    u = _steady_input(model, estimation, j)
    if hypothesis == "input_polynomial":
        span = float(np.max(np.abs(u))) or 1.0
        fit = least_squares(residuals, np.zeros(2), x_scale=np.array([1 / span, 1 / span ** 2]))
        return dict(zip(keys, (float(t) for t in fit.x)))
    starts = [np.array([np.quantile(u, 1 - q), np.quantile(u, q)]) for q in (0.6, 0.75, 0.9, 0.99)]
    start = min(starts, key=lambda t: float(np.sum(residuals(t) ** 2)))
    span = float(np.ptp(u)) or 1.0
    fit = least_squares(residuals, start, bounds=([u.min() - span, u.min()], [u.max(), u.max() + span]),
                        x_scale=span / 10, diff_step=1e-4)
    lower, upper = (float(t) for t in fit.x)
    return {"lower": lower if lower > u.min() else -math.inf, "upper": upper if upper < u.max() else math.inf}


def score_input(model, j: int, hypothesis: str, estimation: Sequence[Run], validation: Sequence[Run],
                before: Sequence[tuple[np.ndarray, np.ndarray, float]], scales: np.ndarray) -> InputScore:
    """Fit an input hypothesis on the estimation runs, score it on the validation ones over all
    outputs (module docstring, 5.) and on each output alone."""
    from scipy import stats

    values = fit_input(model, j, hypothesis, estimation, scales)
    after = compared(with_input_block(model, model.inputs[j], hypothesis, values), validation)
    p = len(INPUT_HYPOTHESES[hypothesis][1])

    def test(s0: float, s1: float, n: int) -> tuple[float, float]:
        gain = 10 * math.log10(s0 / s1) if s0 > 0 and s1 > 0 else 0.0
        if s1 > 0 and n > p and s0 > s1:
            return gain, float(stats.f.sf(((s0 - s1) / p) / (s1 / (n - p)), p, n - p))
        return gain, 1.0

    per_output = {}
    for i, name in enumerate(model.outputs):
        s0, s1 = samples_of(before, i).sse(), samples_of(after, i).sse()
        n_i = samples_of(before, i).x.size
        gain, p_value = test(s0, s1, n_i)
        per_output[name] = {"gain_db": gain, "p_value": p_value, "significant": p_value < ALPHA,
                            "sse_after": s1}
    s0 = float(np.sum(_weighted_errors(before, scales) ** 2))
    s1 = float(np.sum(_weighted_errors(after, scales) ** 2))
    n = sum(x.size for x, _, _ in before)
    gain, p_value = test(s0, s1, n)
    return InputScore(model.inputs[j], hypothesis, values, s0, s1, n, gain, p_value, p_value < ALPHA, per_output)


def choose_side(outputs: Sequence[OutputDiagnosis], inputs: Sequence[InputScore], scales: np.ndarray,
                samples: int) -> tuple[InputScore | None, dict]:
    """Whether an input cause or the outputs' causes explain the data (module docstring, 5.).

    The candidates are each significant input hypothesis (p parameters, its weighted validation
    error S over all outputs) and the outputs' named causes together (the sum of their parameters,
    S = sum_i SSE_i / sigma_i^2 with each output's cause, or its error where it has none). Of the
    candidates not significantly worse than the best (F test of (S - S_best) / dp against
    S_best / (n - p_best), dp = max(p_best - p, 1)), the one of fewest parameters is chosen.
    Returns the input cause (None: the outputs' side) and what was compared."""
    from scipy import stats

    causes = [o for o in outputs if o.cause is not None]
    candidates: list[tuple[str, int, float, InputScore | None]] = []
    if causes:
        s_out = sum((o.cause.sse_after if o.cause is not None else o.scores[0].sse_before) / scales[k] ** 2
                    for k, o in enumerate(outputs))
        candidates.append(("outputs " + ", ".join(o.name for o in causes),
                           sum(len(o.cause.hypothesis.parameters) for o in causes), s_out, None))
    candidates += [(f"input {s.input} {s.hypothesis}", len(s.parameters), s.sse_after, s)
                   for s in inputs if s.significant]
    comparison = {"candidates": [{"name": c[0], "parameters": c[1], "weighted_sse": c[2]} for c in candidates],
                 "samples": samples, "chosen": None}
    if not candidates:
        return None, comparison
    best = min(candidates, key=lambda c: c[2])
    close = []
    for c in candidates:
        dp = max(best[1] - c[1], 1)
        dof = max(samples - best[1], 1)
        if best[2] <= 0 or (c[2] - best[2]) / dp / (best[2] / dof) < float(stats.f.ppf(1 - ALPHA, dp, dof)):
            close.append(c)
    chosen = min(close, key=lambda c: (c[1], c[2]))
    comparison["chosen"] = chosen[0]
    return chosen[3], comparison


def diagnose_mimo(config_data: dict, source: str, estimation: Sequence[Run], validation: Sequence[Run],
                  where: str = "recording", units: dict | None = None) -> MimoDiagnosis:
    """Diagnose a ``mimo_state_space`` model on measured runs, one output at a time (module docstring).

    Parameters
    ----------
    config_data : dict
        The model config (validated) of type ``mimo_state_space``.
    source : str
        Its name in messages and the summary.
    estimation, validation : sequence of Run
        The runs the hypotheses are fitted on and scored on (:func:`nlsid.fit.run_split.split_runs`).
    where : str
        The recording's name, for messages and the FRM's levels.
    units : dict, optional
        Signal -> unit, for the named causes' levels.

    Returns
    -------
    MimoDiagnosis
    """
    from scipy import stats

    from nlsid.fit.mimo_output_error import check_measured
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.models.from_config import model as build

    if not validation:
        raise InputError(where, "no validation run: a diagnosis scores its hypotheses on runs it did not fit")
    model = build(validate_simulate_config(config_data, source, {}))
    runs = [*estimation, *validation]
    for run in runs:
        check_measured(model, run, f"{where}:/runs/{run.run_id}")
    est, val = compared(model, estimation), compared(model, validation)
    outputs = []
    for i, name in enumerate(model.outputs):
        variance, dof = output_noise_variance(runs, name)
        e, v = samples_of(est, i), samples_of(val, i)
        n = v.x.size
        sse = v.sse()
        error_rms = math.sqrt(sse / float(np.sum(v.w))) if n else math.nan
        if dof and variance > 0:
            ratio = sse / (n * variance)
            above, p_value = 10 * math.log10(ratio) if ratio > 0 else -math.inf, float(stats.f.sf(ratio, n, dof))
        else:
            above, p_value = math.nan, math.nan
        scores = [score(h, name, e, v) for h in HYPOTHESES]
        cause = choose(scores)
        diagnosis = OutputDiagnosis(name, math.sqrt(variance) if dof else math.nan, dof, error_rms, n, above,
                                    p_value, bool(p_value < ALPHA), scores, cause,
                                    unit=(units or {}).get(name, ""))
        if cause is not None and dof and variance > 0:
            left = cause.sse_after / (n * variance)
            diagnosis.remainder_above_noise_db = 10 * math.log10(left) if left > 0 else -math.inf
            diagnosis.remainder_significant = bool(stats.f.sf(left, n, dof) < ALPHA)
        outputs.append(diagnosis)
    scales = np.array([o.noise if math.isfinite(o.noise) and o.noise > 0 else (o.error_rms or 1.0) for o in outputs])
    input_scores, notes = [], []
    # an input block moves the outputs: it is sought only where an output's error calls for a cause
    wanted = any(o.significant or o.cause is not None or not math.isfinite(o.noise) for o in outputs)
    for j, name in enumerate(model.inputs if wanted else ()):
        if name in model.input_blocks:
            notes.append(f"input {name}: its hypotheses not tested: it has a block already (fit --model refits "
                         "the block's numbers)")
            continue
        input_scores += [score_input(model, j, h, estimation, validation, val, scales) for h in INPUT_HYPOTHESES]
    n_all = sum(x.size for x, _, _ in val)
    input_cause, side = choose_side(outputs, input_scores, scales, n_all)
    if input_cause is not None:  # it replaces the outputs' causes, against which it was chosen
        for k, o in enumerate(outputs):
            o.cause, o.input_cause = None, input_cause
            o.remainder_above_noise_db, o.remainder_significant = math.nan, False
            if o.noise_dof and math.isfinite(o.noise) and o.noise > 0:
                left = input_cause.outputs[o.name]["sse_after"] / (o.samples * o.noise ** 2)
                o.remainder_above_noise_db = 10 * math.log10(left) if left > 0 else -math.inf
                o.remainder_significant = bool(stats.f.sf(left, o.samples, o.noise_dof) < ALPHA)
    extended = None
    if input_cause is not None or any(o.cause is not None for o in outputs):
        data, added, added_inputs = extended_config(config_data, outputs, input_cause)
        if data is not None:  # its validation error per output: the named causes' fitted level
            pairs = compared(build(validate_simulate_config(data, source, {})), validation)
            for entry in added:
                s_i = samples_of(pairs, list(model.outputs).index(entry["name"]))
                entry["error_rms"] = math.sqrt(s_i.sse() / float(np.sum(s_i.w))) if s_i.x.size else math.nan
        extended = ExtendedModel(data, added, added_inputs)
    frm, note = frm_comparison(model, runs, where)
    from nlsid.diagnose.hypotheses import LIBRARY

    not_tested = [{"hypothesis": h.name, "title": h.title, "reason": NOT_TESTED}
                  for h in LIBRARY if h.name not in TESTED_PER_OUTPUT and h.name not in TESTED_PER_INPUT]
    not_tested.append({"hypothesis": "yardstick", "title": "The black-box yardstick", "reason": NO_YARDSTICK})
    return MimoDiagnosis(source, tuple(model.inputs), outputs, frm, note, not_tested,
                         [run.run_id for run in estimation], [run.run_id for run in validation], extended,
                         input_scores, input_cause, side, notes)
