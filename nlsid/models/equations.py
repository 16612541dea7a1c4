"""A grey-box model written as equations: states, parameters, derivatives or updates, an output.

Continuous time (``derivatives``), with x the states, p the parameters and w the inputs the
expressions read (the plant input u, the reference r, measured channels), each held over its
sample (zero-order hold, as a DAC holds it):

    dx/dt = f(x, p, w[k]),  t in [t_k, t_k + Ts),    y[k] = g(x(t_k), p, w[k]) + output_offset.

Each sample is integrated by M sub-steps (``simulation.substeps``, default
:data:`DEFAULT_SUBSTEPS`) of the classical fourth-order Runge-Kutta method, h = Ts / M (e.g.
Hairer, Norsett and Wanner 1993, Solving ODEs I, Sec. II.1):

    k1 = f(x), k2 = f(B(x + h/2 k1)), k3 = f(B(x + h/2 k2)), k4 = f(B(x + h k3)),
    x <- B(x + h/6 (k1 + 2 k2 + 2 k3 + k4)),

B the projection onto the ``bounds`` (each state clipped into [lower, upper]). Clipping the
stages as well as the step keeps every evaluation of f inside the bounds, so that a law such as
Torricelli's sqrt(x) is never evaluated below a bound at 0 (a level cannot go below its tank's
floor). The comparisons and signs of f, where its value jumps, hold their value over a step and
their switches are located (:func:`kernel_source`), so the error is of order h^4 where f is
smooth between the switches; it is lower across a corner of ``min``, ``max``, ``abs`` or ``clip``
(f continuous, its slope not), and of order h where the solution meets a bound.
:mod:`nlsid.diagnose.accuracy` measures it by the change of the output from M to 2M and 4M
sub-steps, as for the other models with sub-steps.

Discrete time (``updates``): x[k+1] = B(f(x[k], p, w[k])), y[k] = g(x[k], p, w[k]) + output_offset.

The name ``u`` is the plant input as a plant gets it, f_in(u[k - d] + input_offset + sum gain *
channel + process noise): the command delayed by ``delay`` (d whole samples, zero before the
record) through the ``input_nonlinearity`` f_in (identity without one); ``r`` and the channels are
read as recorded. The recorded y is f_out(g) + output_offset, f_out the ``output_nonlinearity``.
The states start at their written initial values (no lead-in), but an arbitrary record with a
measured output, simulated as it was measured, starts from the states fitted to its first samples
(:mod:`nlsid.simulate.equations_state`; not where ``fit --model`` frees ``model.states.NAME``:
then the written values are the one start of every run, which the fit estimates).

Compilation: the checked expressions (:mod:`nlsid.models.expressions`) are written into the
Python source of one kernel per model (the loop above, f and g written out in it), which numba
compiles when the model first runs, once per source text in a process, and keeps in its disk
cache for the next (:func:`compile_kernel`); a fit changes only the numbers (parameters, initial
values, bounds), so its thousands of simulations share one compilation. A value that is not finite (a
division by zero, the root or logarithm of a negative number, an overflow) stops the simulation
with an :class:`~nlsid.errors.InputError` naming the expression's key and the sample.
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.models.blocks import encode
from nlsid.models.expressions import comparison_source, comparisons, parse, source

DEFAULT_SUBSTEPS = 10  # RK4 sub-steps per sample of a continuous equations model (nlsid.simulate.engine's default)
MAX_SWITCHES = 8       # switches located per sub-step at most (kernel_source)
LOCATE_HALVINGS = 44   # bisection halvings locating a switch: to 2^-44 of the remaining sub-step
KERNEL_FORMAT = 3      # in the cached source's first line: a new format (or new compile options) gets new files
RESERVED = ("u", "r")

_KERNELS: dict[str, object] = {}  # kernel source -> compiled kernel
_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class Equations:
    """An equations model ready to simulate (:func:`build`).

    ``inputs`` are the names the expressions read from the run, in the order of the kernel's input
    columns: ``u`` first, then ``r`` and the channels the expressions name. ``keys`` name each
    expression in messages: the state equations' keys, then the output's.
    """

    @property
    def kernel(self):
        """The compiled kernel (:func:`compile_kernel`; compiled on first use, then shared)."""
        return compile_kernel(self.source)

    states: tuple[str, ...]
    x0: np.ndarray
    parameters: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    discrete: bool
    inputs: tuple[str, ...]
    keys: tuple[str, ...]
    source: str   # the kernel's Python source (kernel_source), compiled when the model first runs
    offsets: object
    delay: float = 0.0
    input_block: tuple = field(default_factory=lambda: encode(None))  # (kind, parameters): nlsid.models.blocks
    output_block: tuple = field(default_factory=lambda: encode(None))
    columns: dict = field(default_factory=dict)  # input name -> (key, column) of its first use


def _variables(states, parameters, inputs, state_array: str = "x") -> dict[str, str]:
    """Each name of the model -> the Python expression that reads it inside the kernel (the
    states from ``state_array``)."""
    out = {name: f"{state_array}[{i}]" for i, name in enumerate(states)}
    out.update({name: f"p[{i}]" for i, name in enumerate(parameters)})
    out.update({name: f"w[k, {i}]" for i, name in enumerate(inputs)})
    return out


def _block(lines: list[str], indent: int) -> list[str]:
    return [" " * indent + line for line in lines]


def _functions(equations, output, names, switches) -> list[str]:
    """The kernel's helpers: ``rates`` (the state equations at x into d, with the comparisons of
    ``switches`` read from their frozen modes md; the index of the first value that is not finite,
    else -1), ``modes`` (each switch's value now), ``changed``, ``project`` and the RK4 ``step``."""
    variables = _variables(*names)
    frozen = {id(node): f"md[{i}]" for i, node in enumerate(switches)}
    lines = ["def rates(x, p, w, k, md, d):"]
    lines += [f"    d[{i}] = {source(e, variables, frozen)}" for i, e in enumerate(equations)]
    lines += ["    for i in range(d.size):", "        if not math.isfinite(d[i]):", "            return i",
              "    return -1", "", "def modes(x, p, w, k, out):"]
    lines += [f"    out[{i}] = {comparison_source(node, variables)}" for i, node in enumerate(switches)] or ["    pass"]
    lines += ["", "def changed(a, b):", "    for i in range(a.size):", "        if a[i] != b[i]:",
              "            return True", "    return False", "",
              "def project(x, lower, upper):", "    for i in range(x.size):", "        if x[i] < lower[i]:",
              "            x[i] = lower[i]", "        elif x[i] > upper[i]:", "            x[i] = upper[i]", "",
              "def step(x, tau, p, w, k, md, lower, upper, d1, d2, d3, d4, s, out):"]
    for d, source_array, weight, previous in (("d1", "x", None, None), ("d2", "s", "0.5", "d1"),
                                               ("d3", "s", "0.5", "d2"), ("d4", "s", "1.0", "d3")):
        if previous is not None:
            lines += ["    for i in range(x.size):", f"        s[i] = x[i] + {weight} * tau * {previous}[i]",
                      "    project(s, lower, upper)"]
        lines += [f"    i = rates({source_array}, p, w, k, md, {d})", "    if i >= 0:", "        return i"]
    lines += ["    for i in range(x.size):",
              "        out[i] = x[i] + tau / 6.0 * (d1[i] + 2.0 * d2[i] + 2.0 * d3[i] + d4[i])",
              "    project(out, lower, upper)", "    return -1", ""]
    return lines


def kernel_source(equations: list, output, names: tuple, discrete: bool) -> str:
    """The Python source of a model's kernel ``run(x0, p, lower, upper, w, m, h, y, fail)``: the
    loop of the module docstring over the samples k of w (rows: samples, columns: inputs), with
    the expressions (:class:`nlsid.models.expressions.Expression`, the states' then the output)
    over ``names`` = (states, parameters, inputs). It writes y[k]; on a value that is not finite
    it writes (sample, expression index) into ``fail`` (the output's index is the number of
    states) and returns.

    A continuous model's comparisons and signs are switches
    (:func:`nlsid.models.expressions.comparisons`): their values (modes) are held over each RK4
    step, so that the step integrates a smooth field; where a mode differs at the step's end, the
    step is shortened by bisection to just past the first switch (LOCATE_HALVINGS halvings) and
    the rest of the sub-step continues from there with the new modes, at most MAX_SWITCHES times
    per sub-step (then the rest runs with the modes at its start: a state sliding along a switch,
    e.g. where(x > 0, -1, 1) at x = 0, would otherwise switch without end)."""
    switches = [] if discrete else [node for e in equations for node in comparisons(e)]
    lines = _functions(equations, output, names, switches)
    lines += ["def run(x0, p, lower, upper, w, m, h, y, fail):",
              f"    ns = {len(names[0])}", "    x = x0.copy()", "    project(x, lower, upper)",
              "    d1 = np.empty(ns)", "    d2 = np.empty(ns)", "    d3 = np.empty(ns)", "    d4 = np.empty(ns)",
              "    s = np.empty(ns)", "    xn = np.empty(ns)",
              f"    md = np.zeros({len(switches)})", f"    m2 = np.zeros({len(switches)})",
              "    for k in range(w.shape[0]):",
              f"        v = {source(output, _variables(*names))}",
              "        if not math.isfinite(v):", "            fail[0] = k", "            fail[1] = ns",
              "            return",
              "        y[k] = v"]
    failed = ["if i >= 0:", "    fail[0] = k", "    fail[1] = i", "    return"]
    if discrete:  # comparisons evaluated as they stand: no steps between the samples
        lines += _block(["i = rates(x, p, w, k, md, xn)"] + failed + ["for i in range(ns):", "    x[i] = xn[i]",
                                                                       "project(x, lower, upper)"], 8)
        return "\n".join(lines) + "\n"
    body = ["remaining = h", "switched = 0", "while remaining > 0.0:",
             "    modes(x, p, w, k, md)",
             "    i = step(x, remaining, p, w, k, md, lower, upper, d1, d2, d3, d4, s, xn)"]
    body += _block(failed, 4)
    body += ["    modes(xn, p, w, k, m2)",
             f"    if switched < {MAX_SWITCHES} and changed(md, m2):",
             "        lo = 0.0", "        hi = remaining",
             f"        for it in range({LOCATE_HALVINGS}):",
             "            mid = 0.5 * (lo + hi)",
             "            i = step(x, mid, p, w, k, md, lower, upper, d1, d2, d3, d4, s, xn)"]
    body += _block(failed, 12)
    body += ["            modes(xn, p, w, k, m2)", "            if changed(md, m2):", "                hi = mid",
             "            else:", "                lo = mid",
             "        i = step(x, hi, p, w, k, md, lower, upper, d1, d2, d3, d4, s, xn)"]
    body += _block(failed, 8)
    body += ["        switched += 1", "        remaining -= hi", "    else:", "        remaining = 0.0",
             "    for i in range(ns):", "        x[i] = xn[i]"]
    lines += ["        for j in range(m):"] + _block(body, 12)
    return "\n".join(lines) + "\n"


def _source_module(text: str):
    """The kernel source as a module: a file in the numba cache folder of :mod:`nlsid.simulate.jit`
    named by the text's hash (so that numba's disk cache, which keys a function by its file, keeps
    its compiled code across processes), else, where nothing can be cached, a namespace of its own.
    Returns (namespace, cacheable)."""
    from nlsid.simulate.jit import CACHING

    header = f"# nlsid equations kernel, format {KERNEL_FORMAT}\nimport math\n\nimport numpy as np\n\n\n"
    if not CACHING:
        namespace: dict = {}
        exec(compile(header + text, "<nlsid equations>", "exec"), namespace)  # noqa: S102 (from a checked tree)
        return namespace, False
    content = header + text
    digest = hashlib.sha256(content.encode()).hexdigest()[:32]
    folder = Path(os.environ["NUMBA_CACHE_DIR"]) / "nlsid_equations"
    path = folder / f"kernel_{digest}.py"
    try:
        if not path.is_file() or path.read_text() != content:
            folder.mkdir(parents=True, exist_ok=True)
            part = folder / f".{path.name}.{os.getpid()}.{threading.get_ident()}"
            part.write_text(content)
            os.replace(part, path)  # whole or not at all, whoever writes it at the same time
    except OSError:
        namespace = {}
        exec(compile(content, "<nlsid equations>", "exec"), namespace)  # noqa: S102 (from a checked tree)
        return namespace, False
    name = f"nlsid_equations_kernel_{digest}"
    module = sys.modules.get(name)
    if module is None:  # registered by name: numba's cached code finds its globals through it
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return module.__dict__, True


def compile_kernel(text: str):
    """The numba kernel of a :func:`kernel_source` text, compiled once per text in a process
    (eagerly, for the one signature it is called with, so that threads share it) and kept in
    numba's disk cache across processes (:func:`_source_module`). IEEE arithmetic without
    exceptions (numba's ``error_model="numpy"``): x / 0 is an infinity, which the kernel reports,
    not a Python ZeroDivisionError."""
    with _LOCK:
        kernel = _KERNELS.get(text)
        if kernel is not None:
            return kernel
        from nlsid.simulate.jit import njit

        namespace, cacheable = _source_module(text)
        options = dict(error_model="numpy", cache=cacheable)
        for name in ("rates", "modes", "changed", "project", "step"):
            namespace[name] = njit(**options)(namespace[name])
        a1, a2 = "float64[::1]", "float64[:, ::1]"
        signature = f"void({a1}, {a1}, {a1}, {a1}, {a2}, int64, float64, {a1}, int64[::1])"
        kernel = njit(signature, nogil=True, **options)(namespace["run"])  # threads run runs in parallel
        _KERNELS[text] = kernel
        return kernel


def build(config, offsets, where: str = "model") -> Equations:
    """The :class:`Equations` of a validated :class:`nlsid.io.model_config.EquationsConfig`
    (its expressions checked again with their keys and written into the kernel's source, which is
    compiled when the model first runs); ``offsets`` its :class:`nlsid.models.from_config.Offsets`."""
    states, parameters = list(config.states), list(config.parameters)
    section = config.section
    texts = [(f"{where}.{section}.{name}", config.equations[name]) for name in states]
    texts.append((f"{where}.output", config.output))
    parsed = [parse(text, key) for key, text in texts]
    known = set(states) | set(parameters)
    inputs, columns = ["u"], {}
    for expression in parsed:
        for name, column in expression.names.items():
            if name not in known and name not in inputs:
                inputs.append(name)
            if name not in known and name not in columns:
                columns[name] = (expression.where, column)
    inputs = ["u"] + sorted(inputs[1:])
    text = kernel_source(parsed[:-1], parsed[-1], (states, parameters, inputs), config.updates is not None)
    lower = np.array([_bound(config.bounds.get(name), 0, -math.inf) for name in states])
    upper = np.array([_bound(config.bounds.get(name), 1, math.inf) for name in states])
    return Equations(tuple(states), np.array([config.states[n] for n in states], dtype=np.float64),
                     np.array([config.parameters[n] for n in parameters], dtype=np.float64), lower, upper,
                     config.updates is not None, tuple(inputs), tuple(key for key, _ in texts),
                     text, offsets, config.delay, encode(config.input_nonlinearity),
                     encode(config.output_nonlinearity), columns)


def _bound(pair, index: int, default: float) -> float:
    return default if pair is None or pair[index] is None else float(pair[index])


def input_matrix(model: Equations, run, plant_input: np.ndarray) -> np.ndarray:
    """(n, inputs) float64: the plant input, then r and the channels the expressions read; a
    name that is none of the model's nor the run's is an error listing them all."""
    out = np.empty((run.n_samples, len(model.inputs)))
    out[:, 0] = plant_input
    unknown = [name for name in model.inputs[1:] if not (name == "r" and run.r is not None or name in run.channels)]
    if unknown:
        key, column = model.columns[unknown[0]]
        have = ", ".join(sorted(run.channels)) or "none"
        listed = ", ".join(repr(name) for name in unknown)
        r_note = " (run has no r)" if "r" in unknown else ""
        raise InputError(key, f"column {column}: unknown name{'s' if len(unknown) > 1 else ''} {listed}{r_note}: "
                              f"expected a state, a parameter, u, r or a channel of run {run.run_id} "
                              f"(its channels: {have})")
    for i, name in enumerate(model.inputs[1:], start=1):
        out[:, i] = run.r if name == "r" else run.channels[name]
    return out


def substeps_of(model: Equations, requested: int | None) -> int:
    """Sub-steps per sample: 1 for updates (a discrete model runs one step per sample), else the
    requested ones or :data:`DEFAULT_SUBSTEPS`."""
    if model.discrete:
        if requested not in (None, 1):
            raise InputError("simulation.substeps", "a discrete-time model runs one step per sample; remove substeps")
        return 1
    return DEFAULT_SUBSTEPS if requested is None else int(requested)


def response(model: Equations, run, plant_input: np.ndarray, substeps: int | None) -> np.ndarray:
    """The value of the output expression on ``run`` (before an output block, offset and noise)
    driven by ``plant_input``, the input u of the expressions (:func:`nlsid.simulate.engine.simulate_equations`:
    the delayed command with offsets, channels and process noise, through the input block)."""
    w = input_matrix(model, run, np.asarray(plant_input, dtype=np.float64))
    m = substeps_of(model, substeps)
    y = np.empty(run.n_samples)
    fail = np.full(2, -1, dtype=np.int64)
    model.kernel(np.ascontiguousarray(model.x0), np.ascontiguousarray(model.parameters),
                 np.ascontiguousarray(model.lower), np.ascontiguousarray(model.upper), w, m, 1.0 / (run.fs * m),
                 y, fail)
    if fail[0] >= 0:
        sample, index = int(fail[0]), int(fail[1])
        what = "output" if index == len(model.states) else "value"
        raise InputError(model.keys[index], f"run {run.run_id}: the {what} is not finite at sample {sample} "
                                            f"(t = {sample / run.fs:g} s): a division by zero, the root or "
                                            "logarithm of a negative number, or an overflow; bound the states "
                                            "(bounds:) or guard the expression with where(...)")
    return y
