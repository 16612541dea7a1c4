"""The ``hosidf`` stage: Higher Order Sinusoidal Input Describing Functions from single-sine runs.

``nlsid.hosidf(recording)`` gives a :class:`HosidfResult`; the command ``nlsid hosidf`` is this
function, a ``write``, the figures and a summary. Without ``sweep``: the measured HOSIDFs
H_k = Y(k w0)/U(w0)^k of every frequency x amplitude cell with their variances and the noise
bound of each harmonic (:mod:`nlsid.analysis.hosidf`), and with ``model`` the analytic HOSIDFs of
a polynomial block structure (:mod:`nlsid.analysis.hosidf_analytic`). With ``sweep``: the
linearity cost per value of a run parameter (:mod:`nlsid.analysis.linearity_cost`). Runs of one
input and several outputs give the grid of every output (:meth:`HosidfResult.output`).

Examples
--------
>>> import nlsid
>>> h = nlsid.hosidf("sample_data/stage.h5", harmonics=3)
>>> h.H.shape == (h.frequencies.size, h.levels.size, 4)
True
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping

import numpy as np

from nlsid.analysis.hosidf import HOSIDFGrid, RunSpectra
from nlsid.analysis.linearity_cost import Sweep
from nlsid.citations import FRICTION_COMPENSATION
from nlsid.errors import InputError
from nlsid.io.run import Run
from nlsid.stages.recording import Recording

VARIANCE_CHOICES = ("both", "repeats", "periods")
INPUT_CHOICES = ("auto", "u", "r")

#: Where the harmonics' noise bound comes from: it is measured, never assumed (seed 003, Eq. (6)).
NOISE_BOUND = (f"measured: {FRICTION_COMPENSATION}, Eq. 6, eps_k = sigma(k) + 2 varsigma, from the spread of the "
               "spectra over the repeats and periods of each cell (noise, and whatever changes from repeat to repeat)")

#: The resolution of the PNG figures (``--plots``).
DPI = 110


def check_options(harmonics: int, variance: str = "both", input: str = "auto", sweep: str | None = None,
                  model=None, names: Mapping[str, str] | None = None) -> None:
    """The options of :func:`hosidf`, checked; ``names`` maps an argument to how the caller calls it
    (``{"harmonics": "--harmonics"}`` on the command line)."""
    names = names or {}

    def name(argument: str) -> str:
        return names.get(argument, argument)

    if isinstance(harmonics, bool) or not isinstance(harmonics, (int, np.integer)):
        raise InputError(name("harmonics"), f"expected an integer, got {harmonics!r}")
    if harmonics < 2:
        what = ("the linearity cost needs harmonics k = 2..K, K >= 2; got" if sweep is not None else
                "need at least 2 harmonics (Table I uses k = 1..K, K >= 2), got")
        raise InputError(name("harmonics"), f"{what} {harmonics}")
    if variance not in VARIANCE_CHOICES:
        raise InputError(name("variance"), f"expected one of {', '.join(VARIANCE_CHOICES)}, got {variance!r}")
    if input not in INPUT_CHOICES:
        raise InputError(name("input"), f"expected one of {', '.join(INPUT_CHOICES)}, got {input!r}")
    if sweep is not None and (not isinstance(sweep, str) or not sweep):
        raise InputError(name("sweep"), f"expected the name of a run parameter, got {sweep!r}")
    if sweep is not None and model is not None:
        raise InputError(name("model"),
                         f"analytic HOSIDFs apply to a frequency x amplitude grid, not to {name('sweep')}")
    if model is not None and not (isinstance(model, (str, os.PathLike, Mapping)) or hasattr(model, "to_dict")):
        raise InputError(name("model"), "expected a Model (nlsid.Model), a model config's path or its dict, got "
                                        f"{type(model).__name__}")


@dataclass
class HosidfResult:
    """What the ``hosidf`` stage computes: a frequency x amplitude grid of HOSIDFs, or a sweep.

    Arrays of the grid are indexed ``[frequency, amplitude, k]`` with k = 0..``harmonics``
    (``H[:, :, 1]`` is the first HOSIDF, ``H[:, :, 3]`` the third); cells that were not measured
    hold NaN, variances that could not be measured (fewer than two repeats or periods) too.

    Attributes
    ----------
    harmonics : int
        The highest harmonic K.
    input_signal : {"u", "r"}
        The signal whose tone normalises the HOSIDFs (and that a sweep's output should track).
    units : dict
        Signal -> unit that every single-sine run gives it.
    source : str
        Where the runs came from (a path, or ``"recording"``).
    grid : HOSIDFGrid or None
        The grid (:mod:`nlsid.analysis.hosidf`), None for a sweep.
    sweep : Sweep or None
        The linearity-cost sweep (:mod:`nlsid.analysis.linearity_cost`), None for a grid.
    analytic : ndarray or None
        The analytic HOSIDFs of ``model`` (seed 002 Lemma 2), complex (F, A, K+1).
    warnings : list of str
        What the stage left out (runs that are not single sines).
    inputs, configs : list of str
        The recording's and the model config's paths (the provenance of :meth:`write`).
    first_run : tuple or None
        The first run's output periods, spectra and sample rate (the grid's spectrum figure).
    outputs : tuple of str
        The outputs of the runs (``("y",)``, or y and channels: ``Run.outputs``). With several,
        ``grid``, ``first_run`` and the arrays below are those of the first, y; :meth:`output`
        gives the result of any one of them.
    grids, first_runs : dict
        Output name -> its grid, and its first run's periods, spectra and sample rate (empty for a sweep).

    Examples
    --------
    Tones of 2, 5 and 9 Hz at amplitudes 0.5 and 1, two repeats each, through a linear
    mass-spring-damper 1/(m s^2 + c s + k): its first HOSIDF is its frequency response seen
    through the zero-order hold (from the matrix exponential of its state equation). The output
    noise sigma = 1e-6 is the only error once three transient periods let the slowest mode
    (decay rate 5/s) die out: a tone of amplitude a has |U| = N a / 2 in an N-sample DFT, so
    each period's ratio Y/U has noise variance 4 sigma^2 / (N a^2), and the mean of the R P = 4
    ratios a quarter of it. A complex Gaussian error exceeds five of its standard deviations
    with probability exp(-25):

    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "sines": {"period": 200, "frequencies": [2.0, 5.0, 9.0],
    ...                     "amplitudes": [0.5, 1.0], "repeats": 2, "periods": 2, "transient_periods": 3}})
    >>> plant = nlsid.Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0,
    ...                                          "stiffness": 2000.0}, "disturbances": {"y_noise": 1e-6, "seed": 3}})
    >>> h = nlsid.hosidf(plant.simulate(exc), harmonics=3)
    >>> h.frequencies, h.levels, h.bins
    (array([2., 5., 9.]), array([0.5, 1. ]), array([2, 5, 9]))
    >>> h.H.shape, h.n_repeats.tolist(), h.input_signal
    ((3, 2, 4), [[2, 2], [2, 2], [2, 2]], 'u')
    >>> from scipy.linalg import expm
    >>> A = np.array([[0.0, 1.0, 0.0], [-1000.0, -10.0, 0.5], [0.0, 0.0, 0.0]])  # (x, v, u): v' = (u - c v - k x)/m
    >>> Phi = expm(A / 200.0)  # one sample with u held: (x, v)[n+1] = Ad (x, v)[n] + Bd u[n]
    >>> Ad, Bd = Phi[:2, :2], Phi[:2, 2]
    >>> G = np.array([np.linalg.solve(z * np.eye(2) - Ad, Bd)[0] for z in np.exp(2j * np.pi * h.frequencies / 200.0)])
    >>> std = np.sqrt(4 * 1e-6**2 / (200 * h.levels**2) / 4)
    >>> bool(np.all(np.abs(h.H[:, :, 1] - G[:, None]) < 5 * std))
    True
    """

    harmonics: int
    input_signal: str
    units: dict[str, str]
    source: str
    grid: HOSIDFGrid | None = None
    sweep: Sweep | None = None
    analytic: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    configs: list[str] = field(default_factory=list)
    first_run: tuple[np.ndarray, RunSpectra, float] | None = field(default=None, repr=False)
    outputs: tuple[str, ...] = ("y",)
    grids: dict[str, HOSIDFGrid] = field(default_factory=dict, repr=False)
    first_runs: dict[str, tuple[np.ndarray, RunSpectra, float]] = field(default_factory=dict, repr=False)

    def output(self, name: str) -> "HosidfResult":
        """The result of output ``name`` alone (one of :attr:`outputs`): its grid, arrays and figures.

        Each output's HOSIDFs are those of the path from the one input to that output
        (``H_k = Y_i(k w0)/U(w0)^k``)."""
        if name not in self.outputs:
            raise InputError("output", f"expected one of {', '.join(self.outputs)}, got {name!r}")
        if self.grid is None:
            return self
        return replace(self, grid=self.grids[name], first_run=self.first_runs[name], outputs=(name,),
                       grids={name: self.grids[name]}, first_runs={name: self.first_runs[name]})

    # --- the grid's numbers -------------------------------------------------------------------

    def _grid(self) -> HOSIDFGrid:
        if self.grid is None:
            raise AttributeError(f"this HosidfResult holds a sweep of {self.sweep.parameter}, not a grid: "
                                 "see .sweep, .values, .cost")
        return self.grid

    @property
    def frequencies(self) -> np.ndarray:
        """(F,) the tones' frequencies (Hz)."""
        return self._grid().frequencies

    @property
    def levels(self) -> np.ndarray:
        """(A,) the tones' amplitudes (of the input signal)."""
        return self._grid().levels

    @property
    def bins(self) -> np.ndarray:
        """(F,) the DFT bin of each tone in one period."""
        out = np.zeros(self.frequencies.size, dtype=np.int64)
        for (fi, _), cell in self._grid().cells.items():
            out[fi] = cell.line
        return out

    @property
    def n_repeats(self) -> np.ndarray:
        """(F, A) repeats per cell (0: not measured)."""
        return self._grid().counts("n_repeats")

    @property
    def n_periods(self) -> np.ndarray:
        """(F, A) steady-state periods per run of each cell (0: not measured)."""
        return self._grid().counts("n_periods")

    @property
    def H(self) -> np.ndarray:
        """(F, A, K+1) complex: H_k = Y(k w0)/U(w0)^k (seed 002 Eq. 12), mean over repeats."""
        return self._grid().field("h")

    @property
    def H_var_repeats(self) -> np.ndarray:
        """(F, A, K+1) variance of the mean of H over repeats (seed 000 Eq. 12)."""
        return self._grid().field("h_var_repeats").real

    @property
    def H_var_periods(self) -> np.ndarray:
        """(F, A, K+1) variance of the mean of H from the scatter over periods (noise only)."""
        return self._grid().field("h_var_periods").real

    @property
    def H000(self) -> np.ndarray:
        """(F, A, K+1) complex: |Y(k w0)|/|U(w0)| with phase angle Y - k angle U (seed 000 Eqs. 8-9)."""
        return self._grid().field("h000")

    @property
    def H000_var_repeats(self) -> np.ndarray:
        """(F, A, K+1) variance of the mean of :attr:`H000` over repeats."""
        return self._grid().field("h000_var_repeats").real

    @property
    def H000_var_periods(self) -> np.ndarray:
        """(F, A, K+1) variance of the mean of :attr:`H000` over periods."""
        return self._grid().field("h000_var_periods").real

    @property
    def Y(self) -> np.ndarray:
        """(F, A, K+1) complex: the expected output spectrum E{Y(k w0)}, input-phase aligned (seed 003 Table I)."""
        return self._grid().stat("mean")

    @property
    def Y_var_mean(self) -> np.ndarray:
        """(F, A, K+1) sigma^2(k), the variance on the average (seed 003 Table I)."""
        return self._grid().stat("var_mean")

    @property
    def bound(self) -> np.ndarray:
        """(F, A, K+1) the noise bound eps_k = sigma(k) + 2 varsigma (seed 003 Eq. 6)."""
        return self._grid().stat("bound")

    @property
    def significant(self) -> np.ndarray:
        """(F, A, K+1) bool: |E{Y(k w0)}| > eps_k, the harmonic clears its noise bound."""
        return self._grid().stat("significant")

    # --- the sweep's numbers ------------------------------------------------------------------

    def _sweep(self) -> Sweep:
        if self.sweep is None:
            raise AttributeError("this HosidfResult holds a frequency x amplitude grid, not a sweep: see .H, .levels")
        return self.sweep

    @property
    def values(self) -> np.ndarray:
        """(M,) the swept parameter's values, sorted."""
        return self._sweep().values("value")

    @property
    def cost(self) -> np.ndarray:
        """(M,) the linearity cost f_c of seed 003 Definition 3 (Eq. 5) per value."""
        return self._sweep().values("cost")

    @property
    def cost_all(self) -> np.ndarray:
        """(M,) the cost f over all harmonics k = 2..K (seed 003 Definition 2, Eq. 4)."""
        return self._sweep().values("cost_all")

    @property
    def time_error(self) -> np.ndarray:
        """(M,) the largest per-period rms tracking error (seed 003 Eq. 7)."""
        return self._sweep().values("time_error")

    @property
    def optimum(self) -> float:
        """The value with the smallest :attr:`cost`."""
        return self._sweep().optimum

    @property
    def time_optimum(self) -> float:
        """The value with the smallest :attr:`time_error`."""
        return self._sweep().time_optimum

    # --- outputs ------------------------------------------------------------------------------

    def summary(self) -> dict:
        """The ``nlsid hosidf --json`` summary without paths (``output``, ``plots``): ``input_signal``
        and ``grid`` or ``sweep`` (``docs/formats.md``), JSON-ready (NaN as None)."""
        from nlsid.io.result_file import json_safe

        summary: dict = {"input_signal": self.input_signal}
        if self.grid is not None:
            summary["grid"] = {
                "frequencies": self.grid.frequencies, "levels": self.grid.levels, "harmonics": self.grid.harmonics,
                "cells": len(self.grid.cells),
                "significant_cells_per_harmonic": self.significant.sum(axis=(0, 1)),
                "noise_bound": NOISE_BOUND,
            }
            if len(self.outputs) > 1:
                summary["outputs"] = [self.output(name).output_summary() for name in self.outputs]
        if self.sweep is not None:
            s = self.sweep
            summary["sweep"] = {
                "parameter": s.parameter, "frequency": s.frequency, "level": s.level,
                "values": s.values("value"), "cost": s.values("cost"), "time_error": s.values("time_error"),
                "optimum": s.optimum, "time_optimum": s.time_optimum,
            }
        return json_safe(summary)

    def output_summary(self) -> dict:
        """One output's numbers in the ``--json`` summary of several outputs: ``output``,
        ``significant_cells_per_harmonic``, and ``H1`` (per frequency and amplitude, ``[re, im]``)."""
        return {"output": self.outputs[0], "significant_cells_per_harmonic": self.significant.sum(axis=(0, 1)),
                "H1": np.stack([self.H[:, :, 1].real, self.H[:, :, 1].imag], axis=-1)}

    def _figures(self) -> list[tuple[str, object]]:
        from nlsid.report import hosidf_plots
        from nlsid.report.units import Units

        units = Units(self.units)
        if self.grid is None:
            names = ("sweep_harmonics.png", "sweep_spectrum.png", "sweep_hosidf.png", "sweep_performance.png")
            return list(zip(names, hosidf_plots.sweep_figure_list(self.sweep, units, self.input_signal)))
        if len(self.outputs) > 1:
            return [(name.replace(".png", f"_{output}.png"), figure) for output in self.outputs
                    for name, figure in self.output(output)._output_figures(units, named=True)]
        return self._output_figures(units)

    def _output_figures(self, units, named: bool = False) -> list[tuple[str, object]]:
        """The grid figures of the first output (``named``: its name in the titles)."""
        from nlsid.report import hosidf_plots

        output = self.outputs[0]
        title = output if named else None
        out = [(f"hosidf_vs_amplitude_f{fi:03d}.png",
                hosidf_plots.versus_amplitude_figure(self.grid, fi, units, self.input_signal, output, title))
               for fi in range(self.grid.frequencies.size)]
        out.append(("hosidf_h1_map.png",
                    hosidf_plots.first_hosidf_figure(self.grid, units, self.analytic, self.input_signal, output,
                                                     title)))
        y_periods, spectra, fs = self.first_run
        out.append((f"spectrum_{spectra.run_id}.png",
                    hosidf_plots.run_spectrum_figure(y_periods, spectra, fs, units, output, title)))
        return out

    def figures(self) -> dict[str, bytes]:
        """The stage's figures as PNG bytes by file name, in the order ``nlsid hosidf --plots`` lists them:
        grid: ``hosidf_vs_amplitude_fNNN.png`` per frequency, ``hosidf_h1_map.png``, ``spectrum_<run>.png``;
        sweep: ``sweep_harmonics.png``, ``sweep_spectrum.png``, ``sweep_hosidf.png``, ``sweep_performance.png``."""
        from nlsid.report.vector import fit_labels

        from nlsid.stages.plotting import png_bytes

        out = {}
        for name, figure in self._figures():
            fit_labels(figure)
            out[name] = png_bytes(figure, DPI)
        return out

    def plot(self) -> list:
        """The figures of :meth:`figures` as pyplot figures (a notebook shows them below the cell)."""
        from nlsid.stages.plotting import pyplot_figures

        return pyplot_figures(self.figures())

    def write(self, path: str | os.PathLike, force: bool = False, provenance: dict | None = None) -> Path:
        """Write ``hosidf.h5`` (``docs/formats.md``) atomically; an existing file only with ``force``.
        ``provenance`` defaults to this process's record with the recording and model as inputs."""
        from nlsid.io.atomic import check_suffix, check_writable
        from nlsid.io.hosidf_file import write_hosidf
        from nlsid.io.provenance import provenance as make_provenance

        check_suffix(str(path))
        check_writable(str(path), force)
        record = (provenance if provenance is not None
                  else make_provenance(config_paths=self.configs, input_paths=self.inputs))
        return write_hosidf(path, self.harmonics, self.input_signal, record, grid=self.grid, analytic=self.analytic,
                            sweep=self.sweep, force=force, units=self.units,
                            output_grids=self.grids if len(self.outputs) > 1 else None)

    def __repr__(self) -> str:
        if self.grid is None:
            return (f"HosidfResult(sweep of {self.sweep.parameter} over {len(self.sweep.points)} values, "
                    f"optimum={self.sweep.optimum:g}, harmonics={self.harmonics}, source={self.source!r})")
        outputs = f", outputs={list(self.outputs)}" if len(self.outputs) > 1 else ""
        return (f"HosidfResult({len(self.grid.cells)} cells: {self.grid.frequencies.size} frequencies x "
                f"{self.grid.levels.size} amplitudes, harmonics={self.harmonics}, input_signal={self.input_signal!r}"
                f"{outputs}, source={self.source!r})")

    def _repr_html_(self) -> str:
        from html import escape

        notes = "".join(f"<li>{escape(w)}</li>" for w in self.warnings)
        notes = f"<ul>{notes}</ul>" if notes else ""
        if self.grid is None:
            s = self.sweep
            rows = "".join(f"<tr><td>{p.value:g}</td><td>{p.cost:.4g}</td><td>{p.cost_all:.4g}</td>"
                           f"<td>{p.time_error:.4g}</td></tr>" for p in s.points)
            return (f"<p><b>Linearity cost</b> over {escape(s.parameter)} of {escape(self.source)} "
                    f"({s.frequency:g} Hz, amplitude {s.level:g}): optimum {s.optimum:g}, time-domain optimum "
                    f"{s.time_optimum:g}</p><table><tr><th>{escape(s.parameter)}</th><th>f_c (Eq. 5)</th>"
                    f"<th>f (Eq. 4)</th><th>error (Eq. 7)</th></tr>{rows}</table>{notes}")
        if len(self.outputs) > 1:
            return "".join(self.output(name)._grid_html(f" to output {escape(name)}") for name in self.outputs) + notes
        return self._grid_html("") + notes

    def _grid_html(self, to: str) -> str:
        from html import escape

        shown = range(1, min(self.harmonics, 3) + 1)
        significant, h, counts = self.significant, self.H, self.n_repeats
        periods = self.n_periods
        rows = []
        for (fi, ai) in sorted(self.grid.cells):
            marks = ", ".join(str(k) for k in range(1, self.harmonics + 1) if significant[fi, ai, k]) or "none"
            cells = "".join(f"<td>{abs(h[fi, ai, k]):.4g}</td>" for k in shown)
            rows.append(f"<tr><td>{self.frequencies[fi]:g}</td><td>{self.levels[ai]:g}</td>"
                        f"<td>{counts[fi, ai]} x {periods[fi, ai]}</td>{cells}<td>{marks}</td></tr>")
        heads = "".join(f"<th>|H_{k}|</th>" for k in shown)
        return (f"<p><b>HOSIDFs</b> of {escape(self.source)}{to}: {len(self.grid.cells)} cells, "
                f"k = 0..{self.harmonics}, normalised by {self.input_signal}</p><table><tr><th>Hz</th>"
                f"<th>amplitude</th><th>R x P</th>{heads}<th>significant k</th></tr>{''.join(rows)}</table>")


