"""Which stages a recording can feed: the checks on a recording's runs that the stages and ``nlsid info`` share.

Every stage that reads a recording validates the runs it uses with the functions and classes of
this module, and ``nlsid info`` runs the same checks over every run (:class:`Survey`) to say which
stages the file can feed. So info's verdict is the stage's own: the same check, the same one-line
message (``WHERE: WHAT``), found in the same order of runs (with other options a stage can stop
earlier, at an option-dependent check of an earlier run).

Two kinds of conditions:

- **Structural**: they depend on the file alone (with the stage's ``auto`` choices, which the file
  decides: ``bla --method auto`` uses the reference method when the runs carry r, ``hosidf
  --input auto`` the reference when the first sine run has one). A violation is the reason a
  recording cannot feed the stage.
- **Option-dependent**: they depend on a number or a file the user chooses (``hosidf
  --harmonics`` and ``--variance``, the model of ``diagnose`` and ``fit --model``,
  ``--validation``, ``--start-estimate``). The stages raise them for the options given;
  ``nlsid info`` reports them as notes, evaluated for the default options, not as a promise.

Stages (:data:`STAGES`): ``bla`` and ``hosidf`` (grid mode) read multisine and single-sine runs,
``diagnose`` the periodic runs, ``fit --model`` every run, each with a measured output y;
``simulate --excitation`` only the inputs, and only files in the nlsid layout (it has no ``--map``).
Runs with several inputs are simulated by a ``mimo_state_space`` model that takes their inputs (the
model is an option: info says which inputs it needs); a recording whose runs no one model can take
(:func:`simulate_inputs`) cannot feed ``simulate``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

from nlsid.citations import MOTION_STAGES
from nlsid.errors import InputError
from nlsid.io.run import MISSING_Y, Run, missing_references, reference_names

STAGES = ("bla", "hosidf", "diagnose", "fit --model", "simulate --excitation")

#: A sine run's frequency attribute is on a bin when ``|frequency*N/fs - bin|`` is below this.
BIN_TOLERANCE = 1e-6
#: The fewest harmonics ``hosidf`` accepts (seed 003 Table I uses k = 1..K, K >= 2).
MIN_HARMONICS = 2
#: The default of ``hosidf --harmonics`` (cli/hosidf.py; not imported there, to keep numpy out of start-up).
DEFAULT_HARMONICS = 5
#: An excited line carries no input when its amplitude is at most this fraction of the strongest.
NO_INPUT = 1e-12


# --- the measured output ------------------------------------------------------------------------

def missing_output(recording, run: Run) -> InputError | None:
    """What a reader opened with ``require_y=True`` raises for ``run`` of the open ``recording``
    (read with ``require_y=False``), or None: the file-level error of an excitation file, or the
    run's own missing dataset ``y``."""
    error = recording.output_error()
    if error is not None:
        return error
    if run.y is None:
        return InputError(recording.run_where(run.run_id), MISSING_Y)
    return None


# --- bla: multisine levels ----------------------------------------------------------------------

def uses_reference(method: str, run: Run) -> bool:
    """Whether the robust method of a level whose first run is ``run`` projects on the reference r."""
    return method == "reference" or (method == "auto" and run.r is not None)


