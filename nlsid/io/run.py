"""One run of a recording: a continuous record of u, y (and r, and further measured channels) with
its excitation metadata, and which of its signals are the inputs and outputs of a system with
several of them.

This is the in-memory form of the recording format of ``docs/formats.md``. The HDF5 and MCAP
readers both parse their attributes through :func:`parse_run_attrs` and check the arrays through
:func:`validate_run`, so both formats accept and reject exactly the same content.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, fields
from typing import Any, Iterable, Mapping

import numpy as np

from nlsid.errors import InputError

KINDS = ("multisine", "sine", "arbitrary")
SIGNALS = ("u", "y", "r")
#: The run attributes naming inputs and outputs (format version 3) and their defaults, the first name of each.
IO_DEFAULTS = {"inputs": ("u",), "outputs": ("y",)}
#: The run attributes of format version 3 (ignored in files of older versions).
VERSION_3_ATTRS = (*IO_DEFAULTS, "experiment")
#: A run without its measured output, read where one is required (also :mod:`nlsid.feeds`).
MISSING_Y = "missing dataset 'y' (this is an excitation without a measured output?)"


@dataclass
class Run:
    """A continuous record and its excitation metadata (see ``docs/formats.md``).

    ``u`` is always present; ``y`` is ``None`` in an excitation file (before simulation or
    measurement); ``r`` is the reference of closed-loop experiments. ``channels`` holds further
    measured signals by name (e.g. ``d``, a force pulse injected by the rig), each as long as
    ``u``; ``units`` may give the unit of a channel as of a signal.

    ``inputs`` and ``outputs`` name the system's inputs and outputs in order: ``u`` (``y``) first,
    then channels of the run. A run of a single-input single-output system keeps the defaults
    ``("u",)`` and ``("y",)``; :meth:`input_matrix` and :meth:`output_matrix` stack them.
    ``experiment`` is the index of the run among the experiments of one realization of
    orthogonal multisines (each experiment excites every input; ``None`` otherwise).
    """

    run_id: str
    fs: float
    kind: str
    u: np.ndarray
    y: np.ndarray | None = None
    r: np.ndarray | None = None
    period: int | None = None
    transient_periods: int = 0
    realization: int | None = None
    level: float | None = None
    frequency: float | None = None
    excited_bins: np.ndarray | None = None
    params: dict = field(default_factory=dict)
    units: dict = field(default_factory=dict)
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    inputs: tuple[str, ...] = ("u",)
    outputs: tuple[str, ...] = ("y",)
    experiment: int | None = None

    @property
    def n_samples(self) -> int:
        return int(self.u.shape[0])

    @property
    def n_periods(self) -> int:
        """Whole steady-state periods P after the transient periods (0 for arbitrary runs)."""
        if self.period is None:
            return 0
        return self.n_samples // self.period - self.transient_periods

    def periods(self, name: str) -> np.ndarray:
        """The steady-state part of signal ``name`` as a (P, N) array, one row per period."""
        x = getattr(self, name)
        if x is None:
            raise InputError(self.run_id, f"run has no signal '{name}'")
        if self.period is None:
            raise InputError(self.run_id, "an arbitrary run has no periods")
        start = self.transient_periods * self.period
        return x[start:].reshape(self.n_periods, self.period)

    @property
    def is_mimo(self) -> bool:
        """Whether the run names more than one input or output (a format version 3 run)."""
        return len(self.inputs) > 1 or len(self.outputs) > 1

    @property
    def needs_version_3(self) -> bool:
        """Whether the run has an attribute of format version 3 (several inputs or outputs, an experiment)."""
        return self.is_mimo or self.experiment is not None

    def named_signal(self, name: str) -> np.ndarray:
        """Signal ``u``, ``y`` or ``r``, or channel ``name``: the samples of one named input or output."""
        x = getattr(self, name) if name in SIGNALS else self.channels.get(name)
        if x is None:
            if name == "y":
                raise InputError(self.run_id, MISSING_Y)
            raise InputError(self.run_id, f"run has no signal or channel '{name}'")
        return x

    def input_matrix(self) -> np.ndarray:
        """The inputs as an (n_inputs, n) array, row i the samples of ``inputs[i]``."""
        return np.stack([self.named_signal(name) for name in self.inputs])

    def output_matrix(self) -> np.ndarray:
        """The outputs as an (n_outputs, n) array, row i the samples of ``outputs[i]``."""
        return np.stack([self.named_signal(name) for name in self.outputs])

    def attrs(self) -> dict[str, Any]:
        """The run's attributes as written to a file (the inverse of :func:`parse_run_attrs`)."""
        out: dict[str, Any] = {"fs": float(self.fs), "kind": self.kind}
        if self.period is not None:
            out["period"] = int(self.period)
        out["transient_periods"] = int(self.transient_periods)
        for key in ("realization", "experiment"):
            if getattr(self, key) is not None:
                out[key] = int(getattr(self, key))
        for key in ("level", "frequency"):
            if getattr(self, key) is not None:
                out[key] = float(getattr(self, key))
        if self.excited_bins is not None:
            out["excited_bins"] = np.asarray(self.excited_bins, dtype=np.int64)
        if self.params:
            out["params"] = json.dumps(self.params, sort_keys=True)
        for key, default in IO_DEFAULTS.items():
            if tuple(getattr(self, key)) != default:
                out[key] = list(getattr(self, key))
        return out


