"""Random corruptions of valid inputs (issue #14): every reader and config loader ends in success or
in one clear line, never in a traceback or another exit code, and never leaves a file behind.

Each valid input is small and built here (recordings with the nlsid writers, CSV text, MAT-files
with scipy.io.savemat and h5py, configs as YAML text). Hypothesis corrupts its bytes (truncation,
bit flips, inserted, deleted and overwritten bytes) or, for YAML configs, the parsed document
(a value replaced by a random scalar, list or mapping, a key deleted or added); the CLI runs
in-process on the result. The outcome must be exit 0, or exit 2 with exactly one line
``nlsid: error: ...`` on stderr; on exit 2 the output folder stays empty (a pipeline keeps the
outputs of the steps before the failing one, complete, and no temporary file); the input is never
changed. Settings are derandomized (the same examples on every run, as CI needs) and bounded
(``max_examples`` per reader) so the whole module runs in well under a minute on 2 cores.
Each test also asserts that its unmodified input succeeds and that some corruptions are refused,
so a reader that ignored its input, or a fuzzer that never reached it, would fail the test.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import tempfile
import traceback
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st
from scipy.io import savemat

from nlsid.io.recording import write_recording
from nlsid.io.run import make_run

from generators.mcap_cases import write_json_mcap  # noqa: E402

# Examples per reader; NLSID_FUZZ_EXAMPLES=1000 explores further (still reproducible), and
# NLSID_FUZZ_SEED=N draws other examples (seeded) instead of the derandomized ones CI runs.
EXAMPLES = int(os.environ.get("NLSID_FUZZ_EXAMPLES", "60"))
SEED = os.environ.get("NLSID_FUZZ_SEED")
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=SEED is None, database=None,
                # run_cli is a stateless function-scoped fixture; each example uses its own folder
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                       HealthCheck.data_too_large])

FS, N = 64.0, 16  # small runs: metadata is a good part of every file, so corruptions reach it


# ---------------------------------------------------------------------------------------------
# corruptions


@st.composite
def corrupted(draw, data: bytes) -> bytes:
    """``data`` with one to three random byte-level edits."""
    out = bytearray(data)
    for kind in draw(st.lists(st.sampled_from(["truncate", "flip", "insert", "delete", "overwrite"]), min_size=1, max_size=3)):
        if not out:
            break
        at = draw(st.integers(0, len(out) - 1))
        if kind == "truncate":
            del out[at:]
        elif kind == "flip":
            out[at] ^= 1 << draw(st.integers(0, 7))
        elif kind == "insert":
            out[at:at] = draw(st.binary(min_size=1, max_size=8))
        elif kind == "delete":
            del out[at:at + draw(st.integers(1, 16))]
        else:
            chunk = draw(st.binary(min_size=1, max_size=8))
            out[at:at + len(chunk)] = chunk
    return bytes(out)


# Integers stay small so that a count (periods, realizations, repeats) never asks for a huge design;
# text holds no path characters, so that a pipeline's root or step never points outside its folder.
SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(-3, 64), st.floats(-1e3, 1e3),
    st.sampled_from([0.0, -0.0, math.nan, math.inf, -math.inf, 1e-300, 1e300, "", "1e3", "yes", "~", "a\0b", "\x1e",
                     "\u2028"]),
    st.text(st.characters(blacklist_characters="/\\.", blacklist_categories=("Cs",)), max_size=6),
)
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                        st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=6)


def _paths(doc, prefix=()) -> list[tuple]:
    """Key paths of every value in a parsed YAML document."""
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    out = []
    for key, value in items:
        out.append(prefix + (key,))
        out.extend(_paths(value, prefix + (key,)))
    return out


@st.composite
def edited(draw, doc) -> str:
    """The YAML text of ``doc`` after one to three structural edits."""
    doc = copy.deepcopy(doc)
    for kind in draw(st.lists(st.sampled_from(["replace", "delete", "add"]), min_size=1, max_size=3)):
        paths = _paths(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = doc
        for part in path[:-1]:
            parent = parent[part]
        if kind == "replace":
            parent[path[-1]] = draw(VALUES)
        elif kind == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=6))] = draw(VALUES)
        else:
            parent.insert(path[-1], draw(VALUES))
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


# ---------------------------------------------------------------------------------------------
# outcomes


def check_outcome(result, out: Path, source: Path, digest: str, steps: bool = False) -> int:
    """Exit 0, or exit 2 with one error line and nothing written; the input unchanged.

    ``steps``: a pipeline, whose steps before a failing one keep their (complete) outputs; no
    temporary file of an atomic write may remain."""
    assert hashlib.sha256(source.read_bytes()).hexdigest() == digest, "the input was changed"
    if result.exit_code == 0:
        return 0
    crash = "".join(traceback.format_exception(result.exception)) if result.exception is not None \
        and not isinstance(result.exception, SystemExit) else ""
    assert result.exit_code == 2, f"exit code {result.exit_code}\n{result.stderr}\n{crash}"
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nlsid: error: "), result.stderr
    assert "Traceback" not in result.stderr
    left = sorted(p.name for p in out.iterdir())
    if steps:
        assert not [name for name in left if name.endswith(".tmp")], left
    else:
        assert left == [], "a failed command left files behind"
    return 2


def fuzz(run_cli, name: str, data: bytes, args, strategy=None, beside: dict[str, bytes] | None = None,
         examples: int = EXAMPLES) -> dict[int, int]:
    """Run ``args(source, out)`` on corruptions of ``data`` written to ``name`` (with the files
    ``beside`` next to it); count the exit codes.

    The unmodified data must succeed; at least one corruption must be refused.
    """
    counts = {0: 0, 2: 0}

    def once(payload: bytes) -> int:
        with tempfile.TemporaryDirectory() as folder:
            source, out = Path(folder) / name, Path(folder) / "out"
            out.mkdir()
            source.write_bytes(payload)
            for other, content in (beside or {}).items():
                (Path(folder) / other).write_bytes(content)
            result = run_cli(*args(source, out))
            return check_outcome(result, out, source, hashlib.sha256(payload).hexdigest(), steps=beside is not None)

    assert once(data) == 0, "the unmodified input must succeed"

    @settings(FUZZ, max_examples=examples)
    @given(payload=strategy if strategy is not None else corrupted(data))
    def run_examples(payload: bytes) -> None:
        counts[once(payload)] += 1

    (seed(int(SEED))(run_examples) if SEED is not None else run_examples)()
    assert counts[2] > 0, "no corruption was refused: the fuzzer does not reach the reader"
    return counts


# ---------------------------------------------------------------------------------------------
# valid inputs


def small_runs() -> list:
    n = np.arange(3 * N)
    u = math.sqrt(2 / 3) * (np.cos(2 * np.pi * 1 * n / N) + np.cos(2 * np.pi * 3 * n / N + 1) + np.cos(2 * np.pi * 5 * n / N + 2))
    sine = np.sin(2 * np.pi * 2 * n / N)
    multisine = {"fs": FS, "kind": "multisine", "period": N, "transient_periods": 1, "realization": 0, "level": 1.0,
                 "excited_bins": np.array([1, 3, 5]), "params": json.dumps({"K": 0.5})}
    tone = {"fs": FS, "kind": "sine", "period": N, "transient_periods": 1, "level": 1.0, "frequency": 2 * FS / N,
            "excited_bins": np.array([2])}
    return [make_run("ms_l00_m00", multisine, {"u": u, "y": 0.5 * u}, "test", True, {"u": "N", "y": "m"}),
            make_run("sine_f000_a00_r00", tone, {"u": sine, "y": 0.5 * sine, "r": sine}, "test", True)]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("recordings")
    out = {}
    for suffix in ("h5", "mcap"):
        path = folder / f"rec.{suffix}"
        write_recording(path, small_runs(), provenance={"tool": "nlsid", "command": "test"})
        out[suffix] = path.read_bytes()
    return out


def periodic_signal(periods: int = 3) -> np.ndarray:
    n = np.arange(periods * N)
    return np.cos(2 * np.pi * n / N) + 0.5 * np.cos(2 * np.pi * 3 * n / N + 1)


def test_hdf5_recording_info(run_cli, recordings):
    fuzz(run_cli, "rec.h5", recordings["h5"], lambda source, out: ["info", source, "--json"])


def test_hdf5_recording_bla(run_cli, recordings):
    fuzz(run_cli, "rec.h5", recordings["h5"], lambda source, out: ["-q", "bla", source, "-o", out / "bla.h5"])


def test_mcap_recording_info(run_cli, recordings):
    fuzz(run_cli, "rec.mcap", recordings["mcap"], lambda source, out: ["info", source, "--json"])


def test_hdf5_import(run_cli, recordings):
    fuzz(run_cli, "rec.h5", recordings["h5"], lambda source, out: [
        "-q", "import", source, "--u", "/runs/ms_l00_m00/u", "--y", "runs/ms_l00_m00/y", "--fs", "64", "-o", out / "rec.h5"])


def test_foreign_mcap_import(run_cli, tmp_path):
    path = tmp_path / "log.mcap"
    u = periodic_signal()
    write_json_mcap(path, FS, u, 2 * u)
    fuzz(run_cli, "log.mcap", path.read_bytes(), lambda source, out: [
        "-q", "import", source, "--u", "/cmd:effort", "--y", "/joint:state.position", "-o", out / "rec.h5"])


def csv_text(columns: dict[str, np.ndarray]) -> bytes:
    rows = np.column_stack(list(columns.values()))
    return ("\n".join([",".join(columns)] + [",".join(f"{v:.12g}" for v in row) for row in rows]) + "\n").encode()


def test_csv_import(run_cli):
    u = periodic_signal()
    data = csv_text({"time (s)": np.arange(u.size) / FS, "u": u, "y": 0.5 * u})
    fuzz(run_cli, "scope.csv", data, lambda source, out: ["-q", "import", source, "-o", out / "rec.h5"])


def test_csv_realizations_and_rate_column_import(run_cli):
    u1, u2 = periodic_signal(), -periodic_signal()
    data = csv_text({"fs": np.full(u1.size, FS), "u1": u1, "y1": 0.5 * u1, "u2": u2, "y2": 0.5 * u2})
    fuzz(run_cli, "pairs.csv", data, lambda source, out: ["-q", "import", source, "-o", out / "rec.h5"])


def test_mat_v5_import(run_cli, tmp_path):
    u = periodic_signal()
    path = tmp_path / "old.mat"
    savemat(path, {"u": u, "data": {"y": 0.5 * u, "t": np.arange(u.size) / FS}})
    fuzz(run_cli, "old.mat", path.read_bytes(), lambda source, out: [
        "-q", "import", source, "--y", "data.y", "--time", "data.t", "-o", out / "rec.h5"])


def test_mat_v73_import(run_cli, tmp_path):
    u = periodic_signal()
    path = tmp_path / "new.mat"
    with h5py.File(path, "w", userblock_size=512) as handle:
        for name, value in (("u", u), ("y", 0.5 * u)):
            handle.create_dataset(name, data=value[None, :]).attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as handle:
        handle.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 .")
    fuzz(run_cli, "new.mat", path.read_bytes(), lambda source, out: ["-q", "import", source, "--fs", "64", "-o", out / "rec.h5"])


DESIGN = {
    "fs": FS, "seed": 1, "unit": "N",
    "multisine": {"period": N, "band": [1.0, 20.0], "lines": "random-odd", "group_size": 3, "realizations": 2,
                  "periods": 2, "transient_periods": 1, "rms_levels": [0.5, 1.0]},
    "sines": {"period": N, "frequencies": [4.0, 8.0], "amplitudes": [1.0], "repeats": 1, "periods": 2,
              "transient_periods": 1},
}


def design_args(source: Path, out: Path) -> list:
    return ["-q", "design", source, "-o", out / "excitation.h5"]


def test_design_config_bytes(run_cli):
    data = yaml.safe_dump(DESIGN, sort_keys=False).encode()
    fuzz(run_cli, "design.yaml", data, design_args)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-32-be"])
def test_design_config_bytes_in_unicode(run_cli, encoding):
    """UTF-16 with a BOM (what Windows editors write as "Unicode"), UTF-32 without one: odd lengths,
    lone surrogates and code points beyond U+10FFFF must be refused like any other undecodable text."""
    data = yaml.safe_dump(DESIGN, sort_keys=False).encode(encoding)
    fuzz(run_cli, "design.yaml", data, design_args, examples=max(EXAMPLES // 2, 1))


def test_design_config_structure(run_cli):
    fuzz(run_cli, "design.yaml", yaml.safe_dump(DESIGN).encode(), design_args,
         strategy=edited(DESIGN).map(str.encode))


MODEL = {
    "model": {"type": "mass_spring_damper", "mass": 2.0, "damping": 20.0, "stiffness": 2000.0, "gain": 1.0,
              "output": "position", "nonlinearities": [{"type": "coulomb", "fc": 0.5}]},
    "disturbances": {"u_noise": 0.002, "y_noise": 2.0e-7, "seed": 3},
}


@pytest.fixture(scope="module")
def excitation(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("excitation")
    (folder / "design.yaml").write_text(yaml.safe_dump(DESIGN))
    from click.testing import CliRunner

    from nlsid.cli.main import cli

    result = CliRunner().invoke(cli, ["-q", "design", str(folder / "design.yaml"), "-o", str(folder / "excitation.h5")])
    assert result.exit_code == 0, result.stderr
    return folder / "excitation.h5"


def test_model_config_structure(run_cli, excitation):
    fuzz(run_cli, "model.yaml", yaml.safe_dump(MODEL).encode(),
         lambda source, out: ["-q", "simulate", source, "--excitation", excitation, "-o", out / "recording.h5"],
         strategy=edited(MODEL).map(str.encode))


def test_model_config_bytes(run_cli, excitation):
    fuzz(run_cli, "model.yaml", yaml.safe_dump(MODEL).encode(),
         lambda source, out: ["-q", "simulate", source, "--excitation", excitation, "-o", out / "recording.h5"])


PIPELINE = {"root": ".", "steps": ["design design.yaml -o out/excitation.h5",
                                   "simulate model.yaml --excitation out/excitation.h5 -o out/recording.h5"]}


def pipeline_args(source: Path, out: Path) -> list:
    return ["-q", "run", source]


def test_pipeline_config_structure(run_cli):
    """Pipelines run their steps, so fewer examples; the configs they name are valid."""
    beside = {"design.yaml": yaml.safe_dump(DESIGN).encode(), "model.yaml": yaml.safe_dump(MODEL).encode()}
    fuzz(run_cli, "pipeline.yaml", yaml.safe_dump(PIPELINE).encode(), pipeline_args,
         strategy=edited(PIPELINE).map(str.encode), beside=beside, examples=max(EXAMPLES // 2, 1))


def test_pipeline_config_bytes(run_cli):
    beside = {"design.yaml": yaml.safe_dump(DESIGN).encode(), "model.yaml": yaml.safe_dump(MODEL).encode()}
    fuzz(run_cli, "pipeline.yaml", yaml.safe_dump(PIPELINE).encode(), pipeline_args, beside=beside,
         examples=max(EXAMPLES // 2, 1))


# ---------------------------------------------------------------------------------------------
# non-finite numbers in the sample model configs

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _sample_models() -> dict[str, dict]:
    """The shipped model configs (those with a ``model`` key), parsed as nlsid parses them (YAML 1.2)."""
    from nlsid.io.config import load_yaml

    out = {}
    for path in sorted(CONFIGS.glob("*.yaml")):
        doc, _ = load_yaml(path)
        if isinstance(doc, dict) and "model" in doc:
            out[path.name] = doc
    return out


SAMPLE_MODELS = _sample_models()


def _key_text(path: tuple) -> str:
    """A key path as an error message writes it: ``model.nonlinearities[0].fc``, ``free['model.mass']``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif "." in part:
            out += f"[{part!r}]"
        else:
            out += f".{part}" if out else part
    return out


