"""The ``bla`` stage: Best Linear Approximation with its noise and nonlinear distortion levels.

``nlsid.bla(recording)`` gives a :class:`BlaResult`; the command ``nlsid bla`` is this function, a
``write`` and a table. The methods are those of :mod:`nlsid.analysis.levels` (robust and fast
methods for multisine levels, Local Polynomial Method for arbitrary runs).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from nlsid.analysis.arbitrary import LPMLevel
from nlsid.analysis.frm_levels import FrmLevel, LpmFrmLevel
from nlsid.analysis.levels import LevelResult
from nlsid.errors import InputError
from nlsid.stages.recording import Recording


def check_options(method: str, confidence: float, lpm_lines: int, lpm_degree: int,
                  names: Mapping[str, str] | None = None) -> None:
    """The options of :func:`bla`, checked; ``names`` maps an argument to how the caller calls it
    (``{"confidence": "--confidence"}`` on the command line)."""
    from nlsid.analysis.bla_methods import METHOD_CHOICES

    names = names or {}
    if method not in METHOD_CHOICES:
        raise InputError(names.get("method", "method"), f"expected one of {', '.join(METHOD_CHOICES)}, got {method!r}")
    if not 0 < confidence < 1:
        raise InputError(names.get("confidence", "confidence"), f"expected a probability in (0, 1), got {confidence:g}")
    if lpm_lines < 3:
        raise InputError(names.get("lpm_lines", "lpm_lines"), f"expected at least 3 lines, got {lpm_lines}")
    if lpm_lines % 2 == 0:
        raise InputError(names.get("lpm_lines", "lpm_lines"),
                         f"expected an odd number of lines (a window centred on its line), got {lpm_lines}")
    if lpm_degree < 0:
        raise InputError(names.get("lpm_degree", "lpm_degree"), f"expected a degree >= 0, got {lpm_degree}")


@dataclass
class BlaResult:
    """What the ``bla`` stage computes, per excitation level.

    Attributes
    ----------
    levels : list of LevelResult
        Multisine levels: ``level.lines.frequency(level.lines.excited)`` the excited frequencies,
        ``level.robust.G`` the BLA there, ``level.robust.var_noise`` and ``level.robust.var_nl``
        the noise and nonlinear variances of G (``docs/formats.md``, "BLA results").
    lpm_levels : list of LPMLevel
        Levels of arbitrary runs by the Local Polynomial Method (``.frequency``, ``.G``, ...).
    warnings : list of str
        What the analysis could not do or doubts, for the whole recording.
    across_levels : dict
        The BLA versus the excitation level (``docs/formats.md``).
    units : dict
        Signal -> unit that every run of the recording gives it.
    frm_levels : list of FrmLevel
        Levels of runs with several inputs or outputs: the frequency response matrix ``.frm``
        (:mod:`nlsid.analysis.frm_levels`, ``docs/mimo.md``); empty for a single-input recording.
    frm_lpm_levels : list of LpmFrmLevel
        Levels of arbitrary runs with several inputs or outputs: the frequency response matrix by
        the Local Polynomial Method for several inputs (``.G``, ``.var_G``, ``.bounds``, ``.result``;
        ``docs/mimo.md``); empty for a single-input recording.
    confidence : float
        Probability of the confidence bounds.
    source : str
        Where the runs came from (a path, or ``"recording"``).
    inputs : list of str
        The recording file behind the result, if any (the provenance of :meth:`write`).

    Examples
    --------
    The BLA of a mass-spring-damper, excited by four realizations of two periods at one level:

    >>> import os, tempfile
    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> plant = nlsid.Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0,
    ...                                          "stiffness": 2000.0}, "disturbances": {"y_noise": 1e-6, "seed": 3}})
    >>> b = nlsid.bla(plant.simulate(exc))
    >>> len(b.levels), b.lpm_levels, b.confidence, b.source
    (1, [], 0.95, 'recording')
    >>> row = b.summary()["levels"][0]
    >>> row["realizations"], row["periods"], row["excited_lines"] == len(exc.design["multisine"]["excited_bins"])
    (4, 2, True)
    >>> bool(np.array_equal(b.frequency, np.array(exc.design["multisine"]["excited_bins"]) * 200.0 / 200))
    True
    >>> b.G.shape == b.frequency.shape == b.levels[0].robust.var_noise.shape
    True
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     print(b.write(os.path.join(folder, "bla.h5")).name)
    bla.h5
    """

    levels: list[LevelResult]
    lpm_levels: list[LPMLevel]
    warnings: list[str]
    across_levels: dict
    units: dict[str, str]
    confidence: float
    source: str
    inputs: list[str] = field(default_factory=list)
    frm_levels: list[FrmLevel] = field(default_factory=list)
    frm_lpm_levels: list[LpmFrmLevel] = field(default_factory=list)

    @property
    def frequency(self) -> np.ndarray:
        """The excited frequencies (Hz) of the only level; see :attr:`levels` when there are several."""
        return self._only().frequency

    @property
    def G(self) -> np.ndarray:
        """The BLA at :attr:`frequency` (complex) of the only level."""
        return self._only().G

    def _only(self) -> "_Curve":
        curves = [_Curve.of(level) for level in self.levels] + [_Curve.of_lpm(level) for level in self.lpm_levels]
        if len(curves) != 1:
            raise InputError("BlaResult", f"holds {len(curves)} levels; take one of .levels or .lpm_levels")
        return curves[0]

    def level_names(self) -> list[str]:
        """Each level as every stage names it, ``level 1 (rms 2 N)`` (:mod:`nlsid.analysis.level_names`):
        the multisine levels, then those of arbitrary runs, numbered as ``fit_tf(level=)`` takes them."""
        from nlsid.analysis.level_names import level_name

        return [level_name(i, level.u_rms, self.units.get("u")) for i, level in enumerate([*self.levels,
                                                                                          *self.lpm_levels])]

    def messages(self) -> list[str]:
        """Every warning, of the recording and of each level (``level 1 (rms 2 N): ...``)."""
        names = self.level_names()
        lpm = [(names[len(self.levels) + i] + " (arbitrary runs)", level) for i, level in enumerate(self.lpm_levels)]
        frm = [(f"frequency response matrix level {i}", level) for i, level in enumerate(self.frm_levels)]
        frm += [(f"frequency response matrix level {i} (arbitrary runs)", level)
                for i, level in enumerate(self.frm_lpm_levels, start=len(self.frm_levels))]
        return self.warnings + [f"{name}: {w}" for name, level in [*zip(names, self.levels), *lpm, *frm]
                                for w in level.warnings]

    def summary(self) -> dict:
        """Per level the scalars of ``docs/formats.md`` (``levels``, ``lpm_levels``), the
        ``across_levels`` trend and the ``warnings``: the ``nlsid bla --json`` summary without paths."""
        out = {"levels": [level.summary() for level in self.levels],
               "lpm_levels": [level.summary() for level in self.lpm_levels],
               "across_levels": self.across_levels, "warnings": self.warnings}
        if self.frm_levels:
            out["frm_levels"] = [level.summary() for level in self.frm_levels]
        if self.frm_lpm_levels:
            out["frm_lpm_levels"] = [level.summary() for level in self.frm_lpm_levels]
        return out

    def figures(self) -> dict[str, bytes]:
        """The stage's figures as PNG bytes by file name (``nlsid bla --plots``): those of the
        single-input levels, then ``frm_level_NN.png`` per level of the frequency response matrix
        (the ``frm_levels``, then the ``frm_lpm_levels``, numbered as the terminal table numbers
        them), the report page's n_y x n_u Bode matrix of that level."""
        from nlsid.report.bla_plots import render_figures
        from nlsid.report.units import Units

        out = render_figures(self.levels, Units(self.units), self.lpm_levels)
        out.update(frm_figures(self.frm_levels, self.frm_lpm_levels))
        return out

    def plot(self) -> list:
        """The figures of :meth:`figures` as matplotlib figures (for a notebook)."""
        from nlsid.stages.plotting import pyplot_figures

        return pyplot_figures(self.figures())

    def write(self, path: str | os.PathLike, force: bool = False, provenance: dict | None = None) -> Path:
        """Write ``bla.h5`` (``docs/formats.md``) atomically; an existing file only with ``force``."""
        from nlsid.io.atomic import check_suffix, check_writable
        from nlsid.io.bla_file import write_bla
        from nlsid.io.provenance import provenance as make_provenance

        check_suffix(str(path))
        check_writable(str(path), force)
        record = provenance if provenance is not None else make_provenance(input_paths=self.inputs)
        write_bla(path, self.levels, record, self.confidence, self.warnings, self.across_levels, force=force,
                  lpm_levels=self.lpm_levels, units=self.units, frm_levels=self.frm_levels,
                  frm_lpm_levels=self.frm_lpm_levels)
        return Path(path)

    def _repr_html_(self) -> str:
        from html import escape

        rows = []
        for index, row in enumerate(self.summary()["levels"]):
            rows.append(f"<tr><td>{index}</td><td>{row['u_rms']:.3g}</td><td>{row['realizations']} x "
                        f"{row['periods']}</td><td>{escape(row['method'])}</td><td>{row['bla_db']:.1f}</td>"
                        f"<td>{row['nl_var_db']:.1f}</td><td>{row['noise_var_db']:.1f}</td></tr>")
        for index, row in enumerate(self.summary()["lpm_levels"], start=len(self.levels)):
            rows.append(f"<tr><td>{index}</td><td>{row['u_rms']:.3g}</td><td>{row['realizations']} records</td>"
                        f"<td>{escape(row['method'])}</td><td>{row['bla_db']:.1f}</td><td colspan=2>"
                        f"{row['total_var_db']:.1f} (noise + NL)</td></tr>")
        warnings = "".join(f"<li>{escape(w)}</li>" for w in self.messages())
        return (f"<p><b>BLA</b> of {escape(self.source)}</p><table><tr><th>level</th><th>u rms</th><th>M x P</th>"
                "<th>method</th><th>|G| dB</th><th>NL var dB</th><th>noise var dB</th></tr>" + "".join(rows)
                + "</table>" + (f"<ul>{warnings}</ul>" if warnings else ""))


