"""The ``fit`` stage: a transfer function fitted to a BLA, or the free parameters of a model fitted to data.

``nlsid.fit_tf(bla_result)`` gives a :class:`TransferFunctionFit` and ``nlsid.fit_model(model,
recording)`` a :class:`ModelFit`; the command ``nlsid fit`` is one of them, a ``write`` and a few
printed lines. The methods are those of :mod:`nlsid.fit.tf_fit` and :mod:`nlsid.fit.order` (sample
maximum likelihood weighted by the BLA's variance, order selection) and of
:mod:`nlsid.fit.extension` (simulation error minimised over the free parameters).

A BLA computed in memory is fitted exactly as its ``bla.h5`` file would be: the same level is taken
with the same weight (``robust/var_total``, the fast method's, the noise variance, or for levels of
arbitrary runs the LPM's smoothed ``var_G_smoothed``; :mod:`nlsid.fit.bla_source`), so
``fit_tf(bla(rec))`` and ``nlsid fit bla.h5`` give the same numbers.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.bla_fit import BLAFit
from nlsid.fit.computation_delay import DelayChoice, candidates_of, choose_delay
from nlsid.fit.extension import ExtensionFit
from nlsid.stages.bla import BlaResult
from nlsid.stages.held_out import declares_several, held_out, whole
from nlsid.stages.model import Model
from nlsid.stages.recording import Recording

_ORDER = re.compile(r"(\d+)/(\d+)")

#: the options of the fitting modules' own messages -> the argument of :func:`fit_tf` they are
_INNER_OPTIONS = {"--order": "order", "--delay": "delay", "--max-order": "max_order", "--domain": "domain",
                  "--level": "level"}


def check_tf_options(order, domain: str, delay, max_order, level,
                     names: Mapping[str, str] | None = None) -> tuple[tuple[int, int] | None, int | None]:
    """The options of :func:`fit_tf`, checked and parsed: ``(nb, na)`` or None (``auto``), and the
    delay in samples or None (``auto``). ``names`` maps an argument to how the caller calls it
    (``{"order": "--order"}`` on the command line)."""
    names = names or {}
    if isinstance(order, str):
        text = order.strip()
        match = _ORDER.fullmatch(text)
        if text != "auto" and match is None:
            raise InputError(names.get("order", "order"),
                             f"expected NB/NA (numerator/denominator orders, e.g. 2/2) or auto, got {order!r}")
        pair = None if text == "auto" else (int(match.group(1)), int(match.group(2)))
    elif isinstance(order, (tuple, list)) and len(order) == 2 and all(whole(x) and x >= 0 for x in order):
        pair = (int(order[0]), int(order[1]))
    else:
        raise InputError(names.get("order", "order"),
                         f"expected (nb, na), whole numbers >= 0, \"NB/NA\" or \"auto\", got {order!r}")
    if domain not in ("s", "z"):
        raise InputError(names.get("domain", "domain"), f"expected s or z, got {domain!r}")
    if isinstance(delay, str) and (delay == "auto" or delay.isdigit()):
        samples = None if delay == "auto" else int(delay)
    elif whole(delay) and delay >= 0:
        samples = int(delay)
    else:
        raise InputError(names.get("delay", "delay"), f"expected a whole number of samples >= 0 or auto, got {delay!r}")
    if max_order is not None and not (whole(max_order) and max_order >= 1):
        raise InputError(names.get("max_order", "max_order"),
                         f"expected a whole number >= 1 or None, got {max_order!r}")
    if level is not None and not (whole(level) and level >= 0):
        raise InputError(names.get("level", "level"), f"expected a level index >= 0 or None, got {level!r}")
    return pair, samples


def _renamed(error: InputError, names: Mapping[str, str]) -> InputError:
    """An error of the fitting modules, which name the command's options, naming the caller's argument."""
    head, _, tail = error.where.partition(" ")
    argument = _INNER_OPTIONS.get(head)
    if argument is None:
        return error
    return InputError(names.get(argument, argument) + (f" {tail}" if tail else ""), error.what)


def _arrays(obj, keys: Sequence[str]) -> dict[str, np.ndarray]:
    """The attributes of ``obj`` that are set, as the datasets ``bla.h5`` stores of them."""
    return {key: np.asarray(getattr(obj, key)) for key in keys if getattr(obj, key, None) is not None}


def _layout(result: BlaResult) -> tuple[list[dict], list[dict]]:
    """The levels of a BLA computed in memory in the layout :func:`nlsid.io.bla_file.read_bla` gives
    its file (the keys the fit reads), so that both are fitted by one code path."""
    levels = []
    for index, level in enumerate(result.levels):
        lines = level.lines
        levels.append({
            "name": f"level_{index:02d}",
            "attrs": {"n_realizations": int(level.n_realizations), "n_periods": int(level.n_periods),
                      "period": int(lines.period), "fs": float(lines.fs), "u_rms": float(level.u_rms)},
            "excited_bins": np.asarray(lines.excited).astype(np.int64),
            "robust": _arrays(level.robust, ("G", "var_total", "var_noise", "var_nl")),
            "fast": None if level.fast is None else _arrays(level.fast, ("G", "var_total")),
        })
    lpm_levels = []
    for index, level in enumerate(result.lpm_levels):
        lpm = level.result
        lpm_levels.append({
            "name": f"level_{index:02d}",
            "attrs": {"fs": float(lpm.fs), "n_samples": int(lpm.n_samples), "dof": int(lpm.dof),
                      "u_rms": float(level.u_rms),
                      "smoothing_lines": int(lpm.smoothing_lines), "smoothed_dof": float(lpm.smoothed_dof),
                      "half_width": int(lpm.half_width)},
            "bins": np.asarray(level.bins).astype(np.int64), "G": np.asarray(level.G),
            "var_G": np.asarray(level.var_G), "var_G_smoothed": np.asarray(lpm.var_G_smoothed[level.band]),
        })
    return levels, lpm_levels


#: the keys of the fit report that ``nlsid fit BLA --json`` prints (besides the paths)
JSON_KEYS = ("domain", "order", "delay_samples", "num", "den", "parameters", "cost", "expected_cost", "cost_std",
             "cost_bound", "weights", "weighted", "lines", "stable", "stability", "integrators", "fit", "fit_note",
             "order_reason", "order_scan", "warnings", "level")


@dataclass
class TransferFunctionFit:
    """A rational transfer function fitted to one level of a BLA, with its cost check.

    Attributes
    ----------
    fitted : nlsid.fit.bla_fit.BLAFit
        The level fitted (``.level.data``: frequencies, BLA, weights) and the fit (``.fit``: model,
        parameters, covariance, cost, response and its std per line), and the order scan of
        ``order="auto"`` (``.selection``).
    source : str
        The BLA fitted: the ``bla.h5`` path, or ``BLA of <recording>``.
    units : dict
        Signal -> unit of the recording behind the BLA (for the figure).
    inputs : list of str
        Files the fit comes from (its provenance).
    level : dict
        The level fitted: ``index`` (as ``level`` / ``--level`` take it) and ``rms`` (of u),
        :func:`nlsid.analysis.level_names.level_summary`.

    Examples
    --------
    The BLA of a mass-spring-damper 1/(m s^2 + c s + k), m = 2, c = 20, k = 2000, fitted by
    b0 / (s^2 + a1 s + a0): the coefficients are 1/m, c/m and k/m, each found within five of its
    standard deviations, and the cost lies below its bound:

    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> plant = nlsid.Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0,
    ...                                          "stiffness": 2000.0}, "disturbances": {"y_noise": 1e-6, "seed": 3}})
    >>> tf = nlsid.fit_tf(nlsid.bla(plant.simulate(exc)), order=(0, 2))
    >>> tf.order, tf.domain, tf.delay, tf.stable, tf.level
    ((0, 2), 's', 0, True, {'index': 0, 'rms': 1.0})
    >>> p = tf.summary()["parameters"]
    >>> [bool(abs(p[name]["value"] - true) < 5 * p[name]["std"]) for name, true in
    ...  (("b0", 0.5), ("a1", 10.0), ("a0", 1000.0))]
    [True, True, True]
    >>> bool(np.allclose(tf.den, [1.0, p["a1"]["value"], p["a0"]["value"]])), tf.cost < tf.summary()["cost_bound"]
    (True, True)
    >>> G = tf.frequency_response([5.0], sampled=False)
    >>> s = 2j * np.pi * 5.0
    >>> bool(abs(G[0] * (2.0 * s**2 + 20.0 * s + 2000.0) - 1) < 1e-3)  # coefficients' std: about 1e-4 relative
    True
    """

    fitted: BLAFit
    source: str
    units: dict = field(default_factory=dict)
    inputs: list[str] = field(default_factory=list)
    level: dict = field(default_factory=lambda: {"index": 0, "rms": None})

    @property
    def level_name(self) -> str:
        """The level fitted as every stage names it: ``level 1 (rms 2 N)`` (:mod:`nlsid.analysis.level_names`)."""
        from nlsid.analysis.level_names import level_name

        return level_name(self.level["index"], self.level["rms"], self.units.get("u"))

    @property
    def model(self):
        """The fitted :class:`nlsid.models.lti.TransferFunction`, or for many poles its
        :class:`nlsid.fit.modal_model.ModalModel` (:attr:`modal`); ``.config()`` is the ``model`` block."""
        return self.fitted.fit.model

    @property
    def modal(self):
        """The modal state space (:class:`nlsid.fit.modal_model.ModalModel`) of a fit of many poles whose
        polynomial coefficients do not reproduce it in floating point, else None (the model is a
        :class:`nlsid.models.lti.TransferFunction`)."""
        from nlsid.fit.modal_model import ModalModel

        return self.model if isinstance(self.model, ModalModel) else None

    @property
    def num(self) -> np.ndarray:
        """Numerator: descending powers of s (``domain="s"``) or ascending powers of z^-1 (``"z"``)
        (of a :attr:`modal` model: its polynomial coefficients, for reference only)."""
        return np.array(self.model.num, dtype=float)

    @property
    def den(self) -> np.ndarray:
        """Denominator, in the powers of :attr:`num`, with ``den[0] = 1``."""
        return np.array(self.model.den, dtype=float)

    @property
    def domain(self) -> str:
        """``"s"`` (continuous) or ``"z"`` (discrete at :attr:`fs`)."""
        return self.model.domain

    @property
    def fs(self) -> float:
        """Sample rate of the BLA (Hz): of the discrete model, or of the hold the continuous one is seen through."""
        return float(self.model.fs)

    @property
    def delay(self) -> int:
        """Dead time in samples at :attr:`fs`."""
        return int(self.model.delay)

    @property
    def delay_seconds(self) -> float:
        """Dead time in seconds: :attr:`delay` / :attr:`fs`."""
        return self.delay / self.fs

    @property
    def order(self) -> tuple[int, int]:
        """(nb, na)."""
        return self.fitted.fit.nb, self.fitted.fit.na

    @property
    def cost(self) -> float:
        """The weighted cost at the fit, sum_k |G_BLA(k) - G(Omega_k)|^2 / sigma_k^2 (its expected
        value and bound: :meth:`summary`)."""
        return float(self.fitted.fit.cost)

    @property
    def stable(self) -> bool:
        """Every pole strictly inside the unit circle (z) or the left half plane (s)."""
        return bool(self.model.stable())

    @property
    def warnings(self) -> list[str]:
        """What the fit doubts (rough weights, an unstable or boundary fit, an order cap reached)."""
        return list(self.fitted.warnings)

    def report(self) -> dict:
        """Every number of the fit report ``<model>.fit.json`` (``docs/formats.md``), without provenance;
        ``level``: the level fitted (:attr:`level`)."""
        return {**self.fitted.report(), "level": dict(self.level)}

    def summary(self) -> dict:
        """The ``nlsid fit BLA --json`` summary without paths: order, coefficients, parameters with
        std, cost against its expected value and bound, stability, the order scan, warnings."""
        report = self.report()
        return {key: report[key] for key in JSON_KEYS}

    def header(self, report_name: str) -> list[str]:
        """The comment lines of the model YAML (``report_name``: the report file beside it)."""
        fit_, report, level = self.fitted.fit, self.report(), self.fitted.level
        form = "transfer function" if self.modal is None else "transfer function as a modal state space"
        return [f"nlsid fit {self.source}, {self.level_name}: {fit_.nb}/{fit_.na} {self.domain}-domain {form}, "
                f"{report['stability']}" + (f" ({fit_.integrators} integrator(s))" if fit_.integrators else ""),
                f"cost {fit_.cost:.6g}, {cost_check(fit_)} ({fit_.lines} lines)",
                f"weights: {level.weights}" if level.weighted
                else "unweighted least squares: the BLA is noise-free (zero variances), no weights to fit with",
                f"order: {report['order_reason']}",
                f"report: {report_name}"]

    def frequency_response(self, f, sampled: bool = True) -> np.ndarray:
        """The model's frequency response at ``f`` (Hz), dead time included.

        ``sampled`` (default): the response of the sampled model, what the fit compares with the BLA
        (a continuous model through the zero-order hold at :attr:`fs`, as ``nlsid simulate`` runs it).
        ``sampled=False`` gives B(j 2 pi f) / A(j 2 pi f) e^{-j 2 pi f delay} of a continuous model
        (a discrete model has only its sampled response).
        """
        frequency = np.asarray(f, dtype=float)
        if not np.all(np.isfinite(frequency)):
            raise InputError("f", "expected finite frequencies in Hz")
        if sampled or self.domain == "z":
            return self.model.response(frequency / self.fs, 1)
        s = 2j * np.pi * frequency
        if self.modal is not None:
            return self.modal.to_state_space().frequency_response(s) * np.exp(-s * self.delay_seconds)
        return np.polyval(self.num, s) / np.polyval(self.den, s) * np.exp(-s * self.delay_seconds)

    def _no_delay(self, where: str) -> None:
        if self.domain == "s" and self.delay:
            raise InputError(where, f"the continuous model has a dead time of {self.delay} samples "
                                    f"({self.delay_seconds:.6g} s), which a rational transfer function cannot hold; "
                                    "use .frequency_response, or a Pade approximation of the delay")

    def _z_polynomials(self) -> tuple[np.ndarray, np.ndarray]:
        """num, den in descending powers of z (z^-d B(z^-1) / A(z^-1) times z^n over z^n), the dead
        time as the numerator's lower degree (leading zeros left out: scipy warns of them)."""
        b, a = self.num, self.den
        n = max(a.size - 1, b.size - 1 + self.delay)
        num, den = np.zeros(n + 1), np.zeros(n + 1)
        num[self.delay:self.delay + b.size] = b
        den[:a.size] = a
        return num[self.delay:], den

    def to_scipy(self):
        """The model as :class:`scipy.signal.lti` (``s``) or :class:`scipy.signal.dlti` (``z``, dt = 1/fs,
        the dead time as poles at z = 0). A continuous model with a dead time is refused (no lti holds one).
        A :attr:`modal` model without dead time is given as its state space (A, B, C, D)."""
        from scipy import signal

        if self.modal is not None and not self.delay:
            ss = self.modal.to_state_space()
            system = (ss.A, ss.B[:, None], ss.C[None, :], np.array([[ss.D]]))
            return signal.dlti(*system, dt=1.0 / self.fs) if self.domain == "z" else signal.lti(*system)
        if self.domain == "z":
            num, den = self._z_polynomials()
            return signal.dlti(num, den, dt=1.0 / self.fs)
        self._no_delay("to_scipy")
        return signal.lti(self.num, self.den)

    def to_control(self):
        """The model as a python-control ``TransferFunction`` (``dt = 1/fs`` for ``z``).

        Raises
        ------
        ImportError
            python-control is not installed (``pip install control``).
        """
        try:
            import control
        except ImportError:
            raise ImportError("to_control needs python-control: pip install control") from None
        if self.domain == "z":
            num, den = self._z_polynomials()
            return control.TransferFunction(num, den, 1.0 / self.fs)
        self._no_delay("to_control")
        return control.TransferFunction(self.num, self.den)

    def png(self) -> bytes:
        """The figure of ``nlsid fit --plot`` as PNG bytes: BLA, model, residual, model std, noise and
        nonlinear std (magnitude), BLA and model (phase)."""
        from nlsid.report.fit_plots import tf_fit_png
        from nlsid.report.units import Units

        fit_, level = self.fitted.fit, self.fitted.level
        return tf_fit_png(level.data.frequency, level.data.G, fit_.response, fit_.response_std, level.noise_std,
                          level.nl_std, f"{self.source}, {self.level_name}: {fit_.nb}/{fit_.na} ({self.domain})",
                          Units(self.units))

    def plot(self):
        """The figure of :meth:`png` as a matplotlib figure (for a notebook)."""
        import io

        import matplotlib.image
        import matplotlib.pyplot as plt

        figure, axes = plt.subplots(figsize=(8, 6))
        axes.imshow(matplotlib.image.imread(io.BytesIO(self.png()), format="png"))
        axes.set_axis_off()
        return figure

    def write(self, path: str | os.PathLike, force: bool = False, provenance: dict | None = None,
              plot: str | os.PathLike | None = None) -> Path:
        """Write the model config ``path`` (YAML that ``nlsid simulate`` runs) and the fit report
        ``<name>.fit.json`` beside it (``docs/formats.md``), and with ``plot`` the figure (PNG), as
        ``nlsid fit`` does; existing files only with ``force``. Returns ``path``."""
        from nlsid.io.atomic import atomic_path, check_writable
        from nlsid.io.fit_file import report_path, write_fit
        from nlsid.io.provenance import provenance as make_provenance

        for target in (path, report_path(path)) + ((plot,) if plot else ()):
            check_writable(str(target), force)
        if plot:
            png = self.png()
            with atomic_path(plot, force) as tmp:
                tmp.write_bytes(png)
        record = provenance if provenance is not None else make_provenance(input_paths=self.inputs)
        if not self.fitted.level.weighted:  # said where the model's origin is read, as allow_overlap is
            record = {**record, "unweighted": True}
        write_fit(path, {"model": self.model.config()}, self.header(report_path(path).name), self.report(), record,
                  force=force)
        return Path(path)

    def _repr_html_(self) -> str:
        from html import escape

        fit_ = self.fitted.fit
        rows = "".join(f"<tr><td>{escape(n)}</td><td>{v:.6g}</td><td>{s:.2g}</td></tr>"
                       for n, v, s in zip(fit_.names, fit_.values, fit_.std))
        warnings = "".join(f"<li>{escape(w)}</li>" for w in self.warnings)
        return (f"<p><b>Transfer function</b> {fit_.nb}/{fit_.na} ({self.domain}-domain, delay {self.delay} samples) "
                f"fitted to {escape(self.source)}, {escape(self.level_name)}: {escape(self.model.stability())}; "
                f"cost {fit_.cost:.5g}, "
                f"{escape(cost_check(fit_))} over {fit_.lines} lines</p>"
                f"<p>order: {escape(self.report()['order_reason'])}</p>"
                f"<table><tr><th>parameter</th><th>value</th><th>std</th></tr>{rows}</table>"
                + (f"<ul>{warnings}</ul>" if warnings else ""))

    def __repr__(self) -> str:
        return (f"TransferFunctionFit({self.order[0]}/{self.order[1]}, domain={self.domain!r}, delay={self.delay}, "
                f"cost={self.cost:.6g}, source={self.source!r})")


