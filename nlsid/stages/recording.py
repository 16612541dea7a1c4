"""A recording in memory: the runs of an experiment (u, y, r and further channels), read from a file
or made by a stage, and written back in the recording format.

This is what the stage functions of :mod:`nlsid` take and give (``nlsid.read``, ``nlsid.design``,
``Model.simulate``); the file formats themselves are :mod:`nlsid.io.recording`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Mapping

import numpy as np

from nlsid.io.run import Run


@dataclass
class Recording:
    """Runs of one experiment, with where they came from.

    Attributes
    ----------
    runs : list of Run
        Each run's signals (``u``; ``y`` and ``r`` when measured; ``channels``) and attributes
        (``fs``, ``kind``, ``period``, ``level``, ``excited_bins``, ...): ``docs/formats.md``.
    provenance : dict
        Tool, version, command, configs and inputs of the file (empty for a recording made here).
    path : str or None
        The file it was read from, if any.

    Examples
    --------
    >>> import numpy as np
    >>> from nlsid.io.run import make_run
    >>> run = make_run("r0", {"fs": 100.0, "kind": "arbitrary"}, {"u": np.ones(8), "y": np.zeros(8)}, "r0", True)
    >>> rec = Recording([run])
    >>> rec.fs, rec.run_ids, rec.signals
    (100.0, ['r0'], ['u', 'y'])
    """

    runs: list[Run]
    provenance: dict = field(default_factory=dict)
    path: str | None = None

    def __iter__(self) -> Iterator[Run]:
        return iter(self.runs)

    def __len__(self) -> int:
        return len(self.runs)

    def __getitem__(self, key: int | str) -> Run:
        """A run by position or by id."""
        if isinstance(key, str):
            for run in self.runs:
                if run.run_id == key:
                    return run
            raise KeyError(f"no run {key!r}; runs: {', '.join(self.run_ids)}")
        return self.runs[key]

    @property
    def run_ids(self) -> list[str]:
        """The runs' ids, in order."""
        return [run.run_id for run in self.runs]

    @property
    def fs(self) -> float | None:
        """The sample rate shared by every run (None when the runs differ, or there are none)."""
        rates = {float(run.fs) for run in self.runs}
        return rates.pop() if len(rates) == 1 else None

    @property
    def signals(self) -> list[str]:
        """The signals that every run holds, of u, y and r."""
        return [name for name in ("u", "y", "r") if self.runs and all(getattr(run, name) is not None for run in self.runs)]

    @property
    def channels(self) -> list[str]:
        """The further measured channels of the runs (union, sorted)."""
        return sorted({name for run in self.runs for name in run.channels})

    @property
    def units(self) -> dict[str, str]:
        """The unit of each signal and channel that every run records alike."""
        from nlsid.io.units import common_units

        return common_units(run.units for run in self.runs)

    def write(self, path: str | os.PathLike, force: bool = False) -> Path:
        """Write the runs (HDF5 for ``.h5``/``.hdf5``, MCAP for ``.mcap``) atomically; an existing file
        only with ``force``. Returns the path written."""
        from nlsid.io.atomic import RECORDING_SUFFIXES, check_suffix, check_writable
        from nlsid.io.recording import write_recording

        check_suffix(str(path), RECORDING_SUFFIXES)
        check_writable(str(path), force)
        return write_recording(path, self.runs, provenance=self.provenance or None, force=force)

    def summary(self) -> dict:
        """Runs, kinds, sample rate, signals and units, as a dict."""
        kinds: dict[str, int] = {}
        for run in self.runs:
            kinds[run.kind] = kinds.get(run.kind, 0) + 1
        return {"path": self.path, "runs": len(self.runs), "kinds": kinds, "fs": self.fs, "signals": self.signals,
                "channels": self.channels, "units": self.units,
                "samples": int(sum(run.n_samples for run in self.runs))}

    def _repr_html_(self) -> str:
        from html import escape

        s = self.summary()
        kinds = ", ".join(f"{n} {kind}" for kind, n in s["kinds"].items())
        rows = "".join(f"<tr><td>{escape(run.run_id)}</td><td>{escape(run.kind)}</td><td>{run.n_samples}</td>"
                       f"<td>{'' if run.level is None else f'{run.level:.4g}'}</td></tr>" for run in self.runs[:20])
        more = f"<p>... {len(self.runs) - 20} more</p>" if len(self.runs) > 20 else ""
        return (f"<p><b>Recording</b> {escape(str(s['path'] or ''))}: {s['runs']} runs ({escape(kinds)}), "
                f"fs = {s['fs']} Hz, signals {', '.join(s['signals'])}</p>"
                f"<table><tr><th>run</th><th>kind</th><th>samples</th><th>level</th></tr>{rows}</table>{more}")

    def __repr__(self) -> str:
        s = self.summary()
        return f"Recording({s['runs']} runs, fs={s['fs']}, signals={s['signals']}, path={s['path']!r})"


def read(path: str | os.PathLike, mapping: Mapping[str, str] | None = None, require_y: bool = False) -> Recording:
    """Read a recording file (HDF5 or MCAP) into memory.

    Parameters
    ----------
    path : str or path-like
        A recording written by nlsid (``design``, ``simulate``, ``import``) or measured in its
        format (``docs/formats.md``).
    mapping : dict, optional
        For a foreign MCAP log: signal (``u``, ``y``, ``r``, ``channels.NAME``) -> ``/topic:field``.
    require_y : bool
        Refuse runs without a measured output y (an excitation file has none).

    Returns
    -------
    Recording

    Raises
    ------
    nlsid.InputError
        The file is missing, not a recording, or a run breaks the format (the message names it).

    Examples
    --------
    A designed excitation written and read back (``sample_data/stage.h5`` reads alike):

    >>> import os, tempfile
    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 100.0, "seed": 1, "multisine": {"period": 100, "band": [1.0, 20.0],
    ...                                                            "realizations": 2, "periods": 2,
    ...                                                            "rms_levels": [1.0]}})
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     rec = nlsid.read(exc.write(os.path.join(folder, "excitation.h5")))
    ...     print(rec.path.endswith("excitation.h5"), rec.run_ids, rec.fs, rec.signals)
    True ['ms_l00_m00', 'ms_l00_m01'] 100.0 ['u']
    >>> run = rec["ms_l00_m01"]
    >>> run.kind, run.period, run.n_periods, bool(np.array_equal(run.u, exc[1].u))
    ('multisine', 100, 2, True)
    >>> try:
    ...     nlsid.read("no_such_file.h5")
    ... except nlsid.InputError as error:
    ...     print(error.where)
    no_such_file.h5
    """
    from nlsid.io.recording import open_recording

    with open_recording(path, require_y=require_y, mapping=dict(mapping) if mapping else None) as source:
        runs = list(source)
        provenance = dict(getattr(source, "provenance", None) or {})
    return Recording(runs, provenance, str(path))