def frm_figures(frm_levels: list[FrmLevel], frm_lpm_levels: list[LpmFrmLevel]) -> dict[str, bytes]:
    """``frm_level_NN.png`` per FRM level, multisine levels first, as PNG bytes: the figure of
    :func:`nlsid.report.frm_plots.frm_figure` (the report page's), drawn from the level in memory
    with the arrays ``bla.h5`` stores for it (:func:`frm_figure_data`)."""
    import io

    from nlsid.report.frm_plots import frm_figure
    from nlsid.report.render_frm import frm_level_name
    from nlsid.report.units import units_of
    from nlsid.report.vector import fit_labels

    out = {}
    for index, level in enumerate([*frm_levels, *frm_lpm_levels]):
        figure = frm_figure(frm_figure_data(level), units_of(level.units), frm_level_name(index, level.summary()))
        fit_labels(figure)
        buffer = io.BytesIO()
        figure.savefig(buffer, format="png", dpi=110)  # the resolution of the single-input figures
        out[f"frm_level_{index:02d}.png"] = buffer.getvalue()
    return out


def frm_figure_data(level: FrmLevel | LpmFrmLevel) -> dict:
    """What :func:`nlsid.report.frm_plots.frm_figure` draws of one FRM level, in the layout of its
    ``bla.h5`` group as :func:`nlsid.io.bla_file.read_bla` returns it: ``attrs`` (``inputs``,
    ``outputs``, ``confidence``), ``frequency``, ``G``, ``bounds``, and the standard deviations
    (``std_total`` and ``std_noise`` of a multisine level; ``var_G`` of a level by the LPM)."""
    names = ("radius", "mag_lo", "mag_hi", "phase_lo", "phase_hi")
    attrs = {"inputs": list(level.inputs), "outputs": list(level.outputs)}
    if isinstance(level, LpmFrmLevel):
        bounds = level.bounds
        return {"attrs": {**attrs, "confidence": level.confidence}, "frequency": level.frequency, "G": level.G,
                "var_G": level.var_G, "bounds": {name: getattr(bounds, name) for name in names}}
    result = level.frm
    attrs["confidence"] = result.confidence
    return {"attrs": attrs, "frequency": result.frequency, "G": result.G, "std_total": result.std_total,
            "std_noise": result.std_noise, "bounds": {name: getattr(result.bounds, name) for name in names}}