def cost_check(fit_) -> str:
    """The cost's expected value, spread and bound in words; what has no finite value is said."""
    if not math.isfinite(fit_.expected_cost):
        return "no expected value and no cost check (M = 2 realizations)"
    spread = f"+- {fit_.cost_std:.3g}" if math.isfinite(fit_.cost_std) else "(spread unbounded for M = 3)"
    return f"expected {fit_.expected_cost:.6g} {spread}, bound {fit_.cost_bound:.6g}"


def fit_tf(b: BlaResult | str | os.PathLike, order=(2, 2), domain: str = "s", level: int | None = None,
           delay: int | str = 0, max_order: int | None = None, *,
           names: Mapping[str, str] | None = None) -> TransferFunctionFit:
    """A rational transfer function B/A fitted to one level of a BLA.

    The cost is the sample maximum likelihood cost in FRF form, sum_k |G_BLA(k) - G(Omega_k)|^2 /
    sigma_k^2, weighted by the variance of the averaged BLA (Schoukens, Pintelon and Rolain 2012,
    Chapter 7), with its expected value and acceptance bound, the parameters' standard deviations
    and, with ``order="auto"``, an order scan (``docs/commands.md``, "Transfer function from a BLA").

    Parameters
    ----------
    b : BlaResult or path
        The BLA (:func:`nlsid.bla`), or a ``bla.h5`` file. Both are fitted alike, with the weights
        the command takes from the file.
    order : (nb, na), "NB/NA" or "auto"
        Numerator and denominator orders, or a scan with selection.
    domain : {"s", "z"}
        ``s``: a continuous model seen through the zero-order hold at the BLA's fs; ``z``: a discrete
        model at that fs. (The command's ``--domain`` defaults to ``z``.)
    level : int, optional
        Level index (multisine levels first, then levels of arbitrary runs); needed when the BLA
        holds several.
    delay : int or "auto"
        Dead time in samples, or the best of 0..10.
    max_order : int, optional
        Largest na of ``order="auto"``: from 5, the poles counted by vector fitting up to it (the
        reason and a warning say where the cap is reached), below 5 the polynomial scan of every
        nb <= na <= it. Default: the count up to 40 (``docs/commands.md``); fewer than 5 poles: the
        polynomial scan up to 4, and up to 10 while no order reaches its bound.
    names : dict, optional
        Argument -> how the caller calls it in messages (the command line passes its flags).

    Returns
    -------
    TransferFunctionFit

    Raises
    ------
    nlsid.InputError
        A bad argument (named), a level without weights, or too few lines for the order.

    Examples
    --------
    >>> import nlsid
    >>> b = nlsid.bla("sample_data/stage.h5")
    >>> tf = nlsid.fit_tf(b, order=(0, 2), level=0)
    >>> tf.order, tf.domain, tf.stable
    ((0, 2), 's', True)
    """
    from nlsid.fit.bla_fit import fit_level

    names = dict(names or {})
    pair, samples = check_tf_options(order, domain, delay, max_order, level, names)
    option = names.get("level", "level")
    try:
        if isinstance(b, BlaResult):
            from nlsid.fit.bla_source import frf_from_levels

            levels, lpm_levels = _layout(b)
            chosen = frf_from_levels(levels, lpm_levels, level, "BlaResult", option, "the BLA")
            source, units, inputs = f"BLA of {b.source}", dict(b.units), list(b.inputs)
            taken = _taken(levels, lpm_levels, level)
        elif isinstance(b, (str, os.PathLike)):
            from nlsid.fit.bla_source import frf_from_levels
            from nlsid.io.bla_file import read_bla, read_units

            from nlsid.stages.frm_fit import frm_level

            content = read_bla(b)
            if frm_level(content, level, str(b), option) is not None:
                raise InputError(option, f"level {level or 0} of {b} has several inputs or outputs: fit its frequency "
                                         "response matrix with nlsid.stages.frm_fit.fit_frm_level (nlsid fit "
                                         "--order N|auto)")
            chosen = frf_from_levels(content["levels"], content["lpm_levels"], level, str(b), option)
            source, units, inputs = str(b), read_units(b), [str(b)]
            taken = _taken(content["levels"], content["lpm_levels"], level)
        else:
            raise InputError(names.get("b", "b"), "expected a BlaResult (nlsid.bla) or the path of a bla.h5 file, "
                                                  f"got {type(b).__name__}")
        fitted = fit_level(chosen, pair, domain, samples, max_order)
    except InputError as error:
        raise _renamed(error, names) from None
    return TransferFunctionFit(fitted, source, units, inputs, taken)