def reference_names(n_inputs: int) -> tuple[str, ...]:
    """The references of a run with ``n_inputs`` inputs, one per input: ``r``, then the channels
    ``r2`` .. ``r<n_u>`` (as the inputs are ``u``, ``u2``, ...)."""
    return ("r",) + tuple(f"r{index}" for index in range(2, n_inputs + 1))


def missing_references(run: Run) -> list[str]:
    """The references of :func:`reference_names` that ``run`` does not carry."""
    return [name for name in reference_names(len(run.inputs))
            if (run.r if name == "r" else run.channels.get(name)) is None]


def _scalar(value: Any) -> Any:
    """Unwrap numpy scalars, 0-d and 1-element arrays and bytes as plain Python values."""
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray):
        if value.size != 1:
            return value
        value = value.reshape(()).item()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _float(attrs: Mapping, key: str, where: str, required: bool) -> float | None:
    if key not in attrs:
        if required:
            raise InputError(where, f"missing attribute '{key}'")
        return None
    value = _scalar(attrs[key])
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}.{key}", f"expected a finite number, got {value!r}")
    return float(value)


def _int(attrs: Mapping, key: str, where: str, required: bool, default: int | None = None) -> int | None:
    if key not in attrs:
        if required:
            raise InputError(where, f"missing attribute '{key}'")
        return default
    value = _scalar(attrs[key])
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where}.{key}", f"expected an integer, got {value!r}")
    return value


def parse_run_attrs(run_id: str, attrs: Mapping, where: str) -> dict[str, Any]:
    """Parse and check a run's attributes; return keyword arguments for :class:`Run`.

    ``where`` prefixes every message (e.g. ``rec.h5:/runs/ms_00``). Values may be numpy scalars,
    1-element arrays or bytes, as other tools write them with plain h5py.
    """
    fs = _float(attrs, "fs", where, required=True)
    if fs <= 0:
        raise InputError(f"{where}.fs", f"sample rate must be > 0, got {fs}")
    kind = _scalar(attrs["kind"]) if "kind" in attrs else None
    if kind is None:
        raise InputError(where, "missing attribute 'kind'")
    if kind not in KINDS:
        raise InputError(f"{where}.kind", f"expected one of {', '.join(KINDS)}, got {kind!r}")
    period = _int(attrs, "period", where, required=kind != "arbitrary")
    if period is not None and period < 2:
        raise InputError(f"{where}.period", f"samples per period must be >= 2, got {period}")
    transient = _int(attrs, "transient_periods", where, required=False, default=0)
    if transient < 0:
        raise InputError(f"{where}.transient_periods", f"must be >= 0, got {transient}")
    experiment = _int(attrs, "experiment", where, required=False)
    if experiment is not None and experiment < 0:
        raise InputError(f"{where}.experiment", f"must be >= 0, got {experiment}")
    out: dict[str, Any] = {
        "run_id": run_id,
        "fs": fs,
        "kind": kind,
        "period": period,
        "transient_periods": transient,
        "realization": _int(attrs, "realization", where, required=False),
        "experiment": _int(attrs, "experiment", where, required=False),
        "level": _float(attrs, "level", where, required=False),
        "frequency": _float(attrs, "frequency", where, required=kind == "sine"),
    }
    if out["frequency"] is not None and not 0 < out["frequency"] < fs / 2:
        raise InputError(f"{where}.frequency", f"must lie in (0, fs/2 = {fs / 2:g}) Hz, got {out['frequency']:g}")
    out["excited_bins"] = _bins(attrs, where, period, required=kind == "multisine")
    out["params"] = _params(attrs, where)
    for key, default in IO_DEFAULTS.items():
        out[key] = _names(attrs, key, where, default)
    return out


