"""The frequency response matrix of a recording's runs with several inputs or outputs, per level.

A run that names several inputs or outputs (``Run.is_mimo``, recording format version 3) is one
experiment: the n_u inputs it applied, the n_y outputs it measured. The runs of one excitation
level are grouped by realization (``Run.realization``; a run without one is a realization of its
own) and, within a realization, ordered by experiment (``Run.experiment``, else by run id). With
M realizations of E >= n_u experiments of P steady-state periods, the FRM, the MIMO BLA, and its
noise and total covariances follow from :func:`nlsid.analysis.frm.frm` (Schoukens, Pintelon and
Rolain 2012, Eq. 6-117 and Section 6.1.1; ``docs/mimo.md``).

The runs of a level must share their inputs and outputs (names, in order), sample rate, period,
excited bins and number of steady-state periods, and every realization must hold as many
experiments: anything else is one InputError naming the run and what differs.

Where every multisine run of a level carries one reference per input
(:func:`nlsid.io.run.reference_names`), ``bla --method auto`` and ``reference`` take its FRM from
the references (:func:`nlsid.analysis.frm.frm_reference`, per realization ``(Y R^+) (U R^+)^-1``):
the same numbers where a realization holds n_u experiments, unbiased in a closed loop where it
holds more (``docs/mimo.md``).

Arbitrary runs (kind ``arbitrary``: noise, sweeps, trajectories) with several inputs or outputs
give the FRM by the Local Polynomial Method for several inputs instead
(:func:`nlsid.analysis.lpm_mimo.lpm_mimo`, book Section 7.2; :class:`LpmFrmLevel`): the runs of a
level are records that share G, each with its own transient, cut to the shortest. Its variances
hold the noise and the stochastic nonlinear distortion together (the local model cannot tell them
apart), so they bound the noise from above; every such level says so in its warnings.

Where every run of such a level carries one reference per input (:func:`reference_names`: ``r``,
then the channels ``r2``, ``r3``, ... up to ``r<n_u>``, as the inputs are ``u``, ``u2``, ...), the
FRM is the indirect ratio of the LPM with references
(:func:`nlsid.analysis.lpm_mimo.lpm_mimo_reference`): unbiased in a closed loop or with noisy
inputs, where the LPM from u is not. ``bla --method auto`` and ``reference`` use it (``reference``
refuses a run without its references), ``frf`` and ``io`` take u as known.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator

import numpy as np

from nlsid.analysis.arbitrary import BAND_DB
from nlsid.analysis.confidence import Bounds
from nlsid.analysis.frm import FrequencyResponseMatrix, frm, frm_reference
from nlsid.analysis.lpm import DEFAULT_DEGREE, DEFAULT_HALF_WIDTH
from nlsid.analysis.lpm_mimo import (MimoLPMResult, degrees_of_freedom, lpm_mimo, lpm_mimo_reference,
                                     narrowest_half_width)
from nlsid.errors import InputError
from nlsid.feeds import check_mimo_run
from nlsid.io.run import Run, missing_references, reference_names


@dataclass
class FrmLevel:
    """The FRM of one excitation level.

    Attributes
    ----------
    level : float or None
        The runs' level attribute (None when they carry none).
    fs : float
        Sample rate (Hz).
    period : int
        N, samples per period.
    inputs, outputs : tuple of str
        The names of the inputs (columns of G) and outputs (rows of G), as the runs name them.
    run_ids : list of list of str
        ``run_ids[m][e]``: the run of experiment e of realization m.
    units : dict
        The unit of each input and output the runs record alike.
    frm : FrequencyResponseMatrix
        G (F, n_y, n_u), its standard deviations, covariances and bounds.
    references : tuple of str
        The references G is taken from (``r``, ``r2``, ...; ``frm.method`` is ``"frm_reference"``),
        empty where it is from the inputs.
    """

    level: float | None
    fs: float
    period: int
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    run_ids: list[list[str]]
    units: dict[str, str]
    frm: FrequencyResponseMatrix
    references: tuple[str, ...] = ()

    @property
    def warnings(self) -> list[str]:
        return self.frm.warnings

    def summary(self) -> dict:
        """The level's scalars (``nlsid bla --json``, ``frm_levels``): counts, band, and per entry
        (output i, input a) the band means ``bla_db`` = mean 20 log10 |G_ia| and
        ``noise_var_db``, ``total_var_db`` = 10 log10 of the mean of var / |G_ia|^2 (NaN where a
        variance cannot be estimated). A level taken from the references adds ``method``
        (``frm_reference``) and ``references``; one from the inputs has neither key."""
        result = self.frm
        with np.errstate(divide="ignore", invalid="ignore"):
            magnitude2 = np.abs(result.G) ** 2
            rows = []
            for i, output in enumerate(self.outputs):
                for a, name in enumerate(self.inputs):
                    rows.append({
                        "output": output, "input": name,
                        "bla_db": _db(np.mean(10 * np.log10(magnitude2[:, i, a]))),
                        "noise_var_db": _db10(np.mean(result.std_noise[:, i, a] ** 2 / magnitude2[:, i, a])),
                        "total_var_db": _db10(np.mean(result.std_total[:, i, a] ** 2 / magnitude2[:, i, a])),
                    })
        out = {
            "level": self.level, "inputs": list(self.inputs), "outputs": list(self.outputs),
            "realizations": result.n_realizations, "experiments": result.n_experiments,
            "periods": result.n_periods, "excited_lines": int(result.bins.size),
            "band_hz": [float(result.frequency[0]), float(result.frequency[-1])],
            "entries": rows, "detection": None if result.detection is None else result.detection.summary(),
            "warnings": list(result.warnings),
        }
        if self.references:
            out.update(method=result.method, references=list(self.references))
        return out


def _db(value: float) -> float:
    """A dB value as a float, NaN where it is not finite."""
    value = float(value)
    return value if np.isfinite(value) else float("nan")


def _db10(power: float) -> float:
    return _db(10 * np.log10(power)) if np.isfinite(power) and power > 0 else float("nan")


@dataclass
class MimoRuns:
    """Sets aside the runs with several inputs or outputs from a stream of ``(run, where)`` pairs
    (:meth:`take`), then gives their FRM per level: of the multisine runs (:meth:`levels`) and,
    by the LPM for several inputs, of the arbitrary runs (:meth:`lpm_levels`).

    ``on_run`` is called with each run set aside, as the single-input analysis calls it with the
    others; ``others`` counts the runs passed on; ``exhausted`` says the stream was read to its end.
    """

    on_run: Callable[[Run], None] | None = None
    runs: list[tuple[Run, str]] = field(default_factory=list)
    others: int = 0
    exhausted: bool = False

    def take(self, pairs: Iterable[tuple[Run, str]]) -> Iterator[tuple[Run, str]]:
        """The pairs of runs with one input and one output; the others are kept for :meth:`levels`."""
        for run, where in pairs:
            if not run.is_mimo:
                self.others += 1
                yield run, where
                continue
            check_mimo_run(run, where)
            self.runs.append((run, where))
            if self.on_run is not None:
                self.on_run(run)
        self.exhausted = True

    @property
    def only_mimo(self) -> bool:
        """Whether the stream was read to its end and every run had several inputs or outputs (and
        there was at least one)."""
        return self.exhausted and bool(self.runs) and self.others == 0

    def levels(self, confidence: float = 0.95, source: str = "recording", method: str = "auto") -> list[FrmLevel]:
        """The FRM of each level of the multisine runs set aside, sorted by level (a level of None first;
        ``method`` as ``bla --method``: the references' use, :func:`level_frm`)."""
        by_level = self._by_level("multisine")
        return [level_frm(pairs, confidence, f"{source}: level {key}", method) for key, pairs in by_level.items()]

    def lpm_levels(self, confidence: float = 0.95, source: str = "recording", half_width: int = DEFAULT_HALF_WIDTH,
                   degree: int = DEFAULT_DEGREE, method: str = "auto") -> list["LpmFrmLevel"]:
        """The FRM by the MIMO LPM of each level of the arbitrary runs set aside, sorted by level
        (``method`` as ``bla --method``: the references' use, :func:`level_lpm`)."""
        by_level = self._by_level("arbitrary")
        return [level_lpm(pairs, confidence, f"{source}: level {key} (arbitrary runs)", half_width, degree, method)
                for key, pairs in by_level.items()]

    def _by_level(self, kind: str) -> dict[float | None, list[tuple[Run, str]]]:
        """The runs of one kind by level, in order of level (None first)."""
        by_level: dict[float | None, list[tuple[Run, str]]] = {}
        for run, where in self.runs:
            if run.kind == kind:
                by_level.setdefault(run.level, []).append((run, where))
        return {key: by_level[key] for key in sorted(by_level, key=lambda level: (level is not None, level or 0.0))}


def level_frm(pairs: list[tuple[Run, str]], confidence: float, label: str, method: str = "auto") -> FrmLevel:
    """The FRM of the runs of one level (``label`` names the level in messages).

    With ``method`` ``auto`` or ``reference`` and one reference per input in every run
    (:func:`nlsid.io.run.reference_names`), G is that of
    :func:`nlsid.analysis.frm.frm_reference`, from the references' period-averaged spectra;
    ``reference`` refuses a run without them; otherwise (and with ``frf``, ``io``) it is
    :func:`nlsid.analysis.frm.frm`'s, and references that are not used are named in the warnings.
    """
    first = pairs[0][0]
    for run, where in pairs[1:]:
        _check_alike(first, run, where)
    warnings: list[str] = []
    use_references = _use_references(pairs, method, warnings, FROM_INPUTS_FRM)
    references = reference_names(len(first.inputs)) if use_references else ()
    realizations = _realizations([run for run, _ in pairs], label, len(first.inputs))
    u = np.stack([[_steady(run.input_matrix(), run) for run in experiments] for experiments in realizations])
    y = np.stack([[_steady(run.output_matrix(), run) for run in experiments] for experiments in realizations])
    try:
        if use_references:
            r = np.stack([[_steady(np.stack([run.named_signal(name) for name in references]), run)
                           for run in experiments] for experiments in realizations])
            result = frm_reference(r, u, y, first.excited_bins, first.fs, confidence)
        else:
            result = frm(u, y, first.excited_bins, first.fs, confidence)
    except InputError as error:
        raise InputError(label, f"{error.where}: {error.what}") from None
    result.warnings.extend(warnings)
    units = {name: first.units[name] for name in (*first.inputs, *first.outputs)
             if name in first.units and all(run.units.get(name) == first.units[name] for run, _ in pairs)}
    return FrmLevel(level=first.level, fs=first.fs, period=int(first.period), inputs=tuple(first.inputs),
                    outputs=tuple(first.outputs), run_ids=[[run.run_id for run in e] for e in realizations],
                    units=units, frm=result, references=references)


def _steady(x: np.ndarray, run: Run) -> np.ndarray:
    """The (channels, P, N) steady-state periods of an (channels, n) array of a run."""
    start = run.transient_periods * run.period
    return x[:, start:].reshape(x.shape[0], run.n_periods, run.period)


def _check_alike(first: Run, run: Run, where: str) -> None:
    """A run of the level must match its first run in what the FRM combines."""
    for name, mine, theirs in (
        ("inputs", tuple(run.inputs), tuple(first.inputs)),
        ("outputs", tuple(run.outputs), tuple(first.outputs)),
        ("fs", run.fs, first.fs),
        ("period", run.period, first.period),
        ("steady-state periods", run.n_periods, first.n_periods),
    ):
        if mine != theirs:
            raise InputError(where, f"{name} {mine} differ from those of run {first.run_id} of the same level "
                                    f"({theirs}): one frequency response matrix combines runs of one design")
    if not np.array_equal(run.excited_bins, first.excited_bins):
        raise InputError(f"{where}.excited_bins", f"differ from those of run {first.run_id} of the same level: "
                                                  "orthogonal multisines excite the same lines in every experiment")


def _realizations(runs: list[Run], label: str, n_inputs: int) -> list[list[Run]]:
    """The runs by realization (in order of realization), each list ordered by experiment."""
    groups: dict[tuple, list[Run]] = {}
    for run in runs:
        key = (0, run.realization, "") if run.realization is not None else (1, 0, run.run_id)
        groups.setdefault(key, []).append(run)
    out = []
    for key in sorted(groups):
        experiments = sorted(groups[key], key=lambda run: (run.experiment is None, run.experiment or 0, run.run_id))
        indices = [run.experiment for run in experiments if run.experiment is not None]
        if len(set(indices)) != len(indices):
            raise InputError(label, f"realization {key[1]} holds experiment {_repeated(indices)} twice "
                                    f"({', '.join(run.run_id for run in experiments)})")
        out.append(experiments)
    counts = {len(experiments) for experiments in out}
    if len(counts) > 1:
        detail = ", ".join(f"{e[0].run_id} ...: {len(e)}" for e in out)
        raise InputError(label, f"the realizations hold different numbers of experiments ({detail})")
    if counts.pop() < n_inputs:
        raise InputError(label, f"each realization holds {len(out[0])} experiment(s) (runs), fewer than the "
                                f"{n_inputs} inputs: the frequency response matrix needs n_u independent experiments")
    return out


def _repeated(values: list[int]) -> int:
    seen = set()
    for value in values:
        if value in seen:
            return value
        seen.add(value)
    raise ValueError("no value is repeated")


#: What every level whose FRM is by the LPM says: its variances are not a noise level.
NOT_SEPARABLE = ("the Local Polynomial Method cannot separate the nonlinear distortion from the noise: the "
                 "variances and bounds hold both (an upper bound of the noise); periodic orthogonal multisines "
                 "with P >= 2 periods separate them")


@dataclass
class LpmFrmLevel:
    """The FRM of the arbitrary runs with several inputs or outputs of one level, by the MIMO LPM.

    Attributes
    ----------
    level : float or None
        The runs' level attribute (None when they carry none).
    inputs, outputs : tuple of str
        The names of the inputs (columns of G) and outputs (rows of G).
    run_ids : list of str
        The records, in order.
    units : dict
        The unit of each input and output the runs record alike.
    u_rms : list of float
        The rms of each input about its mean, over the records.
    result : MimoLPMResult
        The LPM at every line 1 .. floor((N-1)/2).
    band : numpy.ndarray
        Indices into ``result.lines`` of the reported lines: where every input's power, smoothed
        over the window, is within ``BAND_DB`` of its largest and G is finite (its variance is
        NaN where rounding left a negative residual energy, on noise-free data).
    excited : numpy.ndarray
        Indices into ``result.lines`` of the band's lines where every input carries power itself;
        the summary's band means are over these.
    confidence : float
        Probability of the bounds.
    warnings : list of str
        Always :data:`NOT_SEPARABLE`; a widened window, records cut to the shortest, references
        not used.
    references : tuple of str
        The references of the indirect method (``r``, ``r2``, ...; ``result.method`` is
        ``"lpm_reference"``), empty where G is from the inputs.
    """

    level: float | None
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    run_ids: list[str]
    units: dict[str, str]
    u_rms: list[float]
    result: MimoLPMResult
    band: np.ndarray
    excited: np.ndarray
    confidence: float
    warnings: list[str] = field(default_factory=list)
    references: tuple[str, ...] = ()

    @property
    def bins(self) -> np.ndarray:
        return self.result.lines[self.band]

    @property
    def frequency(self) -> np.ndarray:
        return self.result.frequencies[self.band]

    @property
    def G(self) -> np.ndarray:
        """G on the band, (F, n_y, n_u)."""
        return self.result.G[self.band]

    @property
    def var_G(self) -> np.ndarray:
        """The variance of each entry (noise plus stochastic nonlinear distortion), (F, n_y, n_u)."""
        return self.result.var_G[self.band]

    @property
    def bounds(self) -> Bounds:
        """Per entry, the circles of probability ``confidence`` with F(2, 2q), on the band."""
        full = self.result.bounds(self.confidence)
        return Bounds(*(getattr(full, name)[self.band] for name in ("radius", "mag_lo", "mag_hi", "phase_lo",
                                                                     "phase_hi")))

    def summary(self) -> dict:
        """The level's scalars (``nlsid bla --json``, ``frm_lpm_levels``): counts, window, band, and
        per entry (output i, input a) over the excited lines ``bla_db`` = mean 20 log10 |G_ia| and
        ``total_var_db`` = 10 log10 of the mean of var / |G_ia|^2 (noise and nonlinear distortion
        together: ``noise_floor`` is ``upper_bound``)."""
        result, excited = self.result, self.excited
        with np.errstate(divide="ignore", invalid="ignore"):
            magnitude2 = np.abs(result.G[excited]) ** 2
            variance = result.var_G[excited]
            rows = [{"output": output, "input": name,
                     "bla_db": _db(np.mean(10 * np.log10(magnitude2[:, i, a]))),
                     "total_var_db": _db10(np.nanmean(variance[:, i, a] / magnitude2[:, i, a]))}
                    for i, output in enumerate(self.outputs) for a, name in enumerate(self.inputs)]
        return {
            "level": self.level, "inputs": list(self.inputs), "outputs": list(self.outputs),
            "records": result.n_records, "samples": result.n_samples, "method": result.method,
            "references": list(self.references),
            "u_rms": [float(value) for value in self.u_rms],
            "lpm": {"lines": 2 * result.half_width + 1, "degree": result.degree, "dof": result.dof},
            "excited_lines": int(excited.size),
            "band_hz": [float(self.frequency[0]), float(self.frequency[-1])],
            "entries": rows, "noise_floor": "upper_bound",
            "floor_source": "LPM residual: noise plus nonlinear distortion",
            "warnings": list(self.warnings),
        }


#: What a level of arbitrary runs whose references are not used takes instead, and (for ``frf`` and
#: ``io``) what that costs.
FROM_INPUTS_LPM = ("the FRM is taken from the inputs as if they were noise-free",
                   " (in a closed loop the output noise then biases it)")
#: The same for a level of orthogonal multisines.
FROM_INPUTS_FRM = ("the FRM is Y U^+ from the inputs: the same as from the references where a realization holds as "
                   "many experiments as inputs, biased in a closed loop where it holds more", "")


def _use_references(pairs: list[tuple[Run, str]], method: str, warnings: list[str],
                    instead: tuple[str, str] = FROM_INPUTS_LPM) -> bool:
    """Whether the level's FRM is the indirect one from the references: ``auto`` where every run
    carries them all, ``reference`` always (InputError naming a run without them); ``frf`` and
    ``io`` never. A reference that is then not used is said in ``warnings``, with what the FRM is
    taken from ``instead`` (:data:`FROM_INPUTS_LPM`, :data:`FROM_INPUTS_FRM`)."""
    names = reference_names(len(pairs[0][0].inputs))
    lacking = [(run, where, missing_references(run)) for run, where in pairs]
    lacking = [(run, where, missing) for run, where, missing in lacking if missing]
    if method == "reference" and lacking:
        run, where, missing = lacking[0]
        raise InputError(where, f"--method reference needs one reference per input ({', '.join(names)}); this run "
                                f"lacks {', '.join(missing)}")
    carried = [run for run, _ in pairs if run.r is not None]
    if method in ("auto", "reference") and not lacking:
        return True
    if carried and method in ("frf", "io"):
        warnings.append(f"the runs' references are not used (--method {method}): {instead[0]}{instead[1]}")
    elif carried:
        run, _, missing = lacking[0]
        warnings.append(f"the runs' reference r is not used: {len(names)} inputs need the references "
                        f"{', '.join(names)}, and run {run.run_id} lacks {', '.join(missing)}; {instead[0]}")
    return False


def level_lpm(pairs: list[tuple[Run, str]], confidence: float, label: str, half_width: int = DEFAULT_HALF_WIDTH,
              degree: int = DEFAULT_DEGREE, method: str = "auto") -> LpmFrmLevel:
    """The FRM by the MIMO LPM of the arbitrary runs of one level (``label`` names it in messages).

    The window is ``2 half_width + 1`` lines, widened (with a warning) to the narrowest that leaves
    a degree of freedom where the level's inputs and records need more (:func:`narrowest_half_width`).
    With ``method`` ``auto`` or ``reference`` and one reference per input in every run
    (:func:`reference_names`), G is the indirect ratio of
    :func:`nlsid.analysis.lpm_mimo.lpm_mimo_reference`, its band where every reference carries power.
    """
    first = pairs[0][0]
    for run, where in pairs[1:]:
        for name, mine, theirs in (("inputs", tuple(run.inputs), tuple(first.inputs)),
                                   ("outputs", tuple(run.outputs), tuple(first.outputs)), ("fs", run.fs, first.fs)):
            if mine != theirs:
                raise InputError(where, f"{name} {mine} differ from those of run {first.run_id} of the same level "
                                        f"({theirs}): the records of one level share one system")
    runs = [run for run, _ in pairs]
    warnings = [NOT_SEPARABLE]
    length = min(run.n_samples for run in runs)
    if any(run.n_samples != length for run in runs):
        warnings.append(f"records of different lengths: all cut to the shortest, {length} samples")
    use_references = _use_references(pairs, method, warnings)
    n_inputs = len(first.inputs)
    needed = narrowest_half_width(len(runs), n_inputs, degree)
    if half_width < needed:
        warnings.append(f"a window of {2 * half_width + 1} lines leaves "
                        f"{degrees_of_freedom(len(runs), n_inputs, half_width, degree)} degrees of freedom with "
                        f"{n_inputs} inputs and {len(runs)} record(s): widened to {2 * needed + 1} lines")
        half_width = needed
    u = np.stack([run.input_matrix()[:, :length] for run in runs])
    y = np.stack([run.output_matrix()[:, :length] for run in runs])
    references = reference_names(n_inputs) if use_references else ()
    r = np.stack([np.stack([run.named_signal(name)[:length] for name in references]) for run in runs]) \
        if use_references else None
    try:
        result = lpm_mimo_reference(r, u, y, first.fs, half_width, degree) if use_references else \
            lpm_mimo(u, y, first.fs, half_width, degree)
    except InputError as error:
        raise InputError(label, f"{error.where}: {error.what}") from None
    regressors = r if use_references else u    # the band: where what the LPM regresses on carries power
    power = np.mean(np.abs(np.fft.rfft(regressors, axis=-1)[..., 1:result.lines.size + 1]) ** 2, axis=0)
    width = 2 * half_width + 1
    smooth = np.array([np.convolve(p, np.ones(width) / width, mode="same") for p in power])
    floor = smooth.max(axis=1, keepdims=True) * 10 ** (-BAND_DB / 10)
    finite = np.all(np.isfinite(result.G), axis=(1, 2))
    band = np.flatnonzero(np.all(smooth >= floor, axis=0) & finite)
    if band.size == 0:
        signals = "reference" if use_references else "input"
        raise InputError(label, f"no line carries power of every {signals}: the records excite nothing the LPM can use")
    excited = band[np.all(power[:, band] >= floor, axis=0)]
    units = {name: first.units[name] for name in (*first.inputs, *first.outputs)
             if name in first.units and all(run.units.get(name) == first.units[name] for run in runs)}
    centred = u - u.mean(axis=-1, keepdims=True)
    u_rms = np.sqrt(np.mean(centred ** 2, axis=(0, 2)))
    return LpmFrmLevel(level=first.level, inputs=tuple(first.inputs), outputs=tuple(first.outputs),
                       run_ids=[run.run_id for run in runs], units=units, u_rms=list(u_rms), result=result,
                       band=band, excited=excited if excited.size else band, confidence=confidence,
                       warnings=warnings, references=references)