def _taken(levels: list[dict], lpm_levels: list[dict], level: int | None) -> dict:
    """The level :func:`nlsid.fit.bla_source.frf_from_levels` took (its index: ``level``, or 0 where
    the BLA holds one) as :func:`nlsid.analysis.level_names.level_summary` gives it."""
    from nlsid.analysis.level_names import level_summary

    index = 0 if level is None else int(level)
    rms = [*levels, *lpm_levels][index]["attrs"].get("u_rms")
    return level_summary(index, None if rms is None else float(rms))


# ---------------------------------------------------------------------------------------------------
# free parameters of a model


@dataclass
class ModelFit:
    """The free parameters of a model fitted to recorded runs, with their uncertainty and the errors
    on estimation and held-out validation runs.

    Attributes
    ----------
    fitted : nlsid.fit.extension.ExtensionFit
        Names, start and fitted values, std, covariance and correlation, rms errors (fitted and
        start) on estimation and validation runs and per run (``.runs``), noise levels, warnings.
    model_source, data_source : str
        The model config and the recording fitted (paths, or ``model``/``recording``), for the header.
    configs, inputs : list of str
        Config files and recordings the fit comes from (its provenance).
    allow_overlap : bool
        A ``validate_on`` recording that is the fitted one was accepted.
    computation_delay : nlsid.fit.computation_delay.DelayChoice or None
        Where the config asks for ``closed_loop.computation_delay: auto``: the delay chosen, every
        candidate's cost and whether the data decide it; ``fitted`` is the chosen delay's fit.
    units : dict
        The recording's units (signal -> unit, those every run fitted or validated on agrees on),
        from which :attr:`parameter_units` derives each parameter's.

    Examples
    --------
    The mass and stiffness of a mass-spring-damper fitted to its own simulation with output noise
    sigma = 1e-6: each is found within five of its standard deviations, and at the truth the
    validation error is the noise (its rms over the 400 validation samples has a relative std
    of 1/sqrt(800), 3.5 %):

    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> plant = nlsid.Model.from_dict({"model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0,
    ...                                          "stiffness": 2000.0}, "disturbances": {"y_noise": 1e-6, "seed": 3}})
    >>> rec = plant.simulate(exc)
    >>> fit = nlsid.fit_model(plant, rec, free={"model.mass": {"start": 1.5}, "model.stiffness": {}})
    >>> fit.names
    ['model.mass', 'model.stiffness']
    >>> [bool(abs(value - true) < 5 * std) for value, std, true in zip(fit.values, fit.std, (2.0, 2000.0))]
    [True, True]
    >>> [run.role for run in fit.runs]  # the highest realization is held out
    ['estimation', 'estimation', 'estimation', 'validation']
    >>> bool(abs(fit.validation_rms / 1e-6 - 1) < 0.2), fit.parameters["model.mass"]["start"]
    (True, 1.5)
    >>> bool(fit.model.parameters["model.mass"] == fit.values[0]), "free" in fit.config
    (True, False)
    """

    fitted: ExtensionFit
    model_source: str
    data_source: str
    configs: list[str] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)
    allow_overlap: bool = False
    computation_delay: DelayChoice | None = None
    units: dict = field(default_factory=dict)

    @property
    def parameter_units(self) -> dict[str, str | None]:
        """Key path -> the free parameter's unit, from the recording's units and the model's
        structure (:mod:`nlsid.models.parameter_units`): "" for a pure number, None where unknown."""
        from nlsid.models.parameter_units import unit_of

        return {name: unit_of(self.fitted.config, name, self.units) for name in self.fitted.names}

    def parameter_lines(self) -> list[str]:
        """``name = value +- std unit (start value)``, one per free parameter, as ``nlsid fit --model`` prints them."""
        from nlsid.models.parameter_units import with_unit

        result, units = self.fitted, self.parameter_units
        return [f"{with_unit(f'{n} = {v:.6g} +- {s:.2g}', units[n])} (start {s0:.6g})"
                for n, v, s, s0 in zip(result.names, result.values, result.std, result.start)]

    @property
    def names(self) -> list[str]:
        """The free parameters' key paths, in the order of :attr:`values`."""
        return list(self.fitted.names)

    @property
    def values(self) -> np.ndarray:
        """The fitted values."""
        return np.array(self.fitted.values, dtype=float)

    @property
    def std(self) -> np.ndarray:
        """The standard deviations of :attr:`values` (sandwich estimator)."""
        return np.array(self.fitted.std, dtype=float)

    @property
    def parameters(self) -> dict[str, dict]:
        """Name -> value, std, start, lower and upper bound, unit (:attr:`parameter_units`)."""
        return self.summary()["parameters"]

    @property
    def config(self) -> dict:
        """The model config with the fitted values written in and without ``free``: what ``nlsid simulate`` runs."""
        from nlsid.models.key_paths import deep_copy

        return deep_copy(self.fitted.config)

    @property
    def model(self) -> Model:
        """The fitted model: :attr:`config` as a :class:`nlsid.Model` (simulate it, change it, write it)."""
        return Model.from_dict(self.fitted.config)

    @property
    def validation_rms(self) -> float:
        """The rms simulation error of the fitted signal on the validation runs, with the fitted values."""
        return float(self.fitted.validation_rms)

    @property
    def estimation_rms(self) -> float:
        """The rms simulation error on the estimation runs, with the fitted values."""
        return float(self.fitted.estimation_rms)

    @property
    def runs(self) -> list:
        """Per run (:class:`nlsid.fit.extension.RunError`): its role (estimation or validation), rms error
        with the fitted and the start values, rms of y and noise level."""
        return list(self.fitted.runs)

    @property
    def warnings(self) -> list[str]:
        """What the fit doubts, and a computation delay that the data do not decide."""
        choice = self.computation_delay
        if choice is None or choice.decided:
            return list(self.fitted.warnings)
        return list(self.fitted.warnings) + [
            f"computation delay {choice.chosen} not decided by the data: {choice.runner_up} is within what the "
            f"noise explains (cost {choice.difference:.3g} more, the noise explains {choice.noise_part:.3g})"]

    def summary(self) -> dict:
        """The ``nlsid fit --model --json`` summary without paths (``docs/formats.md``)."""
        choice = self.computation_delay
        summary = self.fitted.summary()
        units = self.parameter_units
        parameters = {name: {**entry, "unit": units.get(name)} for name, entry in summary["parameters"].items()}
        return {**summary, "parameters": parameters, "units": dict(self.units), "allow_overlap": self.allow_overlap,
                "computation_delay": None if choice is None else choice.summary()}

    def header(self, report_name: str) -> list[str]:
        """The comment lines of the fitted model's YAML (``report_name``: the report beside it)."""
        from nlsid.models.parameter_units import with_unit

        result, units = self.fitted, self.parameter_units
        fitted = ("fitted: " + ", ".join(with_unit(f"{n} = {v:.6g} +- {s:.2g}", units[n])
                                         for n, v, s in zip(result.names, result.values, result.std)))
        if hasattr(result, "output_lines"):  # several outputs (nlsid.fit.mimo_output_error): each its own
            return [f"nlsid fit --model {self.model_source} --data {self.data_source}", fitted,
                    *result.output_lines(), f"report: {report_name}"]
        return [f"nlsid fit --model {self.model_source} --data {self.data_source}", fitted,
                f"validation rms error of {result.fit_on} {result.validation_rms:.4g} (noise "
                f"{result.noise_rms_validation:.4g}); report: {report_name}"] + (
            [] if self.computation_delay is None else
            [f"closed_loop.computation_delay: {self.computation_delay.chosen}, chosen from auto (0.."
             f"{max(c.delay for c in self.computation_delay.candidates)}) by the lowest error; "
             f"{'decided' if self.computation_delay.decided else 'NOT decided'} by the data (report)"])

    def write(self, path: str | os.PathLike, force: bool = False, provenance: dict | None = None) -> Path:
        """Write the fitted model config ``path`` (YAML) and the fit report ``<name>.fit.json`` beside it,
        as ``nlsid fit --model`` does; existing files only with ``force``. Returns ``path``."""
        from nlsid.io.fit_file import report_path, write_fit
        from nlsid.io.provenance import provenance as make_provenance

        record = (provenance if provenance is not None
                  else make_provenance(config_paths=self.configs, input_paths=self.inputs))
        if self.allow_overlap:
            record = {**record, "allow_overlap": True}
        write_fit(path, self.fitted.config, self.header(report_path(path).name),
                  {"kind": "extension", **self.summary()}, record, force=force)
        return Path(path)

    def _repr_html_(self) -> str:
        from html import escape

        result, units = self.fitted, self.parameter_units
        rows = "".join(f"<tr><td>{escape(n)}</td><td>{v:.6g}</td><td>{s:.2g}</td><td>{escape(units[n] or '')}</td>"
                       f"<td>{s0:.6g}</td></tr>"
                       for n, v, s, s0 in zip(result.names, result.values, result.std, result.start))
        warnings = "".join(f"<li>{escape(w)}</li>" for w in result.warnings)
        return (f"<p><b>Model fit</b> of {escape(self.model_source)} to {escape(self.data_source)}</p>"
                f"<table><tr><th>parameter</th><th>value</th><th>std</th><th>unit</th><th>start</th></tr>{rows}</table>"
                f"<p>rms error of {escape(result.fit_on)}: estimation {result.estimation_rms:.4g} (start "
                f"{result.start_estimation_rms:.4g}), validation {result.validation_rms:.4g} (start "
                f"{result.start_validation_rms:.4g}); noise level {result.noise_rms_validation:.4g}</p>"
                + (f"<ul>{warnings}</ul>" if warnings else ""))

    def __repr__(self) -> str:
        fitted = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.fitted.names, self.fitted.values))
        return f"ModelFit({fitted}, validation_rms={self.fitted.validation_rms:.4g})"


