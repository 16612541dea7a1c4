"""The report page of a model YAML (``docs/configs.md``): what the model is, its linear dynamics, its nonlinearities.

Linear part: every LTI element the simulator builds from the config (:mod:`nlsid.models.from_config`)
is shown by its frequency response ``G(x) = C (xI - A)^{-1} B + D`` (:meth:`StateSpace.frequency_response`)
at ``x = j 2 pi f`` for continuous elements, with a dead time ``tau`` as ``e^{-j 2 pi f tau}``, and at
``x = e^{j 2 pi f / fs}`` for discrete ones, in Hz where the model states its sample rate ``fs``, else
over the normalised frequency ``nu = f/fs`` (their dead time, a number of samples, is not drawn). A
mechanical template contributes its linear plant (the nonlinear forces removed); a block structure
contributes the LTI blocks of each branch; a closed loop adds the controller and, when plant and
controller are continuous, the loop gain ``L = C P`` with its crossover frequency (``|L| = 1``) and
phase margin ``180 deg + angle L`` there.

Poles are summarised as modes: a pole p of a continuous element has the natural frequency
``|p|/(2 pi)`` Hz and damping ratio ``-Re p/|p|``; a discrete pole z is mapped to ``s = ln z`` per
sample first, times fs where the model states it (else its frequency is in units of fs). Poles at
s = 0 (z = 1) are integrators.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.models.lti import StateSpace
from nlsid.report.axes import legend_outside, plain_log_ticks, unwrapped_phase
from nlsid.report.html import Page, Table, number
from nlsid.report.vector import figure, new_figure

_TITLES = {
    "transfer_function": "Transfer function", "zpk": "Zero-pole-gain model", "state_space": "State-space model",
    "mass_spring_damper": "Mass-spring-damper", "two_mass_stage": "Two-mass stage", "wiener": "Wiener system",
    "hammerstein": "Hammerstein system", "wiener_hammerstein": "Wiener-Hammerstein system",
    "lpl": "Parallel LPL (Wiener-Hammerstein) system",
    "nonlinear_feedback": "Nonlinear feedback around an LTI system",
    "equations": "Model written as equations",
    "pnlss": "Polynomial nonlinear state-space model (black box)",
    "mimo_state_space": "State-space model of several inputs and outputs",
}


@dataclass(frozen=True)
class Element:
    """One LTI element of the model, named as in the config."""

    name: str
    ss: StateSpace


def in_hertz(ss: StateSpace) -> bool:
    """Whether the frequencies of ``ss`` are drawn in Hz: a continuous model, or a discrete one that
    states its sample rate (``fs``); else in cycles per sample (f / fs)."""
    return not ss.discrete or ss.fs is not None


def _unit(ss: StateSpace) -> str:
    return "Hz" if in_hertz(ss) else "× fs"


@dataclass(frozen=True)
class Mode:
    frequency: float  # Hz (continuous, or discrete with its fs) or cycles per sample (discrete without)
    damping: float
    count: int  # 1 real pole, 2 a complex pair


def modes(ss: StateSpace) -> list[Mode]:
    """The poles of ``ss`` as modes (module docstring), one entry per real pole or complex pair, by frequency."""
    out = []
    for p in ss.poles():
        if p.imag < -1e-12 * max(1.0, abs(p)):
            continue
        s = np.log(p) if ss.discrete else p
        magnitude = abs(s)
        damping = -s.real / magnitude if magnitude > 0 else 1.0
        pair = abs(s.imag) > 1e-12 * max(1.0, magnitude)
        scale = ss.fs if ss.discrete and ss.fs is not None else 1.0  # ln z per sample -> per second
        out.append(Mode(magnitude / (2 * math.pi) * scale, float(damping), 2 if pair else 1))
    return sorted(out, key=lambda m: m.frequency)


def describe_modes(ss: StateSpace) -> str:
    """Text such as ``2 integrators, mode 39 Hz (zeta 0.25)``."""
    unit = _unit(ss)
    found = modes(ss)
    integrators = sum(m.count for m in found if m.frequency < 1e-9)
    parts = [f"{integrators} integrator{'s' if integrators > 1 else ''}"] if integrators else []
    for m in found:
        if m.frequency < 1e-9:
            continue
        unstable = "unstable " if m.damping < 0 else ""
        if m.count == 2:
            parts.append(f"{unstable}mode {m.frequency:.3g} {unit} (ζ {m.damping:.2g})")
        else:
            parts.append(f"{unstable}real pole {m.frequency:.3g} {unit}")
    return ", ".join(parts) if parts else "static gain"


def response(ss: StateSpace, frequency: np.ndarray) -> np.ndarray:
    """Frequency response at ``frequency`` (Hz, continuous with its dead time; a discrete model
    without its dead time, in Hz where it states its fs, else in f/fs)."""
    if ss.discrete:
        return ss.frequency_response(np.exp(2j * math.pi * frequency / (ss.fs or 1.0)))
    return ss.frequency_response(2j * math.pi * frequency) * np.exp(-2j * math.pi * frequency * ss.delay)


def frequency_axis(elements: list[Element]) -> np.ndarray:
    """400 log-spaced points a decade beyond the lowest and highest nonzero mode (Hz); up to half
    the sample rate if discrete (from 1e-4 of it; in f/fs where the model states no fs)."""
    if elements[0].ss.discrete:
        return np.logspace(-4, math.log10(0.5), 400) * (elements[0].ss.fs or 1.0)
    found = [m.frequency for e in elements for m in modes(e.ss) if m.frequency > 1e-9]
    low, high = (min(found), max(found)) if found else (1.0, 1.0)
    return np.logspace(math.floor(math.log10(low)) - 1, math.ceil(math.log10(high)) + 1, 400)


def crossover(frequency: np.ndarray, loop: np.ndarray) -> tuple[float, float] | None:
    """The first frequency where |L| falls through 1 (log-linear interpolation) and the phase margin (deg)."""
    gain_db = 20 * np.log10(np.abs(loop))
    phase = np.degrees(np.unwrap(np.angle(loop)))
    below = np.flatnonzero((gain_db[:-1] >= 0) & (gain_db[1:] < 0))
    if not below.size:
        return None
    i = below[0]
    t = gain_db[i] / (gain_db[i] - gain_db[i + 1])
    log_f = math.log10(frequency[i]) + t * (math.log10(frequency[i + 1]) - math.log10(frequency[i]))
    angle = phase[i] + t * (phase[i + 1] - phase[i])
    margin = (angle + 180.0) % 360.0
    return 10**log_f, float(margin - 360.0 if margin > 180.0 else margin)


def _elements(config) -> tuple[list[Element], list[tuple[str, dict]]]:
    """The LTI elements and the nonlinear elements (name, parameters) of a validated config."""
    from nlsid.models import from_config

    model = config.model
    if model.type in from_config.STRUCTURES:
        structure_blocks = {"wiener": [("linear", "nonlinear")], "hammerstein": [("nonlinear", "linear")],
                            "wiener_hammerstein": [("first", "nonlinear", "second")]}
        branches = ([(f"branches[{i}]", b, ("before", "nonlinear", "after")) for i, b in enumerate(model.branches)]
                    if model.type == "lpl" else [("", model, structure_blocks[model.type][0])])
        linear, nonlinear = [], []
        for prefix, holder, keys in branches:
            for key in keys:
                block = getattr(holder, key)
                name = f"{prefix}.{key}" if prefix else key
                if block is None:
                    continue
                if key == "nonlinear":
                    nonlinear.append((name, block.model_dump()))
                else:
                    linear.append(Element(name, from_config.lti(block, f"model.{name}")))
        return linear, nonlinear
    if model.type == "pnlss":  # the linear part A, B, C, D; E and F as polynomial terms (docs/pnlss.md)
        pnlss = from_config.model(config)
        variables = monomial_variables(pnlss)
        terms = [(name, {"type": f"polynomial terms of degrees {list(degrees)} in the monomials of {variables}",
                         "monomials": int(coefficients.shape[-1]), "nonzero": int(np.count_nonzero(coefficients)),
                         "combinations": pnlss.lfr_inputs if pnlss.lfr else None})
                 for name, degrees, coefficients in (("E, state equation", pnlss.state_degrees, pnlss.E),
                                                     ("F, output equation", pnlss.output_degrees, pnlss.F)) if degrees]
        linear = pnlss.linear
        return [Element("linear part A, B, C, D", StateSpace(linear.A, linear.B, linear.C, linear.D, discrete=True,
                                                             fs=pnlss.fs))], terms
    plant = from_config.plant(model, closed=config.closed_loop is not None)
    label = "linear plant" + (" (nonlinear forces removed)" if plant.forces else "")
    nonlinear = [(f"nonlinearities[{i}]", f.model_dump()) for i, f in enumerate(getattr(model, "nonlinearities", []))]
    for key in ("input_nonlinearity", "output_nonlinearity"):
        block = getattr(model, key, None)
        if block is not None:
            nonlinear.append((key, block.model_dump()))
    return [Element(label, plant.ss)], nonlinear


def monomial_variables(pnlss) -> str:
    """What a PNLSS model's monomials are of (``docs/pnlss.md``): the states and u, the states
    alone, or, in the LFR form, the n_z combinations z = C_z x + D_z u."""
    if pnlss.lfr:
        count = pnlss.lfr_inputs
        return f"z = Cz x + Dz u ({count} combination{'s' if count != 1 else ''})"
    return "the states and u" if pnlss.with_input else "the states"


#: a model config records no units: each element's gain is in its output's unit per unit of its input
BODE_UNIT = "dB re 1 output/input, units not recorded"


def _bode(elements: list[Element], loop: np.ndarray | None, frequency: np.ndarray):
    drawn, (magnitude, phase) = new_figure(2)
    curves = [(e.name, response(e.ss, frequency)) for e in elements]
    if loop is not None:
        curves.append(("loop gain L = C P", loop))
    for name, values in curves:
        magnitude.semilogx(frequency, 20 * np.log10(np.abs(values)), label=name)
        phase.semilogx(frequency, unwrapped_phase(values)[0], label=name)
    magnitude.set_ylabel(f"magnitude ({BODE_UNIT})")
    phase.set_ylabel("phase (deg)")
    legend_outside(magnitude)
    for axis in (magnitude, phase):
        axis.set_xlabel("frequency (Hz)" if in_hertz(elements[0].ss) else "f / fs (cycles per sample)")
        axis.grid(True, which="both", alpha=0.3)
        plain_log_ticks(axis.xaxis)
    return drawn


def _parameters(values: dict) -> str:
    return ", ".join(f"{key} = {value:g}" if isinstance(value, float) else f"{key} = {value}"
                     for key, value in values.items() if key != "type" and value is not None)


MAX_WRITTEN = 60  # numbers listed one per row on the page; a larger model (matrices) is summarised


def written_numbers(data: dict) -> Table:
    """The numbers of the model and closed_loop sections as the file writes them, by the key path
    that ``free:``, ``sweep`` and the Python ``Model.with_parameters`` take; above
    :data:`MAX_WRITTEN` numbers (a black-box model's matrices) their count per block instead."""
    from nlsid.models.key_paths import numbers

    found = numbers(data)
    if len(found) <= MAX_WRITTEN:
        rows = [[key, number(value, ".6g")] for key, value in found.items()]
        return Table("Parameters as written", ["key path", "value"], rows, text=(0,),
                     note="Every number of the model and closed_loop sections, by the key path that free:, "
                          "sweep and Model.with_parameters take. A model config records no units: each "
                          "takes its unit from the recording's signals it relates.")
    blocks: dict[str, int] = {}
    for key in found:
        block = key.split("[", 1)[0]
        blocks[block] = blocks.get(block, 0) + 1
    return Table("Parameters as written", ["block", "numbers"], [[k, str(v)] for k, v in blocks.items()],
                 text=(0,), note=f"{len(found)} numbers: their count per block (the file holds them).")


def render_model(path: Path) -> Page:
    """The report page of a model config (module docstring)."""
    from nlsid.io.config import load_yaml
    from nlsid.io.model_config import validate_simulate_config
    from nlsid.models.from_config import closed_loop, model

    data, lines = load_yaml(path)
    config = validate_simulate_config(data, path, lines)
    hybrid = config.model if config.model.type == "hybrid" else None
    if hybrid is not None:  # the physical part's page, the black-box term stated (_with_black_box)
        try:
            model(config)  # the checks of nlsid simulate on both parts
        except InputError as exc:
            raise InputError(f"{path}: {exc.where}", exc.what) from None
        config = config.model_copy(update={"model": hybrid.physical})
    if config.model.type == "mimo_state_space":
        return _mimo_page(path, config, data)
    if config.model.type == "equations":
        try:
            model(config)  # the checks of nlsid simulate: open loop only, its expressions and names
        except InputError as exc:
            raise InputError(f"{path}: {exc.where}", exc.what) from None
        return _with_black_box(_equations_page(path, config), hybrid)
    try:
        model(config)  # the checks of nlsid simulate: stability, structure in open loop only
        linear, nonlinear = _elements(config)
        loop_config = closed_loop(config)
    except InputError as exc:
        raise InputError(f"{path}: {exc.where}", exc.what) from None
    simple_loop = loop_config is not None and len(loop_config.controller) == 1 and not loop_config.measurement
    if loop_config is not None:
        stages = [c for c in loop_config.controller if not isinstance(c, str)]
        linear += [Element("controller C" + (f" ({i + 1} of {len(stages)})" if len(stages) > 1 else ""), c)
                   for i, c in enumerate(stages)]
        linear += [Element("measurement term M", c) for c in loop_config.measurement if not isinstance(c, str)]
    title = _TITLES[config.model.type]
    setting = "in closed loop" if loop_config is not None else "in open loop"
    headline = f"{title} {setting}: {describe_modes(linear[0].ss)}"
    if nonlinear:
        headline += "; " + ", ".join(f"{values['type'].replace('_', ' ')} ({name})" for name, values in nonlinear)
    else:
        headline += "; linear (no nonlinear element)"
    findings = [f"{e.name}: {describe_modes(e.ss)}" + (f", dead time {e.ss.delay:g} s" if e.ss.delay else "")
                for e in linear]
    figures, numbers = [], {"model": config.model.type, "closed_loop": loop_config is not None, "elements": [],
                            "nonlinear": [{"name": n, **v} for n, v in nonlinear]}
    for domain in (False, True):
        group = [e for e in linear if e.ss.discrete == domain]
        if not group:
            continue
        frequency = frequency_axis(group)
        loop = None
        if simple_loop and not domain and not linear[0].ss.discrete and not loop_config.controller[0].discrete:
            loop = response(linear[0].ss, frequency) * response(loop_config.controller[0], frequency)
            found = crossover(frequency, loop)
            if found is not None:
                findings.append(f"loop gain crossover {found[0]:.3g} Hz, phase margin {found[1]:.0f} deg "
                                "(continuous-time loop)")
                numbers["crossover_hz"], numbers["phase_margin_deg"] = found
        figures.append(figure(_bode(group, loop, frequency),
                              ("Frequency response of the LTI elements" + (
                                  (" (discrete, up to half its sample rate" if in_hertz(group[0].ss) else
                                   " (discrete, over f/fs") + "; dead time not drawn)" if domain else "") + ". Magnitude and phase of each element as simulated"
                               + (", and the loop gain" if loop is not None else "") + "."),
                              "bode_discrete" if domain else "bode"))
    if config.disturbances.u_noise or config.disturbances.y_noise or config.disturbances.process_noise:
        d = config.disturbances
        findings.append(f"noise std: u {d.u_noise:g}, y {d.y_noise:g}, process {d.process_noise:g}")
    if config.sweep is not None:
        findings.append(f"sweep of {config.sweep.name or config.sweep.parameter} ({config.sweep.parameter})")
    pole_rows = []
    for e in linear:
        unit = _unit(e.ss)
        item = {"name": e.name, "discrete": e.ss.discrete, "delay": e.ss.delay, "fs": e.ss.fs, "modes": []}
        for m in modes(e.ss):
            pole_rows.append([e.name, f"{m.frequency:.4g} {unit}", number(m.damping, ".3g"),
                              "complex pair" if m.count == 2 else "real"])
            item["modes"].append({"frequency": m.frequency, "damping": m.damping, "poles": m.count})
        numbers["elements"].append(item)
    tables = [Table("Modes of the LTI elements", ["element", "natural frequency", "damping ratio ζ", "poles"],
                    pole_rows, note="Natural frequency |p|/(2π) and damping ratio −Re p/|p| of each pole p "
                                    "(discrete: of ln z per sample, times the sample rate where the "
                                    "model states it, else in units of fs).")]
    if nonlinear:
        tables.append(Table("Nonlinear elements", ["element", "type", "parameters"],
                            [[name, values["type"], _parameters(values)] for name, values in nonlinear]))
    tables.append(written_numbers(data))
    return _with_black_box(Page(kind="Simulation model", title=f"Model report: {Path(path).name}", source=str(path),
                                headline=headline, findings=findings, figures=figures, tables=tables,
                                numbers=numbers), hybrid)


def _mimo_page(path: Path, config, data: dict) -> Page:
    """The page of a ``mimo_state_space`` model: its modes (the eigenvalues of A, shared by every
    entry) and the matrix of its frequency responses, entry (i, a) from input a to output i
    (:meth:`nlsid.models.lti.MimoStateSpace.frequency_response`, with its dead time; a discrete
    model over f/fs where it states no fs)."""
    from nlsid.models.from_config import model

    try:
        mimo = model(config)  # the checks of nlsid simulate: stability, open loop only
    except InputError as exc:
        raise InputError(f"{path}: {exc.where}", exc.what) from None
    element = Element("A, B, C, D", mimo)
    frequency = frequency_axis([element])
    G = mimo.frequency_response(frequency, fs=1.0 if mimo.discrete and mimo.fs is None else None)
    shape = f"{mimo.n_outputs} outputs ({', '.join(mimo.outputs)}) x {mimo.n_inputs} inputs ({', '.join(mimo.inputs)})"
    nonlinear = [(f"{key}.{name}", block.model_dump()) for key in ("input_nonlinearity", "output_nonlinearity")
                 for name, block in getattr(config.model, key).items()]  # static blocks per signal
    headline = (f"{_TITLES[config.model.type]} in open loop, {shape}: {describe_modes(mimo)}; "
                + (", ".join(f"{values['type'].replace('_', ' ')} ({name})" for name, values in nonlinear)
                   + " (the figure: the linear part A, B, C, D)" if nonlinear else "linear"))
    findings = [f"{mimo.order} states" + (f", dead time {mimo.delay:g} s on every input" if mimo.delay else "")]
    d = config.disturbances
    levels = {"u": d.u_noise, "y": d.y_noise, "process": d.process_noise}
    if any(np.any(np.asarray(level) > 0) for level in levels.values()):
        findings.append("noise std: " + ", ".join(
            f"{kind} " + (", ".join(f"{v:g}" for v in level) if isinstance(level, list) else f"{level:g} on each")
            for kind, level in levels.items()))
    unit = _unit(mimo)
    found = modes(mimo)
    caption = ("Frequency response matrix: row i (magnitude, phase) is output i, a curve per input; "
               "magnitude in dB re 1 output/input (a model config records no units). "
               + ("Discrete, up to half its sample rate." if mimo.discrete else "Continuous, with its dead time."))
    numbers = {"model": config.model.type, "closed_loop": False, "inputs": list(mimo.inputs),
               "outputs": list(mimo.outputs), "nonlinear": [{"name": name, **values} for name, values in nonlinear],
               "elements": [{"name": element.name, "discrete": mimo.discrete, "delay": mimo.delay, "fs": mimo.fs,
                             "modes": [{"frequency": m.frequency, "damping": m.damping, "poles": m.count}
                                       for m in found]}]}
    rows = [[element.name, f"{m.frequency:.4g} {unit}", number(m.damping, ".3g"),
             "complex pair" if m.count == 2 else "real"] for m in found]
    tables = [Table("Modes", ["element", "natural frequency", "damping ratio ζ", "poles"], rows,
                    note="The eigenvalues of A, common to every input-output pair (as on a model of one input)."),
              written_numbers(data)]
    return Page(kind="Simulation model", title=f"Model report: {Path(path).name}", source=str(path),
                headline=headline, findings=findings, tables=tables, numbers=numbers,
                figures=[figure(_bode_matrix(mimo, frequency, G), caption, "bode_matrix")])


def _bode_matrix(mimo, frequency: np.ndarray, G: np.ndarray):
    """Magnitude and phase of each entry of ``G`` (F, n_y, n_u): a row of two panels per output,
    a curve per input."""
    n_y, n_u = G.shape[1:]
    drawn, axes = new_figure(n_y, 2, height=2.6)
    for i in range(n_y):
        magnitude, phase = axes[2 * i], axes[2 * i + 1]
        for a in range(n_u):
            name = f"{mimo.outputs[i]} from {mimo.inputs[a]}"
            magnitude.semilogx(frequency, 20 * np.log10(np.abs(G[:, i, a])), label=name)
            phase.semilogx(frequency, unwrapped_phase(G[:, i, a])[0], label=name)
        magnitude.set_ylabel(f"{mimo.outputs[i]}: magnitude (dB)")
        phase.set_ylabel(f"{mimo.outputs[i]}: phase (deg)")
        phase.legend(fontsize="small")
        for axis in (magnitude, phase):
            axis.set_xlabel("frequency (Hz)" if in_hertz(mimo) else "f / fs (cycles per sample)")
            axis.grid(True, which="both", alpha=0.3)
            plain_log_ticks(axis.xaxis)
    return drawn


def _with_black_box(page: Page, hybrid) -> Page:
    """The page of a hybrid model's physical part (``hybrid``: its
    :class:`~nlsid.io.model_config.HybridConfig`; None: ``page`` as it is) with the black-box term
    in parallel stated: in the headline, a finding, and ``numbers["black_box"]`` (states, degrees,
    form, coefficients)."""
    if hybrid is None:
        return page
    from nlsid.models.pnlss import build

    box = build(hybrid.black_box, "model.black_box")
    form = f"LFR form, {box.lfr_inputs} combination(s) z" if box.lfr else "full form"
    page.headline = f"Hybrid model: {page.headline}; plus a black-box PNLSS term in parallel"
    page.findings.insert(0, f"black-box term (PNLSS, in parallel with the physical part above, y = y_physical + "
                            f"y_black_box): {box.order} states, monomials of degrees {list(box.state_degrees)} / "
                            f"{list(box.output_degrees)} ({form}), {box.n_parameters} coefficients, discrete at "
                            f"{box.fs:g} Hz")
    page.numbers["black_box"] = {"states": box.order, "state_degrees": list(box.state_degrees),
                                 "output_degrees": list(box.output_degrees), "form": "lfr" if box.lfr else "full",
                                 "parameters": box.n_parameters, "fs": box.fs}
    page.numbers["model"] = "hybrid"
    page.numbers["physical"] = hybrid.physical.type
    return page


def _equations_page(path: Path, config) -> Page:
    """The page of a model written as equations: no LTI element to draw, its equations as tables."""
    m = config.model
    time = "continuous" if m.derivatives is not None else "discrete"
    symbol = "d{}/dt" if m.derivatives is not None else "{}[k+1]"
    nonlinear = [(key, getattr(m, key).model_dump()) for key in ("input_nonlinearity", "output_nonlinearity")
                 if getattr(m, key) is not None]
    headline = (f"{_TITLES['equations']} ({time} time) in open loop: {len(m.states)} state"
                f"{'s' if len(m.states) != 1 else ''}, {len(m.parameters)} parameter"
                f"{'s' if len(m.parameters) != 1 else ''}")
    if nonlinear:
        headline += "; " + ", ".join(f"{values['type'].replace('_', ' ')} ({name})" for name, values in nonlinear)
    bounds = {name: [None if v is None else float(v) for v in pair] for name, pair in m.bounds.items()}
    rows = [[symbol.format(name), m.equations[name], number(m.states[name], ".6g"),
             "[{}, {}]".format(*("-" if v is None else f"{v:g}" for v in bounds[name])) if name in bounds else "-"]
            for name in m.states]
    rows.append(["y", m.output, "-", "-"])
    tables = [Table("Equations", ["quantity", "expression", "initial value", "bounds"], rows,
                    note="u: the plant input (the command after delay, offsets and input block); r and the "
                         "recording's channels by name (docs/configs.md, Models written as equations)."),
              Table("Parameters", ["parameter", "value"], [[k, number(v, ".6g")] for k, v in m.parameters.items()])]
    if nonlinear:
        tables.append(Table("Nonlinear elements", ["element", "type", "parameters"],
                            [[name, values["type"], _parameters(values)] for name, values in nonlinear]))
    findings = [f"dead time {m.delay:g} s"] if m.delay else []
    numbers = {"model": "equations", "closed_loop": False, "elements": [],
               "nonlinear": [{"name": n, **v} for n, v in nonlinear],
               "equations": {"time": time, "states": dict(m.states), "bounds": bounds,
                             "parameters": dict(m.parameters), "expressions": dict(m.equations), "output": m.output}}
    return Page(kind="Simulation model", title=f"Model report: {Path(path).name}", source=str(path),
                headline=headline, findings=findings, figures=[], tables=tables, numbers=numbers)