def _names(attrs: Mapping, key: str, where: str, default: tuple[str, ...]) -> tuple[str, ...]:
    """A list of signal and channel names (text, or a 1-D array of text as h5py reads it)."""
    if key not in attrs:
        return default
    raw = attrs[key]
    items = [raw] if isinstance(raw, (str, bytes)) else raw
    try:
        names = [_scalar(item) for item in np.asarray(items, dtype=object).reshape(-1)] \
            if np.ndim(items) == 1 else None
    except (TypeError, ValueError):
        names = None
    if not names or not all(isinstance(name, str) for name in names):
        raise InputError(f"{where}.{key}", f"expected a non-empty list of names, e.g. {list(default) + ['x2']}, got {raw!r}")
    return tuple(names)


def check_io_names(inputs: tuple[str, ...], outputs: tuple[str, ...], channels: Iterable[str], where: str) -> None:
    """Check a run's ``inputs`` and ``outputs``: ``u`` (``y``) first, then channels of the run, no
    name twice (within or across the two lists). ``where`` names the run (``WHERE.inputs`` in messages)."""
    channels = set(channels)
    seen: set[str] = set()
    for key, names in (("inputs", inputs), ("outputs", outputs)):
        check_names(key, names, channels, seen, f"{where}.{key}")


def check_names(key: str, names: tuple[str, ...], channels: set[str], seen: set[str], where: str) -> None:
    """Check the list ``key`` (``inputs`` or ``outputs``) of names: ``u`` (``y``) first, then
    ``channels``, none of ``seen`` (the names of the other list, checked first), which it extends.
    Errors name ``where`` (a run's attribute, or an option)."""
    first = IO_DEFAULTS[key][0]
    if not names or names[0] != first:
        raise InputError(where, f"the first of the {key} must be {first!r}, got {list(names)}")
    for name in names:
        if name in seen:
            raise InputError(where, f"{name!r} is named twice among the inputs and outputs")
        seen.add(name)
        if name != first and name not in channels:
            found = ", ".join(sorted(channels)) or "none"
            raise InputError(where, f"{name!r} is not a channel of the run (channels: {found})")


def _bins(attrs: Mapping, where: str, period: int | None, required: bool) -> np.ndarray | None:
    if "excited_bins" not in attrs:
        if required:
            raise InputError(where, "missing attribute 'excited_bins' (required for a multisine)")
        return None
    raw = np.atleast_1d(np.asarray(attrs["excited_bins"]))
    if raw.ndim != 1 or raw.size == 0 or not np.issubdtype(raw.dtype, np.number):
        raise InputError(f"{where}.excited_bins", "expected a non-empty 1-D integer array")
    if not np.all(np.isfinite(raw)) or not np.all(raw == np.round(raw)):
        raise InputError(f"{where}.excited_bins", "expected integer bin indices")
    bins = raw.astype(np.int64)
    if period is not None and (bins.min() < 1 or bins.max() >= period / 2):
        raise InputError(
            f"{where}.excited_bins",
            f"bins must lie in 1..{(period - 1) // 2} (below Nyquist of a {period}-sample period), "
            f"got {bins.min()}..{bins.max()}",
        )
    if np.any(np.diff(bins) <= 0):
        raise InputError(f"{where}.excited_bins", "bins must be strictly increasing")
    return bins