def _model_config(model, free, names: Mapping[str, str]) -> tuple[dict, dict, str, list[str]]:
    """The model config as a dict, its line map, its name in messages and its config files."""
    from nlsid.models.key_paths import deep_copy

    if isinstance(model, (str, os.PathLike)):
        from nlsid.io.config import load_yaml

        data, lines = load_yaml(model)
        source, configs = str(model), [str(model)]
    elif isinstance(model, Mapping):
        data, lines, source, configs = deep_copy(dict(model)), {}, "model", []
    elif isinstance(model, Model):
        data, lines = model.to_dict(), {}
        source, configs = model.path or "model", [model.path] if model.path else []
    else:
        raise InputError(names.get("model", "model"), "expected a Model (nlsid.Model), a model config's path or "
                                                      f"its dict, got {type(model).__name__}")
    if not isinstance(data, dict):
        raise InputError(source, "expected a mapping with a model: key (docs/configs.md)")
    if free is not None:
        if not isinstance(free, Mapping):
            raise InputError(names.get("free", "free"), "expected key path -> {start, lower, upper} (a dict), got "
                                                        f"{type(free).__name__}")
        data = {**data, "free": {str(key): dict(value or {}) if isinstance(value, Mapping) else value
                                 for key, value in free.items()}}
    return data, lines, source, configs


