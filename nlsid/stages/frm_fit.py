"""The ``fit`` stage on a level of several inputs or outputs: a MIMO state-space model fitted to
the frequency response matrix (FRM) that ``nlsid bla`` writes to ``bla.h5`` as ``frm_levels``.

``nlsid fit bla.h5 --order auto|N`` takes this path when the level it fits (``--level``) is an FRM
level; the levels are numbered as :func:`nlsid.fit.bla_source.frf_from_bla` numbers them, multisine
levels first, then levels of arbitrary runs, then the FRM levels of multisines (``frm_levels``)
and of arbitrary runs (``frm_lpm_levels``, the LPM for several inputs: :func:`lpm_data`). The numbers are those of
:mod:`nlsid.fit.mimo_fit` (subspace start, sample maximum likelihood refinement, order choice);
this module chooses the weights from the file, names the model's inputs and outputs after the
FRM's, and writes the model config (``type: mimo_state_space``, ``docs/configs.md``) and its fit
report (``docs/formats.md``).

Weights, by what the level holds (``docs/mimo.md``, "The fit"): the total covariance of vec(G)
(noise and stochastic nonlinear distortions, over M realizations: n = M - 1 complex degrees of
freedom) where it is positive definite at every line and n >= m + 2 (m = n_y n_u: FULL_MARGIN);
else the noise covariance (n = M E (P - 1)) where the total is unknown (M = 1); with fewer degrees
of freedom or a singular full covariance, each entry's own variance (the diagonal, correlations
left out, said in a warning); unit weights where neither is known (M = 1 and P = 1), without a
cost check.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from nlsid.errors import InputError
from nlsid.fit.mimo_fit import FrmData, MimoFit, fit_frm, whitening

#: the keys of the fit report that ``nlsid fit BLA --json`` prints for an FRM level (besides the paths)
JSON_KEYS = ("kind", "domain", "hold", "order", "inputs", "outputs", "poles", "pole_std", "parameters", "cost",
             "expected_cost", "cost_std", "cost_bound", "weights", "covariance_dof", "lines", "stable",
             "order_reason", "order_scan", "warnings", "level")
#: orders ``order="auto"`` scans at most by default
MAX_ORDER = 10
#: degrees of freedom a full covariance needs beyond the m entries: n - m >= 2 gives the cost a
#: finite spread (the Hotelling T^2's F(2m, 2(n - m + 1)) has a variance for n - m + 1 > 2)
FULL_MARGIN = 2


def frm_level(content: dict, level: int | None, source: str, option: str = "--level") -> tuple[int, dict] | None:
    """The FRM level of a ``bla.h5`` read by :func:`nlsid.io.bla_file.read_bla` that ``level``
    names, as ``(index, level dict)``: the ``frm_levels`` numbered after the levels of one input
    and one output, then the ``frm_lpm_levels``. None where the file holds no FRM level or ``level``
    names a level of one input and one output (the transfer-function fit's)."""
    frm = [*(content.get("frm_levels") or []), *(content.get("frm_lpm_levels") or [])]
    if not frm:
        return None
    siso = len(content["levels"]) + len(content["lpm_levels"])
    total = siso + len(frm)
    if level is None:
        if total > 1:
            raise InputError(source, f"{total} levels in the file; choose one with {option} 0..{total - 1} "
                                     "(multisine levels first, then levels of arbitrary runs, then levels of several "
                                     "inputs or outputs: multisine, then arbitrary)")
        level = 0
    if not 0 <= level < total:
        raise InputError(option, f"expected 0..{total - 1} for {source}, got {level}")
    return None if level < siso else (level, frm[level - siso])


def levels_to_fit(content: dict, level: int | None, source: str, option: str = "--level") -> list[int] | None:
    """The FRM level indices a fit of ``level`` takes: every FRM level where the file holds FRM
    levels only, several of them, and no ``level`` is given (one model each); else the one
    :func:`frm_level` names; None for a level of one input and one output (or a file without FRM
    levels)."""
    frm = [*(content.get("frm_levels") or []), *(content.get("frm_lpm_levels") or [])]
    if level is None and frm and not content["levels"] and not content["lpm_levels"] and len(frm) > 1:
        return list(range(len(frm)))
    found = frm_level(content, level, source, option)
    return None if found is None else [found[0]]


def level_paths(output: str | os.PathLike, indices: list[int]) -> list[Path]:
    """Where the models of ``indices`` go: ``output`` for one level, else ``<stem>.level_NN<suffix>``
    beside it for each (``model.yaml`` -> ``model.level_00.yaml``, ...)."""
    path = Path(output)
    if len(indices) == 1:
        return [path]
    return [path.with_name(f"{path.stem}.level_{index:02d}{path.suffix}") for index in indices]


def _definite(cov: np.ndarray) -> bool:
    """Positive definite at every line, as the fit's whitening asks."""
    try:
        whitening(cov)
    except InputError:
        return False
    return True


def frm_data(chosen: dict, where: str) -> tuple[FrmData, list[str]]:
    """The FRM of a level dict with its weights (module docstring) and the warnings they bring."""
    if "cov_G" in chosen:
        return lpm_data(chosen, where)
    attrs = chosen["attrs"]
    G = np.asarray(chosen["G"], dtype=complex)
    f = np.asarray(chosen["frequency"], dtype=float)
    F, n_y, n_u = G.shape
    m = n_y * n_u
    M, E, P = int(attrs["n_realizations"]), int(attrs["n_experiments"]), int(attrs["n_periods"])
    sources = (("cov_total", M - 1, f"the total covariance (noise and nonlinear distortions) over M = {M} "
                                    "realizations"),
               ("cov_noise", M * E * (P - 1), f"the noise covariance over P = {P} periods (nonlinear distortions "
                                              "not included)"))
    warnings = []
    for name, dof, words in sources:
        cov = chosen.get(name)
        if cov is None or not np.all(np.isfinite(cov)):
            continue
        cov = np.asarray(cov, dtype=complex)
        if name == "cov_noise":
            warnings.append("weights: the noise covariance only (M = 1 realization): nonlinear distortions are not "
                            "in the weights and raise the cost above its expected value")
        if dof - m >= FULL_MARGIN and _definite(cov):
            return FrmData(f, G, cov, float(attrs["fs"]), float(dof), f"{words}, full ({m} x {m} per line)"), warnings
        variance = np.real(np.einsum("fii->fi", cov))
        if np.all(variance > 0):
            warnings.append(f"weights: {name} has {dof} degrees of freedom for {m} entries (a full covariance needs "
                            f"{m + FULL_MARGIN} and must be positive definite): each entry weighted by its own "
                            "variance, correlations left out")
            diagonal = np.einsum("fi,ij->fij", variance, np.eye(m)).astype(complex)
            return (FrmData(f, G, diagonal, float(attrs["fs"]), float(dof), f"{words}, its diagonal", diagonal=True),
                    warnings)
    warnings.append(f"unit weights: {where} holds no covariance (M = {M} realization(s), P = {P} period(s)); the "
                    "cost has no expected value and the order by cost + parameters depends on the scale of G: "
                    "give --order")
    identity = np.broadcast_to(np.eye(m, dtype=complex), (F, m, m)).copy()
    return FrmData(f, G, identity, float(attrs["fs"]), 0.0, "unit weights (no covariance in the file)"), warnings


def lpm_data(chosen: dict, where: str) -> tuple[FrmData, list[str]]:
    """The FRM of a level of arbitrary runs (``frm_lpm_levels``, the LPM for several inputs) with
    its weights: ``cov_G`` (noise and stochastic nonlinear distortion, q = ``dof`` complex degrees
    of freedom) where q >= n_y + FULL_MARGIN and it is positive definite, else its diagonal
    ``var_G``. ``cov_G = [A^-1]_00 kron C`` with the outputs' disturbance covariance C estimated
    with q degrees of freedom (``docs/mimo.md``, "The LPM for several inputs"): each line's cost
    term is n_u Hotelling T^2 of dimension n_y sharing that C (``FrmData.block`` = n_y). The
    LPM's windows of 2n+1 lines overlap up to 2n lines apart (``FrmData.shared_lags``): the
    cost's expected value and spread count the correlation of those lines' errors
    (:func:`nlsid.fit.mimo_fit.line_correlation`)."""
    attrs = chosen["attrs"]
    G = np.asarray(chosen["G"], dtype=complex)
    f = np.asarray(chosen["frequency"], dtype=float)
    n_y = G.shape[1]
    m = n_y * G.shape[2]
    dof = float(attrs["dof"])
    lags = 2 * int(attrs.get("half_width", 0))
    cov = np.asarray(chosen["cov_G"], dtype=complex)
    words = (f"the Local Polynomial Method's covariance (noise and nonlinear distortions, q = {dof:g}; the "
             f"correlation of lines up to {lags} apart, whose windows overlap, counted in the cost check)")
    warnings = []
    if np.all(np.isfinite(cov)) and dof - n_y >= FULL_MARGIN and _definite(cov):
        return FrmData(f, G, cov, float(attrs["fs"]), dof, f"{words}, full ({m} x {m} per line)", block=n_y,
                       shared_lags=lags), warnings
    variance = np.swapaxes(np.asarray(chosen["var_G"], dtype=float), 1, 2).reshape(f.size, m)
    if not (np.all(np.isfinite(variance)) and np.all(variance > 0)):
        raise InputError(f"{where}/var_G", "not finite and > 0 at every line: no weights to fit with")
    warnings.append(f"weights: cov_G has {dof:g} degrees of freedom for {n_y} outputs (a full covariance needs "
                    f"{n_y + FULL_MARGIN} and must be positive definite): each entry weighted by its own variance, "
                    "correlations left out; the cost's spread then treats the entries as independent and is "
                    "approximate")
    diagonal = np.einsum("fi,ij->fij", variance, np.eye(m)).astype(complex)
    return (FrmData(f, G, diagonal, float(attrs["fs"]), dof, f"{words}, its diagonal", diagonal=True,
                    shared_lags=lags), warnings)


def parse_order(order, option: str = "order") -> int | None:
    """``"auto"`` -> None; a whole number of states >= 1 (or its text) -> int; else an InputError."""
    if isinstance(order, str) and order.strip() == "auto":
        return None
    text = order.strip() if isinstance(order, str) else order
    if isinstance(text, str) and text.isdigit():
        text = int(text)
    if isinstance(text, (int, np.integer)) and not isinstance(text, bool) and text >= 1:
        return int(text)
    raise InputError(option, f"a level of several inputs or outputs is fitted by a state-space model: expected its "
                             f"number of states N (e.g. 4) or auto, got {order!r}")


@dataclass
class MimoStateSpaceFit:
    """A MIMO state-space model fitted to one FRM level of a ``bla.h5`` file.

    Attributes
    ----------
    fitted : nlsid.fit.mimo_fit.MimoFit
        The fit (``.fit``: A, B, C, D, cost and its statistics, poles and their std), the order scan
        and its reason.
    source : str
        The ``bla.h5`` path.
    inputs, outputs : list of str
        The FRM's inputs (B's columns) and outputs (C's rows), as the recording names them.
    level : dict
        ``index`` (as ``--level`` takes it) and ``level`` (the runs' level attribute, None where none).
    files : list of str
        Files the fit comes from (its provenance).
    warnings : list of str
        What the weights and the fit doubt.
    covariance_dof : float or None
        Complex degrees of freedom of the weights' covariance (None: unit weights).
    lines : int
        F, the lines fitted.
    stored : dict or None
        The level as :func:`nlsid.io.bla_file.read_bla` returns it (what :meth:`png` draws).
    """

    fitted: MimoFit
    source: str
    inputs: list[str]
    outputs: list[str]
    level: dict
    files: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    covariance_dof: float | None = None
    lines: int = 0
    stored: dict | None = None

    @property
    def order(self) -> int:
        """n, the number of states."""
        return self.fitted.fit.order

    def config(self) -> dict:
        """The model config (``type: mimo_state_space``, ``docs/configs.md``): what ``nlsid simulate`` runs."""
        fit = self.fitted.fit
        model = {"type": "mimo_state_space", "A": fit.A.tolist(), "B": fit.B.tolist(), "C": fit.C.tolist(),
                 "D": fit.D.tolist(), "domain": "continuous" if self.fitted.domain == "s" else "discrete"}
        if self.fitted.domain == "z":
            model["fs"] = self.fitted.fs
        model["inputs"], model["outputs"] = list(self.inputs), list(self.outputs)
        return {"model": model}

    def report(self) -> dict:
        """Every number of the fit report ``<model>.fit.json`` (``docs/formats.md``), without provenance."""
        fitted, fit = self.fitted, self.fitted.fit
        return {"kind": "mimo_state_space", "domain": fitted.domain, "hold": fitted.hold, "order": fit.order,
                "inputs": list(self.inputs), "outputs": list(self.outputs),
                "A": fit.A.tolist(), "B": fit.B.tolist(), "C": fit.C.tolist(), "D": fit.D.tolist(),
                "poles": [[float(p.real), float(p.imag)] for p in fit.poles],
                "pole_std": [[float(p.real), float(p.imag)] for p in fit.pole_std],
                "parameters": fit.parameters, "cost": fit.cost, "expected_cost": fit.expected_cost,
                "cost_std": fit.cost_std, "cost_bound": fit.cost_bound, "weights": fitted.weights,
                "covariance_dof": self.covariance_dof, "lines": self.lines, "stable": fit.stable,
                "order_reason": fitted.reason, "order_scan": [r.row() for r in fitted.scan],
                "warnings": list(self.warnings), "level": dict(self.level)}

    def summary(self) -> dict:
        """The ``nlsid fit BLA --json`` summary without paths (:data:`JSON_KEYS`)."""
        report = self.report()
        return {key: report[key] for key in JSON_KEYS}

    def header(self, report_name: str) -> list[str]:
        """The comment lines of the model YAML (``report_name``: the report file beside it)."""
        fit = self.fitted.fit
        domain = "continuous (through the zero-order hold)" if self.fitted.domain == "s" else "discrete"
        return [f"nlsid fit {self.source}, level {self.level['index']}: {self.order}-state {domain} state space, "
                f"{len(self.outputs)} outputs x {len(self.inputs)} inputs, {'stable' if fit.stable else 'UNSTABLE'}",
                f"cost {fit.cost:.6g}, {cost_words(self.fitted)} ({self.lines} lines)",
                f"weights: {self.fitted.weights}",
                f"order: {self.fitted.reason}",
                f"report: {report_name}"]

    def figure(self):
        """The figure of ``nlsid fit --plot`` (a matplotlib Figure): the level's n_y x n_u Bode plots
        with their bounds and standard deviations (:func:`nlsid.report.frm_plots.frm_figure`), the
        model's FRM over them and the residual |G_model - G| per entry."""
        from nlsid.report.frm_plots import frm_figure
        from nlsid.report.units import units_of
        from nlsid.report.vector import fit_labels

        if self.stored is None:
            raise InputError("plot", "the fit holds no level to draw (it was not made by fit_frm_level)")
        model = self.fitted.frequency_response(np.asarray(self.stored["frequency"], dtype=float))
        name = (f"{self.source}, level {self.level['index']}, {self.order}-state "
                f"{'continuous' if self.fitted.domain == 's' else 'discrete'} model")
        figure = frm_figure(self.stored, units_of(self.stored["attrs"].get("units")), name, model=model)
        fit_labels(figure)
        return figure

    def png(self) -> bytes:
        """The figure of :meth:`figure` as PNG bytes (what ``nlsid fit --plot`` writes)."""
        import io

        buffer = io.BytesIO()
        self.figure().savefig(buffer, format="png", dpi=110)  # the resolution of the single-input figures
        return buffer.getvalue()

    def write(self, path: str | os.PathLike, force: bool = False, provenance: dict | None = None,
              plot: str | os.PathLike | None = None) -> Path:
        """Write the model config ``path`` (YAML) and the fit report ``<name>.fit.json`` beside it, and
        with ``plot`` the figure of :meth:`png` (PNG), as ``nlsid fit`` does; existing files only
        with ``force``. Returns ``path``."""
        from nlsid.io.atomic import atomic_path, check_writable
        from nlsid.io.fit_file import report_path, write_fit
        from nlsid.io.provenance import provenance as make_provenance

        if plot:
            check_writable(str(plot), force)
            png = self.png()
            with atomic_path(plot, force) as tmp:
                tmp.write_bytes(png)
        record = provenance if provenance is not None else make_provenance(input_paths=self.files)
        write_fit(path, self.config(), self.header(report_path(path).name), self.report(), record, force=force)
        return Path(path)


def cost_words(fitted: MimoFit) -> str:
    """The cost's expected value, spread and bound in words; what has no finite value is said."""
    fit = fitted.fit
    if not math.isfinite(fit.expected_cost):
        return "no expected value and no cost check (no covariance, or too few degrees of freedom in it)"
    return f"expected {fit.expected_cost:.6g} +- {fit.cost_std:.3g}, bound {fit.cost_bound:.6g}"


def fit_frm_level(b: str | os.PathLike, order="auto", domain: str = "z", level: int | None = None,
                  max_order: int | None = None, *, names: Mapping[str, str] | None = None) -> MimoStateSpaceFit:
    """A MIMO state-space model fitted to an FRM level of a ``bla.h5`` file (module docstring).

    Parameters
    ----------
    b : path
        The ``bla.h5`` file.
    order : int, "N" or "auto"
        The number of states, or a scan of 1 .. ``max_order`` with the choice of
        :mod:`nlsid.fit.mimo_fit`.
    domain : {"s", "z"}
        ``s``: a continuous model seen through the zero-order hold at the FRM's fs; ``z``: discrete at fs.
    level : int, optional
        The level index; needed when the file holds several levels.
    max_order : int, optional
        Largest order of ``order="auto"`` (default :data:`MAX_ORDER`).
    names : dict, optional
        Argument -> how the caller calls it in messages (the command line passes its flags).

    Returns
    -------
    MimoStateSpaceFit

    Raises
    ------
    nlsid.InputError
        A bad argument (named), a level that is not an FRM level, or data the fit cannot use.
    """
    from nlsid.io.bla_file import read_bla

    names = dict(names or {})
    option = lambda argument: names.get(argument, argument)  # noqa: E731
    if domain not in ("s", "z"):
        raise InputError(option("domain"), f"expected s or z, got {domain!r}")
    states = parse_order(order, option("order"))
    if max_order is not None and not (isinstance(max_order, (int, np.integer)) and max_order >= 1):
        raise InputError(option("max_order"), f"expected a whole number >= 1 or None, got {max_order!r}")
    content = read_bla(b)
    found = frm_level(content, level, str(b), option("level"))
    if found is None:
        raise InputError(option("level"), f"level {0 if level is None else level} of {b} has one input and one "
                                          "output: fit it with a transfer function (--order NB/NA)")
    index, chosen = found
    group = "frm_lpm_levels" if "cov_G" in chosen else "frm_levels"
    where = f"{b}:/{group}/{chosen['name']}"
    data, warnings = frm_data(chosen, where)
    try:
        fitted = fit_frm(data, states, domain, hold=True, max_order=int(max_order or MAX_ORDER))
    except InputError as error:
        head = option("order") if error.where in ("order", "max_order") else where
        raise InputError(head, error.what) from None
    attrs = chosen["attrs"]
    value = attrs.get("level")
    level_value = None if value is None or not math.isfinite(float(value)) else float(value)
    return MimoStateSpaceFit(fitted, str(b), list(attrs["inputs"]), list(attrs["outputs"]),
                             {"index": index, "level": level_value}, [str(b)], warnings + fitted.warnings,
                             covariance_dof=data.dof if data.dof else None, lines=data.lines, stored=chosen)