class LevelShape:
    """What the realizations of one BLA level share, fixed by its first run: fs, period, excited
    lines, steady-state periods, the use of r, and distinct realization indices."""

    def __init__(self, run: Run, method: str):
        self.level = run.level
        self.fs, self.period, self.n_periods = run.fs, run.period, run.n_periods
        self.excited = np.asarray(run.excited_bins, dtype=np.int64)
        self.use_reference = uses_reference(method, run)
        self.first = run.run_id
        self.realizations: dict[int, str] = {}

    @property
    def name(self) -> str:
        return f"level {self.level:g}" if self.level is not None else "runs without a level"

    def check(self, run: Run, where: str) -> None:
        """Runs of one level must share fs, period, excited lines, periods and (for ``reference``) r."""
        name = self.name
        if run.period != self.period or run.fs != self.fs:
            raise InputError(where, f"period {run.period} at fs {run.fs:g} differs from run {self.first} of {name} "
                                    f"(period {self.period} at fs {self.fs:g}); one level needs one period")
        if not np.array_equal(run.excited_bins, self.excited):
            raise InputError(f"{where}.excited_bins", f"differ from those of run {self.first} of {name}; "
                                                      "realizations of one level must excite the same lines")
        if run.n_periods != self.n_periods:
            raise InputError(where, f"{run.n_periods} steady-state periods, run {self.first} of {name} has "
                                    f"{self.n_periods}; realizations of one level need the same P")
        if self.use_reference and run.r is None:
            raise InputError(where, f"no reference r, which the reference method of {name} needs")
        if run.realization is not None:
            other = self.realizations.setdefault(run.realization, run.run_id)
            if other != run.run_id:
                raise InputError(f"{where}.realization", f"{run.realization} is also run {other} of {name}; "
                                                         "each run must be a new realization of the random phases")

    def check_input(self, run: Run, where: str) -> None:
        """Every excited line carries input (and, for the reference method, reference) power."""
        R = np.fft.rfft(run.periods("r").mean(axis=0)) if self.use_reference else None
        self.check_spectra(np.fft.rfft(run.periods("u").mean(axis=0)), R, where)

    def check_spectra(self, U: np.ndarray, R: np.ndarray | None, where: str) -> None:
        """:meth:`check_input` on the spectra of the run's mean period of u (and r, for the
        reference method), at bins 0..N//2 and at any scale: the analysis has them at hand."""
        U = np.abs(U[self.excited])
        no_reference = False
        if self.use_reference:
            no_reference = bool(np.any(R[self.excited] == 0))
        if np.any(U <= NO_INPUT * U.max()) or no_reference:
            bad = int(self.excited[np.argmin(U)])
            raise InputError(f"{where}/u", f"excited bin {bad} carries no input; "
                                           "excited_bins does not match the signal")


class BlaRuns:
    """The checks of the BLA over a stream of ``(run, where)``: :meth:`add` each run, then :meth:`finish`.

    Multisine runs feed the robust and fast methods, arbitrary runs the Local Polynomial Method
    (:mod:`nlsid.analysis.arbitrary`); sines are skipped (they are for ``hosidf``). Runs with
    several inputs or outputs feed the frequency response matrix (:func:`check_mimo_run`; listed
    in ``mimo``; their levels are checked by :mod:`nlsid.analysis.frm_levels`). With
    ``check_input=False`` :meth:`add` makes the structural checks only and the caller runs
    :meth:`LevelShape.check_spectra` on the spectra it computes anyway (the BLA analysis).
    """

    def __init__(self, method: str = "auto", check_input: bool = True):
        self.method = method
        self.check_input = check_input
        self.levels: dict[float | None, LevelShape] = {}
        self.arbitrary: list[str] = []
        self.skipped: list[str] = []
        self.mimo: list[str] = []
        # per (kind, level) of the runs with several inputs or outputs: their inputs' references
        self.mimo_references: dict[tuple[str, float | None], MimoReferences] = {}

    def add(self, run: Run, where: str) -> LevelShape | None:
        """Check one run; return its level's shape, or None for a run that is not a multisine
        of one input and one output (an arbitrary run, checked and listed in ``arbitrary``, a run
        with several inputs or outputs, checked and listed in ``mimo``, or a skipped one)."""
        if run.is_mimo:
            check_mimo_run(run, where)
            self.mimo.append(run.run_id)
            key = (run.kind, run.level)
            self.mimo_references.setdefault(key, MimoReferences(reference_names(len(run.inputs)))).add(run)
            return None
        if run.kind == "arbitrary":
            check_arbitrary_run(run, where, self.method)
            self.arbitrary.append(run.run_id)
            return None
        if run.kind != "multisine":
            self.skipped.append(run.run_id)
            return None
        shape = self.levels.get(run.level)
        if shape is None:
            shape = self.levels[run.level] = LevelShape(run, self.method)
        shape.check(run, where)
        if self.check_input:
            shape.check_input(run, where)
        return shape

    def finish(self, source: str) -> None:
        if not self.levels and not self.arbitrary and not self.mimo:
            raise InputError(source, "holds no multisine or arbitrary runs; the BLA needs random-phase multisines "
                                     "or arbitrarily excited records (sines are for `nlsid hosidf`)")