@dataclass(frozen=True)
class _Curve:
    frequency: np.ndarray
    G: np.ndarray

    @classmethod
    def of(cls, level: LevelResult) -> "_Curve":
        return cls(level.lines.frequency(level.lines.excited), level.robust.G)

    @classmethod
    def of_lpm(cls, level: LPMLevel) -> "_Curve":
        return cls(level.frequency, level.G)


def bla(recording: Recording | str | os.PathLike, method: str = "auto", confidence: float = 0.95,
        lpm_lines: int = 7, lpm_degree: int = 2, mapping: Mapping[str, str] | None = None,
        on_run: Callable | None = None) -> BlaResult:
    """Best Linear Approximation of a recording, per excitation level.

    Multisine runs of a level are M realizations x P periods of a random-phase multisine: the
    robust method gives G_BLA(k) = mean over m of G^[m](k) with the noise variance from the
    period-to-period scatter and the nonlinear variance from the realization-to-realization
    scatter, var_NL = M var_total - var_noise (Pintelon and Schoukens 2012, Sec. 3.4; book
    Sec. 6.1.1); the fast method uses the detection lines of one random grid (book Sec. 6.1.2).
    Arbitrary runs get the Local Polynomial Method (book Sec. 3.7). Runs with several inputs or
    outputs give the frequency response matrix per level: orthogonal multisines by (6-117), arbitrary
    runs by the LPM for several inputs (book Sec. 7.2; ``docs/mimo.md``).

    Parameters
    ----------
    recording : Recording, path, or a recording open for reading (``nlsid.io.recording.open_recording``)
        The measured runs (u, y, and r for closed loops); a file is read run by run.
    method : {"auto", "frf", "io", "reference"}
        Robust-method variant: known input, noisy input, or projected on the reference r. For runs
        with several inputs, ``auto`` and ``reference`` take the FRM from the references (``r``,
        ``r2``, ...) where every run of a level carries them (``docs/mimo.md``).
    confidence : float
        Probability of the confidence bounds on |G_BLA| and its phase, in (0, 1).
    lpm_lines, lpm_degree : int
        Local Polynomial Method window (odd number of lines) and polynomial degree. With several
        inputs the window is widened, with a warning, where it leaves no degree of freedom.
    mapping : dict, optional
        Signals of a foreign MCAP log (``read``).
    on_run : callable, optional
        Called with each run as it is analysed (progress).

    Returns
    -------
    BlaResult

    Raises
    ------
    nlsid.InputError
        A bad argument (named), or runs the methods cannot take (the message says why).

    Examples
    --------
    A linear plant's BLA is its frequency response: here that of the mass-spring-damper
    1/(m s^2 + c s + k) seen through the zero-order hold, as it is simulated (and sampled on a
    machine), computed from the matrix exponential of its state equation. Three transient
    periods let its slowest mode (decay rate c/2m = 5/s) die out to e^-15. The output noise
    sigma = 1e-6 then is the only error: a multisine of rms a on F lines has
    |U(k)| = N a / sqrt(2 F) in an N-sample DFT, so each of the M P period ratios Y/U has noise
    variance 2 F sigma^2 / (N a^2), and their mean 1/(M P) of it. A complex Gaussian error
    exceeds five of its standard deviations with probability exp(-25):

    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> plant = nlsid.Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0,
    ...                                          "stiffness": 2000.0}, "disturbances": {"y_noise": 1e-6, "seed": 3}})
    >>> b = nlsid.bla(plant.simulate(exc))
    >>> from scipy.linalg import expm
    >>> A = np.array([[0.0, 1.0, 0.0], [-1000.0, -10.0, 0.5], [0.0, 0.0, 0.0]])  # (x, v, u): v' = (u - c v - k x)/m
    >>> Phi = expm(A / 200.0)  # one sample with u held: (x, v)[n+1] = Ad (x, v)[n] + Bd u[n]
    >>> Ad, Bd = Phi[:2, :2], Phi[:2, 2]
    >>> G = np.array([np.linalg.solve(z * np.eye(2) - Ad, Bd)[0] for z in np.exp(2j * np.pi * b.frequency / 200.0)])
    >>> F, N, M, P = len(b.frequency), 200, 4, 2
    >>> std = np.sqrt(2 * F * 1e-6**2 / (N * 1.0**2) / (M * P))
    >>> bool(np.all(np.abs(b.G - G) < 5 * std))
    True
    >>> try:
    ...     nlsid.bla(exc)  # an excitation has no measured y
    ... except nlsid.InputError as error:
    ...     print(error)
    ms_l00_m00: run has no signal 'y'
    """
    from nlsid.analysis.frm_levels import MimoRuns
    from nlsid.analysis.levels import across_levels, analyse_bla, recording_runs
    from nlsid.io.units import common_units

    check_options(method, confidence, lpm_lines, lpm_degree)
    units_seen = []

    def seen(run) -> None:
        units_seen.append(run.units)
        if on_run is not None:
            on_run(run)

    options = dict(method=method, probability=confidence, on_run=seen, lpm_half_width=lpm_lines // 2,
                   lpm_degree=lpm_degree)
    mimo = MimoRuns(on_run=seen)  # runs with several inputs or outputs: the frequency response matrix

    def analyse(runs, source: str):
        try:
            return analyse_bla(mimo.take(runs), source=source, **options)
        except InputError:
            if mimo.only_mimo:  # its only complaint: no run of one input and one output to analyse
                return [], [], []
            raise

    if isinstance(recording, Recording):
        source = recording.path or "recording"
        runs = ((run, f"{source}:/runs/{run.run_id}") for run in recording.runs)
        levels, lpm_levels, warnings = analyse(runs, source)
        inputs = [recording.path] if recording.path else []
    elif hasattr(recording, "load") and hasattr(recording, "run_ids"):  # a file open for reading, run by run
        source = str(recording.path)
        levels, lpm_levels, warnings = analyse(recording_runs(recording, source), source)
        inputs = [source]
    else:
        from nlsid.io.recording import open_recording

        with open_recording(recording, require_y=True, mapping=dict(mapping) if mapping else None) as rec:
            return bla(rec, method, confidence, lpm_lines, lpm_degree, on_run=on_run)
    return BlaResult(levels, lpm_levels, warnings, across_levels(levels), common_units(units_seen), confidence,
                     source, inputs, mimo.levels(confidence, source, method),
                     mimo.lpm_levels(confidence, source, lpm_lines // 2, lpm_degree, method))
