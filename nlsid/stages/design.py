"""The ``design`` stage: excitation signals from a design config, as a recording with u only.

``nlsid.design(config)`` gives an :class:`Excitation`: a :class:`~nlsid.stages.recording.Recording`
whose runs are the designed excitation (random-phase multisines and single-sine grids,
:mod:`nlsid.signals.design`) and whose ``design`` attribute is the design summary (the
``nlsid design --json`` document without ``output``). The command ``nlsid design`` is this
function, a ``write`` and a table.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Mapping

import numpy as np

from nlsid.errors import InputError
from nlsid.signals.design_config import DesignConfig
from nlsid.io.run import Run
from nlsid.stages.recording import Recording


@dataclass
class Excitation(Recording):
    """A designed excitation: the runs (u only) and the design that made them.

    Attributes
    ----------
    runs : list of Run
        One run per multisine level and realization (``ms_lLL_mMM``), then one per sine frequency,
        amplitude and repeat (``sine_fFFF_aAA_rRR``); ``docs/formats.md``.
    design : dict
        The design summary, keys as in ``nlsid design --json`` (``docs/formats.md``) without
        ``output``: ``fs``, ``seed``, ``runs``, ``duration_s``, and ``multisine`` (excited and
        detection bins, levels, crest factors, ...) and/or ``sines``.
    provenance : dict
        Tool, version and the config file with its SHA-256 (no config file for a dict).
    path : None
        No file holds the runs until :meth:`write`.

    Examples
    --------
    Two realizations of a multisine and a grid of two sines; each run lasts its
    ``transient_periods + periods`` periods, which the duration adds up:

    >>> import os, tempfile
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 100.0, "seed": 1,
    ...                     "multisine": {"period": 100, "band": [1.0, 20.0], "realizations": 2, "periods": 2,
    ...                                   "transient_periods": 1, "rms_levels": [0.5]},
    ...                     "sines": {"period": 100, "frequencies": [2.0, 5.0], "amplitudes": [1.0], "repeats": 1,
    ...                               "periods": 2, "transient_periods": 1}})
    >>> isinstance(exc, nlsid.Recording), exc.run_ids
    (True, ['ms_l00_m00', 'ms_l00_m01', 'sine_f000_a00_r00', 'sine_f001_a00_r00'])
    >>> exc.design["runs"], exc.design["duration_s"] == 4 * (1 + 2) * 100 / 100.0
    (4, True)
    >>> exc.design["sines"]["frequencies"], exc.signals, exc.path
    ([2.0, 5.0], ['u'], None)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     print(len(nlsid.read(exc.write(os.path.join(folder, "excitation.h5")))))
    4
    """

    design: dict = field(default_factory=dict)

    def _repr_html_(self) -> str:
        from html import escape

        d = self.design
        parts = []
        if "multisine" in d:
            m = d["multisine"]
            lo, hi = m["excited_frequency_range"]
            parts.append(f"multisine {escape(m['lines'])}: {len(m['excited_bins'])} lines in {lo:g}..{hi:g} Hz, "
                         f"{len(m['levels'])} levels x {m['realizations']} realizations")
        if "sines" in d:
            s = d["sines"]
            parts.append(f"sines: {len(s['frequencies'])} frequencies x {len(s['amplitudes'])} amplitudes "
                         f"x {s['repeats']} repeats")
        return (f"<p><b>Excitation</b>: {escape('; '.join(parts))}; {d.get('duration_s', 0):.1f} s at "
                f"{d.get('fs', 0):g} Hz</p>" + super()._repr_html_())

    def __repr__(self) -> str:
        return f"Excitation({len(self.runs)} runs, fs={self.fs}, duration_s={self.design.get('duration_s')})"


@dataclass(frozen=True)
class DesignSource:
    """A validated design config and where it came from (for messages naming its lines).

    Attributes
    ----------
    config : DesignConfig
        The validated keys (``docs/configs.md``).
    path : str or None
        The YAML file, or None for a config given as a dict.
    lines : dict
        Key path (tuple) -> line of the file.
    """

    config: DesignConfig
    path: str | None = None
    lines: dict = field(default_factory=dict)

    @property
    def run_count(self) -> int:
        """How many runs the design makes."""
        from nlsid.signals.design import run_count

        return run_count(self.config)

    def error(self, key_path: tuple, what: str) -> InputError:
        """The error of a key: ``file:line: key: what``, or ``key: what`` for a dict."""
        from nlsid.io.config import config_error

        return config_error(self.path, self.lines, key_path, what)


def parse(config: str | os.PathLike | Mapping[str, Any] | DesignSource) -> DesignSource:
    """Read and validate a design config: a YAML file, or a dict of the same keys.

    Raises
    ------
    nlsid.InputError
        A missing file, bad YAML, or a bad key: ``file:line: key.path: what`` for a file,
        ``key.path: what`` for a dict.
    """
    from nlsid.io.config import load_yaml, validate
    from nlsid.models.key_paths import deep_copy

    if isinstance(config, DesignSource):
        return config
    if isinstance(config, Mapping):
        data = deep_copy(dict(config))
        return DesignSource(validate(data, DesignConfig, None), None, {})
    if not isinstance(config, (str, os.PathLike)):
        raise InputError("config", f"expected a path to a design YAML or a dict, got {type(config).__name__}")
    data, lines = load_yaml(config)
    return DesignSource(validate(data, DesignConfig, config, lines), str(config), lines)


def design(config: str | os.PathLike | Mapping[str, Any] | DesignSource,
           on_run: Callable[[Run], None] | None = None) -> Excitation:
    """Design the excitation signals of a config: random-phase multisines and single-sine grids.

    A multisine run of rms level a on the N-sample period excites the F chosen bins k with equal
    amplitudes A = a sqrt(2 / F) and random phases, u(n) = sum_k A cos(2 pi k n / N + phi_k)
    (Pintelon and Schoukens 2012, Sec. 2.2; random-odd grids: book Sec. 6.1.2.B, one group of
    ``group_size`` odd lines losing one line at random); a sine run is u(n) = a sin(2 pi k n / N).
    Each run holds ``transient_periods + periods`` whole periods; randomness comes only from the
    config's ``seed``.

    Parameters
    ----------
    config : path, dict, or DesignSource
        A design YAML (``configs/stage_design.yaml``; keys in ``docs/configs.md``) or a dict of the
        same keys.
    on_run : callable, optional
        Called with each run as it is made (progress).

    Returns
    -------
    Excitation
        The runs (u only) and ``.design``, the design summary.

    Raises
    ------
    nlsid.InputError
        A bad key (``file:line: key: what``; ``key: what`` for a dict), or a level so large that
        the samples overflow (named by the key that set it).

    Examples
    --------
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 1000.0, "seed": 1,
    ...                     "multisine": {"period": 1000, "band": [1.0, 20.0], "lines": "odd", "rms_levels": [0.5]}})
    >>> exc.run_ids, exc.design["multisine"]["excited_bins"][:3]
    (['ms_l00_m00'], [1, 3, 5])
    >>> round(float(exc[0].u.std()), 12)
    0.5
    """
    source = parse(config)
    made: dict = {}
    runs = list(iter_runs(source, made, on_run))
    return Excitation(runs, _provenance(source), None, design=made)  # path: no recording file holds it yet


def iter_runs(config: str | os.PathLike | Mapping[str, Any] | DesignSource, summary_into: dict | None = None,
              on_run: Callable[[Run], None] | None = None) -> Iterator[Run]:
    """The runs of :func:`design` one at a time, so that a design larger than memory can be
    written run by run (``nlsid.io.recording.write_recording`` takes them so). Once all are made,
    ``summary_into`` (a dict) receives the design summary (:attr:`Excitation.design`).

    Raises
    ------
    nlsid.InputError
        As :func:`design`, when the run concerned is reached.
    """
    from nlsid.signals.design import design_runs, level_key
    from nlsid.signals.multisine import crest_factor

    source = parse(config)
    cfg = source.config
    meta = []
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below, by its key
        for run in design_runs(cfg):
            inputs = run.input_matrix()
            if not np.all(np.isfinite(inputs)):  # a level near the float range overflows
                what = "rms" if run.kind == "multisine" else "amplitude"
                raise source.error(level_key(cfg, run), f"{what} {run.level:g} gives non-finite samples (float "
                                                         f"overflow in run {run.run_id}); nothing was written")
            meta.append({"run": run.run_id, "kind": run.kind, "level": run.level, "frequency": run.frequency,
                         "crest_factor": max(crest_factor(x[: run.period]) for x in inputs)})
            if on_run is not None:
                on_run(run)
            yield run
    if summary_into is not None:
        summary_into.update(summary(cfg, meta))


def _provenance(source: DesignSource) -> dict:
    from nlsid.io.provenance import provenance

    return provenance(config_paths=[source.path] if source.path is not None else [])


def _orthogonal_summary(m) -> dict:
    """The keys of orthogonal multisines in the design summary: inputs (and the experiments of each
    realization, as many), their names, and the unitary matrix T used."""
    from nlsid.signals.design import input_names
    from nlsid.signals.orthogonal_multisine import is_power_of_two

    transform = m.transform if m.transform != "auto" else ("hadamard" if is_power_of_two(m.inputs) else "dft")
    return {"inputs": m.inputs, "experiments": m.inputs, "input_names": list(input_names(m.inputs)),
            "transform": transform}


def summary(cfg: DesignConfig, runs_meta: list[dict]) -> dict:
    """The design summary (``nlsid design --json`` without ``output``, layout in docs/formats.md), in
    plain Python numbers and lists."""
    from nlsid.io.result_file import json_safe
    from nlsid.signals.design import plan_lines

    out: dict = {"fs": cfg.fs, "seed": cfg.seed, "runs": len(runs_meta)}
    duration = 0.0
    if cfg.multisine is not None:
        m = cfg.multisine
        plan = plan_lines(m, cfg.fs, cfg.seed)
        crest = [r["crest_factor"] for r in runs_meta if r["kind"] == "multisine"]
        out["multisine"] = {
            "period": m.period, "frequency_resolution": cfg.fs / m.period, "lines": m.lines,
            "excited_bins": plan.excited, "detection_bins": plan.detection,
            "excited_frequency_range": [plan.excited[0] * cfg.fs / m.period, plan.excited[-1] * cfg.fs / m.period],
            "levels": m.levels(), "realizations": m.realizations, "periods": m.periods,
            "transient_periods": m.transient_periods, "crest_factors": crest,
        }
        if m.inputs > 1:
            out["multisine"].update(_orthogonal_summary(m))
        duration += len(crest) * (m.periods + m.transient_periods) * m.period / cfg.fs
    if cfg.sines is not None:
        s = cfg.sines
        out["sines"] = {
            "period": s.period, "frequencies": s.frequency_values(), "amplitudes": s.amplitude_values(),
            "repeats": s.repeats, "periods": s.periods, "transient_periods": s.transient_periods,
        }
        n_sines = s.frequency_values().size * s.amplitude_values().size * s.repeats
        duration += n_sines * (s.periods + s.transient_periods) * s.period / cfg.fs
    out["duration_s"] = duration
    return json_safe(out)