def fit_model(model, rec: Recording | str | os.PathLike, free: Mapping[str, Mapping] | None = None,
              validate_on=(), validation: Sequence[str] | None = None, estimation_range=None,
              validation_range=None, allow_overlap: bool = False, fit_on: str = "y", jacobian: str = "differences",
              start_estimate: bool = False, workers: int | None = None, mapping: Mapping[str, str] | None = None, *,
              names: Mapping[str, str] | None = None) -> ModelFit:
    """The free parameters of a model config fitted to recorded runs by simulation error.

    theta_hat = argmin sum over estimation runs of (s_sim(theta) - s)^2 over their steady state, for
    the fitted signal s (``y``, or ``u`` in closed loop), by trust-region least squares with bounds;
    standard deviations by the sandwich estimator; validation runs are never fitted
    (``docs/commands.md``, "Free parameters of a model").

    Parameters
    ----------
    model : Model, path or dict
        The model (:class:`nlsid.Model`), or its config (``docs/configs.md``): the YAML file or the
        loaded dict.
    rec : Recording or path
        The recording fitted (runs with a measured y).
    free : dict, optional
        Key path -> ``{start, lower, upper}`` (each optional), e.g.
        ``{"model.nonlinearities[0].fc": {"lower": 0}}``; replaces the config's ``free:`` section.
    validate_on : Recording, path, or a list of them
        Further recordings whose runs are validation only (ids ``PATH:ID``); ``rec``'s runs are then
        all estimation runs.
    validation : list of str, optional
        Run ids of ``rec`` held out (default: the highest realization of each level, else the last run).
    estimation_range, validation_range : "a:b" or (a, b), optional
        Sample ranges of every (arbitrary) run to fit and to validate on.
    allow_overlap : bool
        Accept a ``validate_on`` recording that is ``rec`` (its validation then measures fitted samples).
    fit_on : {"y", "u"}
        The signal whose simulation error is minimised.
    jacobian : {"differences", "sensitivities"}
        Forward differences, or forward sensitivities where the model is smooth in its parameters.
    start_estimate : bool
        Start free force parameters without a ``start`` at a regression of the residual force.
    workers : int, optional
        Parallel simulations (threads).
    mapping : dict, optional
        Signals of a foreign MCAP log.
    names : dict, optional
        Argument -> how the caller calls it in messages (the command line passes its flags).

    Returns
    -------
    ModelFit

    Raises
    ------
    nlsid.InputError
        A bad argument (named), config, key path, bound or run, or a model that refuses its start.

    Examples
    --------
    The Coulomb friction level of a stage, from a start of 0.1 to the 0.3 that made the data,
    within five standard deviations; the error on the validation run falls to the noise
    (sigma = 1e-6):

    >>> import numpy as np
    >>> import nlsid
    >>> exc = nlsid.design({"fs": 200.0, "seed": 1, "multisine": {"period": 200, "band": [1.0, 40.0],
    ...                     "realizations": 4, "periods": 2, "transient_periods": 3, "rms_levels": [1.0]}})
    >>> stage = {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0,
    ...          "nonlinearities": [{"type": "coulomb", "fc": 0.3}]}
    >>> rec = nlsid.Model.from_dict({"model": stage, "disturbances": {"y_noise": 1e-6, "seed": 3}}).simulate(exc)
    >>> start = nlsid.Model.from_dict({"model": stage}).with_parameters({"model.nonlinearities[0].fc": 0.1})
    >>> fit = nlsid.fit_model(start, rec, free={"model.nonlinearities[0].fc": {"lower": 0.0}})
    >>> bool(abs(fit.values[0] - 0.3) < 5 * fit.std[0]), bool(abs(fit.validation_rms / 1e-6 - 1) < 0.2)
    (True, True)
    >>> fit.summary()["start_validation_rms"] > 100 * fit.validation_rms
    True
    >>> try:
    ...     nlsid.fit_model(start, rec, free={"model.friction": {}})
    ... except nlsid.InputError as error:
    ...     print(error)
    model: free.model.friction: no number at this key path of the config; give a start value
    """
    from nlsid.fit.extension import JACOBIANS, fit_config
    from nlsid.fit.run_split import split_runs
    from nlsid.io.units import common_units

    names = dict(names or {})
    name = lambda argument: names.get(argument, argument)  # noqa: E731
    if fit_on not in ("y", "u"):
        raise InputError(name("fit_on"), f"expected y or u, got {fit_on!r}")
    if jacobian not in JACOBIANS:
        raise InputError(name("jacobian"), f"expected one of {', '.join(JACOBIANS)}, got {jacobian!r}")
    if workers is not None and not (whole(workers) and workers >= 1):
        raise InputError(name("workers"), f"expected a whole number >= 1 or None, got {workers!r}")
    if isinstance(validation, str):
        validation = [validation]
    data = held_out(rec, validate_on, estimation_range, validation_range, allow_overlap, mapping, name, names,
                    several=declares_several(model))
    config, lines, source, configs = _model_config(model, free, names)
    held = list(validation) if validation else None

    def fit(written: dict) -> ExtensionFit:
        return fit_config(written, data.runs, held, workers, start_estimate, validate_on=data.extra_runs,
                          estimation_range=data.estimation, validation_range=data.validation, fit_on=fit_on,
                          where=data.where, jacobian=jacobian, source=source, lines=lines)

    units = common_units(run.units for run in [*data.runs, *data.extra_runs])
    largest = candidates_of(config, source, lines)
    if largest is None:
        return ModelFit(fit(config), source, data.where, configs, data.inputs, bool(allow_overlap), units=units)
    # computation_delay: auto, a discrete nuisance: one fit per candidate (nlsid.fit.computation_delay)
    estimation, _ = split_runs(data.runs, held, data.extra_runs, data.estimation, data.validation, data.where)
    fitted, choice = choose_delay(config, largest, fit, estimation, fit_on, "free parameters", source)
    return ModelFit(fitted, source, data.where, configs, data.inputs, bool(allow_overlap), choice, units)