@dataclass
class MimoReferences:
    """Whether ``bla --method auto`` takes the frequency response matrix of one level of runs with
    several inputs or outputs from the references (:func:`nlsid.io.run.reference_names`): where
    every run carries them all (:mod:`nlsid.analysis.frm_levels`)."""

    names: tuple[str, ...]
    carried: bool = False
    lacking: tuple[str, list[str]] | None = None

    def add(self, run: Run) -> None:
        self.carried = self.carried or run.r is not None
        missing = missing_references(run)
        if missing and self.lacking is None:
            self.lacking = (run.run_id, missing)

    def note(self, kind: str, level: float | None) -> str | None:
        """What ``nlsid info`` says of the level; None where no run carries a reference."""
        if not self.carried:
            return None
        what = f"the frequency response matrix of the {kind} runs of level {level}"
        if self.lacking is None:
            return f"--method auto takes {what} from the references {', '.join(self.names)}"
        run_id, missing = self.lacking
        return (f"--method auto takes {what} not from the references ({', '.join(self.names)}): run {run_id} "
                f"lacks {', '.join(missing)}")


def several_inputs_outputs(run: Run, where: str, reader: str = "a model of one input u and one output y"
                           ) -> InputError | None:
    """The error of the stages of one input and one output (``simulate`` of such a model, ``fit --model``,
    ``diagnose``) on a run with several inputs or outputs; None for a run of one of each. Taking u
    and y alone would drop the other inputs and outputs silently."""
    if not run.is_mimo:
        return None
    return InputError(where, f"has inputs {', '.join(run.inputs)} and outputs {', '.join(run.outputs)}: {reader} "
                             "cannot use it without dropping the others (several inputs and outputs: `nlsid bla`, and "
                             "`nlsid simulate` of a mimo_state_space model, docs/mimo.md)")


def check_mimo_run(run: Run, where: str) -> None:
    """A run with several inputs or outputs feeds the frequency response matrix when it is a
    multisine (orthogonal multisines) or an arbitrary run (the LPM for several inputs) with its
    outputs measured."""
    if run.kind not in ("multisine", "arbitrary"):
        raise InputError(where, f"a run with several inputs or outputs ({', '.join(run.inputs)} -> "
                                f"{', '.join(run.outputs)}) must be a multisine or an arbitrary run for the "
                                f"frequency response matrix, got kind {run.kind!r}")
    run.output_matrix()  # no y: the run's own error


def check_arbitrary_run(run: Run, where: str, method: str) -> None:
    """An arbitrary run feeds the LPM when it has an exciting input (or reference) and the
    reference the method asks for."""
    if method == "reference" and run.r is None:
        raise InputError(where, "--method reference needs the reference r, which this run does not carry")
    excitation = run.r if (run.r is not None and method in ("auto", "reference")) else run.u
    if not np.ptp(excitation) > 0:
        name = "reference r" if excitation is run.r else "input u"
        raise InputError(where, f"the {name} is constant: it excites nothing")


# --- hosidf: single sines -----------------------------------------------------------------------

def sine_bin(run: Run, where: str) -> int:
    """The DFT bin of a single-sine run's tone in one period; InputError if it is not a sine on a bin."""
    if run.kind != "sine":
        raise InputError(where, f"is a '{run.kind}' run; HOSIDFs need single-sine runs (kind 'sine')")
    exact = run.frequency * run.period / run.fs
    line = int(round(exact))
    if abs(exact - line) > BIN_TOLERANCE or line < 1:
        raise InputError(
            f"{where}.frequency",
            f"{run.frequency:g} Hz is not on a bin of the {run.period}-sample period at fs {run.fs:g} Hz "
            f"(frequency*period/fs = {exact:.6g}, expected an integer)",
        )
    return line


def highest_harmonic(run: Run, line: int) -> int:
    """The highest harmonic of the tone on bin ``line`` that lies below Nyquist of the run's period."""
    return (run.period - 1) // 2 // line


def hosidf_input(first: Run, choice: str) -> str:
    """The signal whose tone normalises the HOSIDFs: ``--input auto`` takes r when the first sine run has it."""
    return choice if choice != "auto" else ("r" if first.r is not None else "u")


def no_sine_runs(source: str) -> InputError:
    return InputError(source, "holds no single-sine runs (kind 'sine'): design a sine grid (`sines:` in the design config)")