def _params(attrs: Mapping, where: str) -> dict:
    if "params" not in attrs:
        return {}
    text = _scalar(attrs["params"])
    try:
        params = json.loads(text) if isinstance(text, str) else None
    except json.JSONDecodeError as exc:
        raise InputError(f"{where}.params", f"expected JSON text, {exc.msg} at position {exc.pos}") from None
    if not isinstance(params, dict):
        raise InputError(f"{where}.params", "expected JSON text of an object, e.g. {\"K_fc\": 0.12}")
    return params


def validate_signal(x: Any, where: str) -> np.ndarray:
    """Check one signal: a 1-D real array of finite numbers; return it as float64."""
    arr = np.asarray(x)
    if arr.ndim != 1 or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InputError(where, f"expected a 1-D real array, got shape {arr.shape} of {arr.dtype}")
    arr = arr.astype(np.float64, copy=False)
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.argmax(bad))
        raise InputError(where, f"{int(bad.sum())} NaN or Inf samples (first at index {first})")
    return arr


def check_lengths(n: dict[str, int], kw: Mapping, where: str) -> None:
    """Check that all signals have one length and that a periodic run holds whole periods."""
    if len(set(n.values())) > 1:
        detail = ", ".join(f"{k} has {v}" for k, v in n.items())
        raise InputError(where, f"signals differ in length: {detail}")
    length = next(iter(n.values()))
    if length == 0:
        raise InputError(where, "signals are empty")
    period = kw.get("period")
    if period is None:
        return
    transient = kw.get("transient_periods", 0)
    whole, rest = divmod(length, period)
    if rest or whole <= transient:
        raise InputError(
            where,
            f"{length} samples is not (transient_periods {transient} + whole periods >= 1) x period {period}",
        )


CHANNEL_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: ``CHANNEL_KEY + NAME`` names channel NAME beside u, y, r in a mapping of sources (``--map``, importers).
CHANNEL_KEY = "channels."
#: Names a channel may not have: the signals, and the names of the run's fields, properties and
#: methods and of the attributes a file stores beside them (MCAP ``run``, ``n_samples``, ``signals``).
RESERVED_CHANNEL_NAMES = frozenset(
    {*SIGNALS, *(f.name for f in fields(Run)), *(n for n in vars(Run) if not n.startswith("_")),
     "run", "n_samples", "signals"})


def check_channel_name(name: Any, where: str) -> str:
    """Refuse a channel name that is not an identifier, or is a signal or run attribute name."""
    if not isinstance(name, str) or not CHANNEL_NAME.fullmatch(name):
        raise InputError(where, f"channel name {name!r} is not an identifier ([A-Za-z_][A-Za-z0-9_]*)")
    if name in RESERVED_CHANNEL_NAMES:
        raise InputError(where, f"channel name {name!r} is reserved (not a channel name: "
                                f"{', '.join(sorted(RESERVED_CHANNEL_NAMES))})")
    return name


def make_run(
    run_id: str,
    attrs: Mapping,
    signals: Mapping[str, Any],
    where: str,
    require_y: bool,
    units: Mapping[str, str] | None = None,
    channels: Mapping[str, Any] | None = None,
) -> Run:
    """Build a validated :class:`Run` from raw attributes, signal and channel arrays and their units.

    Each channel (errors name ``WHERE/channels/NAME``) must have a valid name and be a 1-D real
    array of finite numbers as long as u; this is the one check of channels for every format.
    The attributes ``inputs`` and ``outputs`` must name u (y) and then channels of the run.
    """
    kw = parse_run_attrs(run_id, attrs, where)
    if "u" not in signals:
        raise InputError(where, "missing dataset 'u'")
    if require_y and "y" not in signals:
        raise InputError(where, MISSING_Y)
    arrays = {name: validate_signal(signals[name], f"{where}/{name}") for name in SIGNALS if name in signals}
    check_lengths({k: v.shape[0] for k, v in arrays.items()}, kw, where)
    checked = {}
    for name, x in (channels or {}).items():
        at = f"{where}/channels/{name}"
        check_channel_name(name, at)
        checked[name] = validate_signal(x, at)
        if checked[name].shape[0] != arrays["u"].shape[0]:
            raise InputError(at, f"channel has {checked[name].shape[0]} samples, u has {arrays['u'].shape[0]}")
    check_io_names(kw["inputs"], kw["outputs"], checked, where)
    return Run(**kw, **arrays, units=dict(units or {}), channels=checked)