def _numeric_positions() -> list[tuple[str, tuple, float]]:
    """(config, key path, non-finite value) for every number of every sample model config; a free
    parameter's bound takes only NaN (an infinite bound is no bound, and valid)."""
    out = []
    for name, doc in SAMPLE_MODELS.items():
        for path in _paths(doc):
            value = doc
            for part in path:
                value = value[part]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                continue
            bound = path[0] == "free" and path[-1] in ("lower", "upper")
            out += [(name, path, bad) for bad in ((math.nan,) if bound else (math.nan, math.inf, -math.inf))]
    return out


NUMERIC_POSITIONS = _numeric_positions()


def _with_value(doc: dict, path: tuple, value: float) -> str:
    doc = copy.deepcopy(doc)
    parent = doc
    for part in path[:-1]:
        parent = parent[part]
    parent[path[-1]] = value
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def _refused_at_key(run_cli, folder: Path, name: str, path: tuple, value: float) -> None:
    source, out = folder / name, folder / "out"
    out.mkdir(exist_ok=True)
    source.write_text(_with_value(SAMPLE_MODELS[name], path, value))
    result = run_cli("simulate", source, "--excitation", folder / "no_excitation.h5", "-o", out / "rec.h5")
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1, (name, path, value, result.stderr, result.exception)
    assert lines[0].startswith(f"nlsid: error: {source}:") and f": {_key_text(path)}: " in lines[0], \
        (name, path, value, lines[0])
    assert "Traceback" not in result.stderr and list(out.iterdir()) == []