def _sine_runs(runs: Iterable[Run], units: list, skipped: list, on_run: Callable | None) -> Iterator[Run]:
    """The single-sine runs (their units appended to ``units``); the ids of the others go to ``skipped``."""
    for run in runs:
        if on_run is not None:
            on_run(run)
        if run.kind == "sine":
            units.append(run.units)
            yield run
        else:
            skipped.append(run.run_id)


def _analytic(branches, grid: HOSIDFGrid) -> np.ndarray:
    from nlsid.analysis.hosidf_analytic import lpl_hosidf

    out = np.full((grid.frequencies.size, grid.levels.size, grid.harmonics + 1), np.nan, dtype=complex)
    for fi, ai in grid.cells:
        out[fi, ai] = lpl_hosidf(branches, 2 * np.pi * grid.frequencies[fi], grid.levels[ai], grid.harmonics)
    return out


def _model_branches(model, fs: float) -> list:
    """The LPL branches of ``model``: a config path, a dict, or a :class:`nlsid.Model`."""
    from nlsid.analysis.hosidf_model import branches_from_config, branches_from_data

    if isinstance(model, (str, os.PathLike)):
        return branches_from_config(model, fs)
    data = model.to_dict() if hasattr(model, "to_dict") else dict(model)
    return branches_from_data(data, fs)