def check_sine_run(run: Run, where: str, input_signal: str) -> int:
    """The structural checks of one single-sine run (one input, any number of outputs, tone on a
    bin, harmonic 2 below Nyquist, an amplitude, an input tone); return the tone's bin."""
    if len(run.inputs) > 1:
        raise InputError(where, f"has inputs {', '.join(run.inputs)}: a HOSIDF is a single-input concept "
                                "(H_k = Y(k w0)/U(w0)^k divides by the tone of one input), so runs with several "
                                "inputs cannot give one (several inputs: `nlsid bla`, docs/mimo.md)")
    line = sine_bin(run, where)
    if highest_harmonic(run, line) < MIN_HARMONICS:
        raise InputError(where, f"harmonic {MIN_HARMONICS} of bin {line} ({run.frequency:g} Hz) lies at or above "
                                f"Nyquist of the {run.period}-sample period: no harmonic can be measured")
    if run.level is None:
        raise InputError(where, "missing attribute 'level' (the amplitude of the sine)")
    if getattr(run, input_signal) is None:
        raise InputError(where, f"run has no input signal '{input_signal}'")
    if np.any(np.fft.rfft(run.periods(input_signal), axis=-1)[:, line] == 0):
        raise InputError(where, f"input '{input_signal}' has no content at {run.frequency:g} Hz")
    return line


def check_sine_outputs(run: Run, outputs: tuple[str, ...], where: str) -> None:
    """The sine runs of one HOSIDF analysis measure the same outputs (those of the first), in order:
    a run with others would leave an output without some of its cells."""
    if tuple(run.outputs) != tuple(outputs):
        raise InputError(where, f"has outputs {', '.join(run.outputs)}, the first sine run "
                                f"{', '.join(outputs)}: the HOSIDFs of each output need every run to measure it")


def check_harmonics(run: Run, line: int, harmonics: int, where: str) -> None:
    """``--harmonics``: harmonic K of the tone must lie below Nyquist (option-dependent)."""
    if harmonics * line >= run.period / 2:
        raise InputError(
            where,
            f"harmonic {harmonics} of bin {line} ({run.frequency:g} Hz) lies at or above Nyquist of the "
            f"{run.period}-sample period; use at most {highest_harmonic(run, line)} harmonics",
        )


@dataclass
class SineCell:
    """The repeats of one (frequency, amplitude) cell: their run ids and steady-state periods."""

    frequency: float
    level: float
    run_ids: list[str] = field(default_factory=list)
    periods: list[int] = field(default_factory=list)

    @property
    def n_repeats(self) -> int:
        return len(self.run_ids)

    @property
    def n_periods(self) -> int:
        return self.periods[0]


def check_cells(cells: Iterable[SineCell], source: str) -> None:
    """Each cell needs two spectra (Table I) and repeats of one number of periods (structural)."""
    for cell in cells:
        if cell.n_repeats * cell.periods[0] < 2:
            raise InputError(f"{source}: cell {cell.frequency:g} Hz, amplitude {cell.level:g}",
                             "a single run of a single period: Table I needs at least two spectra")
        if len(set(cell.periods)) != 1:
            raise InputError(cell.run_ids[0], f"repeats of one cell hold different numbers of periods "
                                              f"{sorted(set(cell.periods))}")


def check_variance_counts(cells: Iterable, variance: str, source: str) -> None:
    """``--variance``: InputError when a requested variance lacks data, < 2 repeats or < 2 periods per
    run (option-dependent). ``cells`` have ``frequency``, ``level``, ``n_repeats`` and ``n_periods``."""
    for cell in cells:
        where = f"{source}: cell {cell.frequency:g} Hz, amplitude {cell.level:g}"
        if variance in ("repeats", "both") and cell.n_repeats < 2:
            raise InputError(where, f"{cell.n_repeats} repeat; the variance over repeats ({MOTION_STAGES}, Eq. 12) "
                                    "needs at least 2 (or ask for the variance over periods only)")
        if variance in ("periods", "both") and cell.n_periods < 2:
            raise InputError(where, f"{cell.n_periods} steady-state period per run; the variance over periods "
                                    "needs at least 2 (or ask for the variance over repeats only)")


# --- diagnose and fit --model -------------------------------------------------------------------

