"""A model in memory: a model config (``docs/configs.md``) that simulates numpy signals and recordings.

``nlsid.Model.from_yaml(path)`` or ``nlsid.Model.from_dict(d)`` validates the config as ``nlsid
simulate`` does; ``.parameters`` lists its numbers by dotted key path (``model.mass``,
``model.nonlinearities[0].fc``, ``model.den[1]``: the paths of ``sweep.parameter`` and of
``free:`` in ``fit --model``), ``.with_parameters`` gives a changed copy, ``.simulate`` runs it.
The command ``nlsid simulate`` is :meth:`Model.simulate` of a recording and a ``write``.
"""

from __future__ import annotations

import numbers
import os
import re
from pathlib import Path
from typing import Any, Callable, Mapping

from nlsid.errors import InputError
from nlsid.stages.recording import Recording

#: The sections whose numbers :attr:`Model.parameters` lists (the others are noise, sweep,
#: simulation settings and fit bounds).
PARAMETER_SECTIONS = ("model", "closed_loop")


class Model:
    """A validated model config: the plant (open or closed loop), its noise, and a sweep if any.

    Make one with :meth:`from_yaml` or :meth:`from_dict`; a Model is not changed in place
    (:meth:`with_parameters` returns a new one).

    Parameters
    ----------
    data : dict
        The keys of a model config (``docs/configs.md``); a copy is kept.
    path : str or path-like, optional
        The file the keys were read from, named in messages.
    lines : dict, optional
        Key path (tuple) -> line of that file, for messages ``file:line: key: what``.

    Attributes
    ----------
    path : str or None
        The YAML file it was read from (None for a dict or a changed copy).

    Examples
    --------
    >>> m = Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0,
    ...                                "stiffness": 2000.0}})
    >>> m.parameters
    {'model.mass': 2.0, 'model.damping': 20.0, 'model.stiffness': 2000.0}
    >>> m.with_parameters({"model.mass": 2.5}).parameters["model.mass"]
    2.5

    A force of 1 held for 3 s deflects the spring by u/k; the transient has decayed as
    exp(-c t / 2m) = exp(-15) by then:

    >>> import numpy as np
    >>> y = m.simulate(np.ones(3000), fs=1000.0)
    >>> y.shape, bool(abs(y[-1] - 1 / 2000.0) < 1e-9)
    ((3000,), True)
    """

    def __init__(self, data: Mapping[str, Any], path: str | os.PathLike | None = None, lines: dict | None = None):
        from nlsid.models.key_paths import deep_copy
        from nlsid.simulate.sweep import config_points

        self._data = deep_copy(dict(data) if isinstance(data, Mapping) else data)  # not a mapping: refused below
        self.path = None if path is None else str(path)
        self._points = config_points(self._data, path, lines)

    @classmethod
    def from_yaml(cls, path: str | os.PathLike) -> "Model":
        """Read a model config file (``configs/stage_true.yaml``).

        Raises
        ------
        nlsid.InputError
            A missing file, bad YAML or a bad key: ``file:line: key.path: what``.
        """
        from nlsid.io.config import load_yaml

        data, lines = load_yaml(path)
        return cls(data, path, lines)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Model":
        """A model from a dict of the keys of a model config (a copy is kept).

        Raises
        ------
        nlsid.InputError
            A bad key, named by its key path: ``model.mass: must be > 0, got -1.0``.
        """
        if not isinstance(data, Mapping):
            raise InputError("config", f"expected a mapping of keys (a dict), got {type(data).__name__}")
        return cls(data)

    @property
    def parameters(self) -> dict[str, float | int]:
        """The numbers of the ``model`` and ``closed_loop`` sections as written, by dotted key path
        (``{"model.mass": 2.0, "model.nonlinearities[0].fc": 0.5, ...}``): the paths that
        :meth:`with_parameters`, ``sweep.parameter`` and ``free:`` take. Keys left to their
        defaults are not listed, yet :meth:`with_parameters` sets them too."""
        from nlsid.models.key_paths import numbers as config_numbers

        return config_numbers(self._data, PARAMETER_SECTIONS)

    @property
    def points(self) -> list[dict]:
        """What each simulation of a run adds to its ``params``: one dict per sweep value
        (``{name: value}``), or ``[{}]`` without a sweep."""
        return [dict(point.params) for point in self._points]

    def with_parameters(self, values: Mapping[str, float]) -> "Model":
        """A new Model with the numbers of ``values`` (dotted key path -> number) written in.

        The whole config is validated again, so a value obeys the rules of a value written in
        the file. Any key path of a number is taken (``model.damping`` also where the config
        leaves it to its default; ``disturbances.y_noise``), except in ``sweep``.

        Raises
        ------
        nlsid.InputError
            Named by the key path: not a number, no such place, or a value the model refuses.
        """
        from nlsid.models.key_paths import set_value

        data = self.to_dict()
        for key, value in dict(values).items():
            set_value(data, str(key), _number(str(key), value), key=str(key))
        return Model(data)

    def simulate(self, u, fs: float | None = None, seed: int | None = None, workers: int | None = None,
                 steady: bool = False, progress: Callable[[], None] | None = None):
        """Simulate the model on a signal or on every run of a recording.

        Continuous LTI parts are run exactly for an input held between samples (zero-order hold);
        nonlinear forces by sub-stepping (``docs/commands.md``, "Numerical method and its error").
        The config's ``disturbances`` add their noise, drawn from ``disturbances.seed`` (or
        ``seed``): the same numbers as ``nlsid simulate``.

        Parameters
        ----------
        u : 1-D array, Recording, or path of a recording
            An array: the input samples (in closed loop the reference), simulated from rest; for
            a ``mimo_state_space`` model an (n_u, n) array, row i its input ``inputs[i]``.
            A Recording (or file): each run's u (closed loop: its r where it has one, else u), as
            ``nlsid simulate MODEL --excitation FILE``; a ``mimo_state_space`` model reads its
            inputs from u and the run's channels (:mod:`nlsid.simulate.mimo`).
        fs : float, optional
            Sample rate (Hz) of an array (default 1000.0); a recording carries its own.
        seed : int, optional
            Seed of the noise, overriding ``disturbances.seed``.
        workers : int, optional
            Parallel simulations (threads); default all cores (or ``NLSID_THREADS``).
        steady : bool
            Recording only: periodic runs in their periodic steady state (``--steady-state``).
        progress : callable, optional
            Called without arguments after each simulated run (a progress bar's step).

        Returns
        -------
        numpy.ndarray or Recording
            For an array, the output y (as measured, with the config's y noise; a ``mimo_state_space``
            model: the (n_y, n) outputs); for a recording, a Recording of one run per excitation
            run and sweep value (``<id>_s<k>``), with u, y (and r in closed loop) and the
            excitation's attributes and channels (a ``mimo_state_space`` model: its inputs and
            outputs named, the outputs after y as channels).

        Raises
        ------
        nlsid.InputError
            A bad argument (named), or a model that cannot run on the signal (e.g. unstable).
        """
        if isinstance(u, Recording):
            if fs is not None:
                raise InputError("fs", "a Recording carries its own sample rate; give fs only with an array")
            return self._simulate_recording(u, seed, workers, steady, progress)
        if isinstance(u, (str, os.PathLike)):
            from nlsid.stages.recording import read

            return self.simulate(read(u), fs, seed, workers, steady, progress)
        return self._simulate_array(u, 1000.0 if fs is None else fs, seed, workers, steady, progress)

    def _simulate_recording(self, rec: Recording, seed, workers, steady, progress) -> Recording:
        from nlsid.io.provenance import provenance, sha256_in_background
        from nlsid.simulate.batch import simulate_all

        from nlsid.feeds import several_inputs_outputs
        from nlsid.simulate.mimo import check_run

        mimo = self._mimo_names()
        for run in rec.runs:
            where = f"{rec.path or 'recording'}:/runs/{run.run_id}"
            if mimo is not None:  # before any work: every run carries the model's inputs, none is dropped
                check_run(*mimo, run, where)
                continue
            error = several_inputs_outputs(run, where)
            if error is not None:
                raise error
        configs, inputs = [self.path] if self.path else [], [rec.path] if rec.path else []
        digests = {path: sha256_in_background(path) for path in configs + inputs}  # beside the simulation
        out = simulate_all(self._points, list(rec.runs), seed=seed, workers=workers,
                           step=progress, steady=steady)
        return Recording(out, provenance(config_paths=configs, input_paths=inputs, digests=digests))

    def _mimo_names(self) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
        """(inputs, outputs) of a ``mimo_state_space`` model; None for a model of one input and output."""
        config = self._points[0].config.model
        if config.type != "mimo_state_space":
            return None
        return tuple(config.input_names), tuple(config.output_names)

    def _simulate_array(self, u, fs, seed, workers, steady, progress):
        import math

        from nlsid.io.run import Run, validate_signal
        from nlsid.simulate.batch import simulate_all

        if steady:
            raise InputError("steady", "needs a Recording (its periods or its measured y); an array runs from rest")
        if isinstance(fs, bool) or not isinstance(fs, numbers.Real) or not (math.isfinite(fs) and fs > 0):
            raise InputError("fs", f"expected a sample rate > 0 in Hz, got {fs!r}")
        if len(self._points) > 1:
            raise InputError("u", f"the model sweeps {self._points[0].config.sweep.parameter} over "
                                  f"{len(self._points)} values: simulate a Recording (one run per value)")
        mimo = self._mimo_names()
        if mimo is not None:
            return self._simulate_matrix(u, fs, seed, workers, progress, *mimo)
        signal = validate_signal(u, "u")
        if signal.size == 0:
            raise InputError("u", "no samples")
        run = Run(run_id="u", fs=float(fs), kind="arbitrary", u=signal)
        out = simulate_all(self._points, [run], seed=seed, workers=workers,
                           step=progress)
        return out[0].y

    def _simulate_matrix(self, u, fs, seed, workers, progress, inputs, outputs):
        """A model of several inputs and outputs on an (n_u, n) array (a 1-D array: one input): (n_y, n)."""
        import numpy as np

        from nlsid.io.run import Run, validate_signal
        from nlsid.simulate.batch import simulate_all

        matrix = np.asarray(u)
        if matrix.ndim == 1:
            matrix = matrix[None, :]
        if matrix.ndim != 2 or matrix.shape[0] != len(inputs) or matrix.shape[1] == 0:
            raise InputError("u", f"expected an array of {len(inputs)} rows (the model's inputs {', '.join(inputs)}) "
                                  f"of samples, got shape {np.shape(u)}")
        rows = [validate_signal(row, f"u[{i}]") for i, row in enumerate(matrix)]
        run = Run(run_id="u", fs=float(fs), kind="arbitrary", u=rows[0], channels=dict(zip(inputs[1:], rows[1:])),
                  inputs=inputs)
        out = simulate_all(self._points, [run], seed=seed, workers=workers, step=progress)
        return out[0].output_matrix()

    def to_dict(self) -> dict:
        """The config as a dict (a copy): the keys as written, with the values set by
        :meth:`with_parameters`."""
        from nlsid.models.key_paths import deep_copy

        return deep_copy(self._data)

    def write(self, path: str | os.PathLike, force: bool = False) -> Path:
        """Write the config as YAML (``.yaml`` or ``.yml``) atomically; an existing file only with
        ``force``. Reading it back with :meth:`from_yaml` gives the same config."""
        from nlsid.io.atomic import check_suffix, write_text_atomic

        check_suffix(path, (".yaml", ".yml"))
        return write_text_atomic(path, to_yaml(self._data), force=force)

    def _repr_html_(self) -> str:
        """A notebook's view: the model's type, its file, and its numbers by key path."""
        from html import escape

        rows = "".join(f"<tr><td><code>{escape(key)}</code></td><td>{value:.6g}</td></tr>"
                       for key, value in self.parameters.items())
        return (f"<p><b>{escape(repr(self))}</b></p>"
                f"<table><tr><th>parameter</th><th>value</th></tr>{rows}</table>")

    def __repr__(self) -> str:
        model = self._data.get("model", {})
        kind = model.get("type") if isinstance(model, dict) else None
        loop = ", closed loop" if "closed_loop" in self._data else ""
        sweep = f", sweep of {len(self._points)}" if len(self._points) > 1 else ""
        return f"Model({kind}{loop}{sweep}, path={self.path!r})"


def _number(key: str, value) -> float | int:
    """A value for a config key as a plain Python number (numpy scalars too); an int stays an int
    (keys such as ``closed_loop.computation_delay`` take whole numbers only)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(key, f"expected a number, got {value!r}")
    return int(value) if isinstance(value, numbers.Integral) else float(value)


#: Text written without quotes: names and key paths, which no YAML resolver takes for a number
_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_.\[\]/-]*")


def to_yaml(data: dict) -> str:
    """A config as YAML text that the config loader reads back to the same data (YAML 1.2: text
    that would read as a number, a boolean or null is quoted)."""
    import yaml

    reserved = {"true", "false", "null", "yes", "no", "on", "off", "y", "n"}

    class Dumper(yaml.SafeDumper):
        pass

    def text(dumper, value: str):
        plain = _PLAIN.fullmatch(value) is not None and value.lower() not in reserved
        return dumper.represent_scalar("tag:yaml.org,2002:str", value, style=None if plain else '"')

    Dumper.add_representer(str, text)
    return yaml.dump(data, Dumper=Dumper, sort_keys=False, default_flow_style=False, allow_unicode=True)