def _one_output_only(first: Run, source: str, parameter: str | None, model) -> None:
    """The sweep and the analytic HOSIDFs are of one output: refused on runs of several."""
    if len(first.outputs) < 2 or (parameter is None and model is None):
        return
    what = ("the linearity cost (sweep, --sweep) is that of one output tracking its reference" if parameter is not None
            else "a model's analytic HOSIDFs (model, --model) are those of one output")
    raise InputError(f"{source}:/runs/{first.run_id}", f"has outputs {', '.join(first.outputs)}: {what}; without it, "
                                                       "the HOSIDFs of every output are measured")


def _analyse(runs: Iterable[Run], source: str, harmonics: int, variance: str, choice: str, parameter: str | None,
             model, on_run: Callable | None) -> HosidfResult:
    from nlsid.analysis.hosidf import measured_hosidfs, output_periods, output_spectra
    from nlsid.analysis.linearity_cost import sweep as linearity_sweep
    from nlsid.feeds import hosidf_input, no_sine_runs
    from nlsid.io.units import common_units

    units_seen, skipped = [], []
    sines = _sine_runs(runs, units_seen, skipped, on_run)
    first = next(sines, None)
    if first is None:
        raise no_sine_runs(source)
    _one_output_only(first, source, parameter, model)
    signal = hosidf_input(first, choice)
    sines = itertools.chain([first], sines)
    grid = analytic = result = first_run = None
    outputs, grids, first_runs = tuple(first.outputs), {}, {}
    if parameter is None:
        branches = None
        if model is not None:
            branches = _model_branches(model, first.fs)
        grids = measured_hosidfs(sines, harmonics, variance, signal, source, outputs)
        spectra = output_spectra(first, harmonics, signal, source, outputs)
        first_runs = {name: (output_periods(first, name), spectra[name], first.fs) for name in outputs}
        grid, first_run = grids[outputs[0]], first_runs[outputs[0]]
        if branches is not None:
            analytic = _analytic(branches, grid)
    else:
        result = linearity_sweep(sines, parameter, harmonics, signal, source)
    warnings = []
    if skipped:
        warnings.append(f"skipped {len(skipped)} runs that are not single sines ({', '.join(skipped[:5])}"
                        f"{', ...' if len(skipped) > 5 else ''})")
    return HosidfResult(harmonics, signal, common_units(units_seen), source, grid=grid, sweep=result,
                        analytic=analytic, warnings=warnings,
                        configs=[str(model)] if isinstance(model, (str, os.PathLike)) else [],
                        first_run=first_run, outputs=outputs, grids=grids, first_runs=first_runs)