def excitation_key(run: Run) -> tuple:
    """What a run excites, for the estimation/validation split: (kind, level, frequency); the
    arbitrary records form one group of their own."""
    if run.period is None:
        return ("arbitrary", None, None)
    return (run.kind, run.level, run.frequency)


def check_repeated_excitation(group_sizes: Iterable[int], where: str) -> None:
    """``diagnose`` needs one excitation with two runs: one to estimate on, one to validate on."""
    if max(group_sizes, default=0) < 2:
        raise InputError(where, "needs two runs (realizations) of one excitation, or two arbitrary records, at "
                                "least: one to estimate the model extensions, one to validate them (or "
                                "--validate-on FILE, or --estimation-range with --validation-range)")


def check_run_count(n_runs: int) -> None:
    """``fit --model`` (default split) needs two runs: some to fit and one to validate on."""
    if n_runs < 2:
        raise InputError("runs", "need at least two runs: some to fit and one to validate on (or --validate-on "
                                 "FILE, or one arbitrary record cut by --estimation-range A:B with "
                                 "--validation-range C:D)")


# --- simulate: the inputs of one model ---------------------------------------------------------

def simulate_inputs(runs: Iterable[tuple[str, tuple[str, ...], frozenset[str]]]) -> tuple[str, ...]:
    """The inputs of the one model that can simulate every run: the runs' inputs in order of first
    appearance (``u`` first), from ``(run id, inputs, channel names)`` of each run. A model of more
    inputs would need channels the runs lack; of fewer, it would drop an input."""
    names: list[str] = []
    for _, inputs, _ in runs:
        names += [name for name in inputs if name not in names]
    return tuple(names)


# --- nlsid info: every stage's verdict ----------------------------------------------------------

@dataclass
class Verdict:
    """Whether a recording can feed one stage; ``reason`` is the stage's own error line when not,
    ``notes`` what depends on options (evaluated for the default options)."""

    stage: str
    feeds: bool = True
    reason: str | None = None
    notes: list[str] = field(default_factory=list)

    def fail(self, error: InputError) -> None:
        if self.feeds:
            self.feeds, self.reason = False, str(error)

    def summary(self) -> dict:
        return {"feeds": self.feeds, "reason": self.reason, "notes": list(self.notes)}