def test_the_sample_models_have_numbers_everywhere():
    """The sweep below reaches the models' numbers: every shipped model config, many positions."""
    assert len(SAMPLE_MODELS) >= 8 and len({name for name, _, _ in NUMERIC_POSITIONS}) == len(SAMPLE_MODELS)
    assert len(NUMERIC_POSITIONS) > 100


def test_non_finite_number_anywhere_in_a_sample_model(run_cli):
    """Hypothesis picks a sample model config, a number in it and a non-finite value for it (YAML
    ``.nan``, ``.inf``, ``-.inf``): refused with exit 2, naming the file and the key path."""

    @settings(FUZZ)
    @given(case=st.sampled_from(NUMERIC_POSITIONS))
    def run_examples(case) -> None:
        with tempfile.TemporaryDirectory() as folder:
            _refused_at_key(run_cli, Path(folder), *case)

    (seed(int(SEED))(run_examples) if SEED is not None else run_examples)()


def test_non_finite_number_in_every_position_of_the_sample_models(run_cli, tmp_path):
    """The same, exhaustively: every number of every sample model config, each non-finite value."""
    for index, case in enumerate(NUMERIC_POSITIONS):
        folder = tmp_path / str(index)
        folder.mkdir()
        _refused_at_key(run_cli, folder, *case)