def hosidf(recording: Recording | str | os.PathLike, harmonics: int = 5, variance: str = "both", input: str = "auto",
           sweep: str | None = None, model=None, mapping: Mapping[str, str] | None = None,
           on_run: Callable | None = None) -> HosidfResult:
    """Higher Order Sinusoidal Input Describing Functions of the single-sine runs of a recording.

    Each run holds one tone ``a cos(w0 t + phi)`` on an exact DFT bin of its period; runs with
    equal frequency and amplitude are repeats of one cell. Per cell: H_k = Y(k w0)/U(w0)^k
    (Rijlaarsdam et al., seed 002 Eq. 12) and |Y(k w0)|/|U(w0)| (seed 000 Eqs. 8-9), k = 0..K,
    averaged over repeats, with their variances over repeats and periods, and the noise bound
    eps_k = sigma(k) + 2 varsigma of seed 003 Eq. 6 that marks harmonic k significant. With
    ``sweep``, the linearity cost of seed 003 (Definitions 2-3, Eq. 7) per value of a run
    parameter instead. Runs of other kinds are skipped (said in ``warnings``). Runs of one input
    and several outputs give the HOSIDFs of each output (``outputs``, ``grids``, ``output(name)``);
    runs of several inputs are refused.

    Parameters
    ----------
    recording : Recording, path, or a recording open for reading (``nlsid.io.recording.open_recording``)
        The measured runs; a file is read run by run.
    harmonics : int
        The highest harmonic K (k = 0..K), K >= 2 and K times the tone's bin below half the period.
    variance : {"both", "repeats", "periods"}
        The variances that must be available: over repeats (>= 2 runs per cell), over periods
        (>= 2 steady-state periods per run).
    input : {"auto", "u", "r"}
        The signal whose tone normalises the HOSIDFs; ``auto`` takes r when the runs carry it.
    sweep : str, optional
        A run parameter (``run.params``, e.g. ``"K_fc"``): the linearity cost per value of it,
        over runs of one tone, instead of the grid.
    model : Model, path or dict, optional
        A model of polynomial blocks (wiener, hammerstein, wiener_hammerstein, lpl): a
        :class:`nlsid.Model`, its config file or the loaded dict; its analytic HOSIDFs (seed 002
        Lemma 2) beside the measured ones; not with ``sweep``.
    mapping : dict, optional
        Signals of a foreign MCAP log (``read``).
    on_run : callable, optional
        Called with each run as it is read (progress).

    Returns
    -------
    HosidfResult

    Raises
    ------
    nlsid.InputError
        A bad argument (named), or runs the analysis cannot take (the message names the run):
        several inputs; outputs other than the first run's; ``sweep`` or ``model`` on several outputs.

    Examples
    --------
    >>> import nlsid
    >>> h = nlsid.hosidf("sample_data/stage.h5", harmonics=3, variance="repeats")
    >>> h.input_signal, h.harmonics, h.significant.shape[-1]
    ('u', 3, 4)
    """
    check_options(harmonics, variance, input, sweep, model)
    options = (harmonics, variance, input, sweep, model, on_run)
    if isinstance(recording, Recording):
        result = _analyse(recording.runs, recording.path or "recording", *options)
        result.inputs = [recording.path] if recording.path else []
        return result
    if hasattr(recording, "load") and hasattr(recording, "run_ids"):  # a file open for reading, run by run
        source = str(recording.path)
        result = _analyse((recording.load(run_id) for run_id in recording.run_ids), source, *options)
        result.inputs = [source]
        return result
    from nlsid.io.recording import open_recording

    with open_recording(recording, require_y=True, mapping=dict(mapping) if mapping else None) as rec:
        return hosidf(rec, harmonics, variance, input, sweep, model, on_run=on_run)