class Survey:
    """The checks of every stage (:data:`STAGES`) over the runs of one open recording, run by run.

    ``path`` is the recording as named on the command line (the stages name it so), ``mapping``
    the ``--map`` of a foreign MCAP file. :meth:`add` each run as read with ``require_y=False``,
    then :meth:`verdicts`. Memory holds a few numbers per level and sine cell, not the runs.
    """

    def __init__(self, recording, path: str, mapping: Mapping[str, str] | None = None):
        self.recording, self.path, self.mapping = recording, str(path), dict(mapping or {})
        self.verdict = {stage: Verdict(stage) for stage in STAGES}
        self.bla = BlaRuns("auto")
        # hosidf (grid mode, --input auto)
        self.sine_signal: str | None = None
        self.sine_outputs: tuple[str, ...] = ("y",)
        self.cells: dict[tuple[float, float], SineCell] = {}
        self.top_harmonic: int | None = None  # the highest --harmonics every sine run allows
        self.harmonics_error: InputError | None = None  # what the default --harmonics gives first
        # diagnose: the first error of each kind, in the order the stage meets them
        self.diagnose_y: InputError | None = None
        self.diagnose_bla = BlaRuns("auto")
        self.diagnose_bla_error: InputError | None = None
        self.diagnose_sine_error: InputError | None = None
        self.groups: dict[tuple, int] = {}
        # fit --model
        self.fit_y: InputError | None = None
        self.n_runs = 0
        self.without_r: list[str] = []
        self.periodic_without_r: list[str] = []
        self.arbitrary: list[str] = []
        # simulate --excitation: each run's inputs and channel names, the first run of several
        self.simulate_runs: list[tuple[str, tuple[str, ...], frozenset[str]]] = []
        self.several: InputError | None = None

    def add(self, run: Run) -> None:
        """Check one run for every stage."""
        where = f"{self.path}:/runs/{run.run_id}"
        no_y = missing_output(self.recording, run)
        self.n_runs += 1
        if run.r is None:
            self.without_r.append(run.run_id)
            if run.period is not None:
                self.periodic_without_r.append(run.run_id)
        if run.period is None:
            self.arbitrary.append(run.run_id)
        self._bla(run, where, no_y)
        self._hosidf(run, where, no_y)
        self._diagnose(run, where, no_y)
        if self.fit_y is None and no_y is not None:
            self.fit_y = no_y
        self.simulate_runs.append((where, tuple(run.inputs), frozenset(run.channels)))
        several = several_inputs_outputs(run, where)
        if several is not None:  # a model of one input and one output stops at the first such run (a note)
            self.several = self.several or several

    def _bla(self, run: Run, where: str, no_y: InputError | None) -> None:
        verdict = self.verdict["bla"]
        if not verdict.feeds:
            return
        try:
            if no_y is not None:
                raise no_y
            self.bla.add(run, where)
        except InputError as exc:
            verdict.fail(exc)

    def _hosidf(self, run: Run, where: str, no_y: InputError | None) -> None:
        verdict = self.verdict["hosidf"]
        if not verdict.feeds:
            return
        try:
            if no_y is not None:
                raise no_y
            if run.kind != "sine":
                return
            if self.sine_signal is None:
                self.sine_signal = hosidf_input(run, "auto")
                self.sine_outputs = tuple(run.outputs)
            line = check_sine_run(run, where, self.sine_signal)
            check_sine_outputs(run, self.sine_outputs, where)
        except InputError as exc:
            verdict.fail(exc)
            return
        top = highest_harmonic(run, line)
        self.top_harmonic = top if self.top_harmonic is None else min(top, self.top_harmonic)
        if self.harmonics_error is None:
            try:
                check_harmonics(run, line, DEFAULT_HARMONICS, where)
            except InputError as exc:
                self.harmonics_error = exc
        cell = self.cells.setdefault((run.frequency, run.level), SineCell(run.frequency, run.level))
        cell.run_ids.append(run.run_id)
        cell.periods.append(run.n_periods)

    def _diagnose(self, run: Run, where: str, no_y: InputError | None) -> None:
        if no_y is not None:
            self.diagnose_y = self.diagnose_y or no_y
            return
        key = excitation_key(run)
        self.groups[key] = self.groups.get(key, 0) + 1
        try:
            if self.diagnose_bla_error is None and run.kind == "multisine":
                self.diagnose_bla.add(run, where)
            if self.diagnose_sine_error is None and run.kind == "sine":
                sine_bin(run, f"run {run.run_id}")
        except InputError as exc:
            if run.kind == "multisine":
                self.diagnose_bla_error = exc
            else:
                self.diagnose_sine_error = exc

    def verdicts(self) -> dict[str, Verdict]:
        """The verdict of every stage after the last run."""
        self._finish_bla()
        self._finish_hosidf()
        self._finish_diagnose()
        self._finish_fit()
        self._finish_simulate()
        return self.verdict

    def _finish_bla(self) -> None:
        verdict = self.verdict["bla"]
        if verdict.feeds:
            try:
                self.bla.finish(self.path)
            except InputError as exc:
                verdict.fail(exc)
        reference = [shape.name for shape in self.bla.levels.values() if shape.use_reference]
        if reference:
            verdict.notes.append(f"--method auto uses the reference method (r) for {', '.join(reference)}")
        if self.bla.skipped:
            verdict.notes.append(f"skips {len(self.bla.skipped)} runs that are not multisines")
        if self.bla.mimo:
            verdict.notes.append(f"{len(self.bla.mimo)} runs with several inputs or outputs: the frequency "
                                 "response matrix per level")
        for (kind, level), references in self.bla.mimo_references.items():
            note = references.note(kind, level)
            if note is not None:
                verdict.notes.append(note)

    def _finish_hosidf(self) -> None:
        verdict = self.verdict["hosidf"]
        if verdict.feeds and self.sine_signal is None:
            verdict.fail(no_sine_runs(self.path))
        if verdict.feeds:
            try:
                check_cells(self.cells.values(), self.path)
            except InputError as exc:
                verdict.fail(exc)
        if not verdict.feeds:
            return
        top = self.top_harmonic
        if self.harmonics_error is not None:
            verdict.notes.append(f"--harmonics {top} at most; the default {DEFAULT_HARMONICS} stops it: "
                                 f"{self.harmonics_error}")
        else:
            verdict.notes.append(f"--harmonics {top} at most")
        refused = {}
        for variance in ("both", "repeats", "periods"):
            try:
                check_variance_counts(self.cells.values(), variance, self.path)
            except InputError as exc:
                refused[variance] = exc
        if "repeats" in refused and "periods" in refused:  # no --variance serves every cell
            verdict.fail(refused["both"])
            return
        if "both" in refused:
            works = "periods" if "repeats" in refused else "repeats"
            verdict.notes.append(f"the default --variance both stops it: {refused['both']}; "
                                 f"--variance {works} does not")
        if self.sine_signal == "r":
            verdict.notes.append("--input auto normalises by the reference r")

    def _finish_diagnose(self) -> None:
        verdict = self.verdict["diagnose"]  # the stage reads every run, splits them, then checks them
        if self.diagnose_y is not None:
            verdict.fail(self.diagnose_y)
        if verdict.feeds:
            try:
                check_repeated_excitation(self.groups.values(), self.path)
            except InputError as exc:
                verdict.fail(exc)
        for error in (self.diagnose_bla_error, self.diagnose_sine_error):
            if error is not None:
                verdict.fail(error)
        if self.periodic_without_r:
            verdict.notes.append(_closed_loop_note(self.periodic_without_r))
        if self.arbitrary:
            verdict.notes.append(f"does not use the {len(self.arbitrary)} arbitrary (non-periodic) runs")
        self._mimo_model_note(verdict)

    def _finish_fit(self) -> None:
        verdict = self.verdict["fit --model"]
        if self.fit_y is not None:
            verdict.fail(self.fit_y)
        if verdict.feeds:
            try:
                check_run_count(self.n_runs)
            except InputError as exc:
                verdict.fail(exc)
        if self.without_r:
            verdict.notes.append(_closed_loop_note(self.without_r))
        if self.arbitrary:
            verdict.notes.append(f"--start-estimate needs periodic runs with excited bins; {self.arbitrary[0]} "
                                 "is arbitrary")
        self._mimo_model_note(verdict)

    def _mimo_model_note(self, verdict: Verdict) -> None:
        """Runs with several inputs or outputs feed ``diagnose`` and ``fit --model`` of a
        ``mimo_state_space`` model (docs/mimo.md); a model of one input and one output refuses the
        first such run, which the note quotes."""
        if self.several is not None and verdict.feeds:
            verdict.notes.append(f"needs a mimo_state_space model of the runs' inputs and outputs (docs/mimo.md); a "
                                 f"model of one input and one output stops: {self.several}")

    def _finish_simulate(self) -> None:
        if self.mapping:
            from nlsid.io.recording import open_recording

            try:  # simulate --excitation has no --map: what it says of the file without one
                with open_recording(self.path, require_y=False):
                    pass
            except InputError as exc:
                verdict = self.verdict["simulate --excitation"]
                verdict.fail(exc)
                verdict.notes.append("simulate has no --map: convert the file with nlsid import first")
        if self.several is not None:
            self._simulate_several()

    def _simulate_several(self) -> None:
        """Runs with several inputs or outputs: a ``mimo_state_space`` model of the runs' inputs
        simulates them all, unless a run lacks one of those inputs (that model's own refusal);
        a model of one input and one output refuses the first such run (a note)."""
        from types import SimpleNamespace

        from nlsid.simulate.mimo import check_run

        verdict = self.verdict["simulate --excitation"]
        inputs = simulate_inputs(self.simulate_runs)
        for where, names, channels in self.simulate_runs:
            try:
                check_run(inputs, ("y",), SimpleNamespace(inputs=names, outputs=("y",), channels=channels), where)
            except InputError as exc:
                verdict.fail(exc)
                return
        verdict.notes.append(f"needs a mimo_state_space model of the inputs {', '.join(inputs)} (docs/mimo.md); a "
                             f"model of one input and one output stops: {self.several}")


def _closed_loop_note(runs: Sequence[str]) -> str:
    shown = ", ".join(runs[:3]) + (", ..." if len(runs) > 3 else "")
    count = "1 run has" if len(runs) == 1 else f"{len(runs)} runs have"
    return f"a model with a closed_loop section needs r in every run; {count} none ({shown})"

