"""The output folder of ``nlsid diagnose``: a summary, result arrays and the extended model.

Layout (``docs/formats.md``, drafted in ``docs/drafts/diagnose.md``)::

    diagnosis/
      summary.json          nlsid_format = "diagnosis", nlsid_format_version = 1, provenance,
                            headline, findings, split, evidence, original, verdict, hypotheses,
                            gain, files (the names below that exist)
      results.h5            root attrs nlsid_format = "diagnosis_results", nlsid_format_version = 1
        /bla/level_NN/      per multisine level (attrs level (NaN: none), u_rms): frequency (F,) Hz,
                            G, G_model (F, 2: re, im), radius (F,) of the 95% circle of G,
                            gain_error_db, phase_error_deg (F,), outside (F,) int8
        /spectrum/level_NN/ per line 0 .. N//2: kind (int8: -1 DC/Nyquist, 0 excited, 1 odd, 2 even,
                            3 non-harmonic), in_band (int8), frequency (Hz), y_power (measured),
                            model_power (model), noise (measured noise variance), all on the scale
                            of the P-averaged spectrum (DFT / N)
        /time/              one mean steady-state period (attrs run_id, fs): measured, model,
                            residual, input, [position, velocity] (mechanical models)
        /validation/        one validation run's mean period (attrs run_id, fs): original_error,
                            [extended_error] (the winner's)
      extended_model.yaml   only when a cause is named: the user's model plus the fitted block,
                            parameter values and standard errors in its header comment
      candidate_model.yaml  only when no cause is named but a hypothesis' gain is suggestive: the
                            leading candidate's model, its header marking it as not significant

The folder is written next to its final place under a temporary name and renamed when complete, so
a failed run leaves nothing; an existing folder is replaced only with ``force``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from nlsid.errors import InputError
from nlsid.io.atomic import atomic_folder
from nlsid.io.result_file import datasets, json_safe, put

FORMAT = "diagnosis"
RESULTS_FORMAT = "diagnosis_results"
FORMAT_VERSION = 1
SUMMARY, RESULTS, EXTENDED = "summary.json", "results.h5", "extended_model.yaml"


def _level_name(i: int) -> str:
    return f"level_{i:02d}"


def _write_results(path: Path, arrays: dict) -> None:
    import h5py

    with h5py.File(path, "w") as handle:
        handle.attrs["nlsid_format"] = RESULTS_FORMAT
        handle.attrs["nlsid_format_version"] = FORMAT_VERSION
        for section in ("bla", "spectrum"):
            group = handle.create_group(section)
            for i, level in enumerate(arrays.get(section, [])):
                sub = group.create_group(_level_name(i))
                for key, value in level.items():
                    if key in ("level", "u_rms"):
                        sub.attrs[key] = float("nan") if value is None else float(value)
                    else:
                        put(sub, key, value)
        for section in ("time", "validation"):
            group = handle.create_group(section)
            for key, value in arrays.get(section, {}).items():
                if key in ("run_id", "fs"):
                    group.attrs[key] = value
                else:
                    put(group, key, value)


def extended_yaml(data: dict, header: list[str]) -> str:
    """The extended model config as YAML text, with ``header`` lines as a leading comment."""
    import yaml

    comment = "".join(f"# {line}\n" for line in header)
    return comment + yaml.safe_dump(json_safe(data), sort_keys=False, default_flow_style=None)


def write_diagnosis(folder: str | os.PathLike, summary: dict, arrays: dict, extended: str | None,
                    provenance: dict, force: bool = False, others: dict[str, str] | None = None) -> Path:
    """Write the folder of the module docstring atomically; refuse an existing one unless ``force``.
    ``others``: further model files (file name -> YAML text) beside ``extended_model.yaml``."""
    with atomic_folder(folder, force) as tmp:
        models = {**({EXTENDED: extended} if extended is not None else {}), **(others or {})}
        files = [SUMMARY, RESULTS, *models]
        _write_results(tmp / RESULTS, arrays)
        for name, text in models.items():
            (tmp / name).write_text(text, encoding="utf-8")
        document = {"nlsid_format": FORMAT, "nlsid_format_version": FORMAT_VERSION, "provenance": provenance,
                    **summary, "files": files}
        (tmp / SUMMARY).write_text(json.dumps(json_safe(document), indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return Path(folder)


def _read_group(group) -> dict:
    out = {key: (float(v) if isinstance(v, (float, np.floating)) else v) for key, v in group.attrs.items()}
    out.update(datasets(group, group.name))
    return out


def read_diagnosis(folder: str | os.PathLike) -> tuple[dict, dict]:
    """The summary and the result arrays of a diagnosis folder, checked for format and version."""
    import h5py

    folder = Path(folder)
    summary_path = folder / SUMMARY
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(str(folder), f"no {SUMMARY}: not a diagnosis folder") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(str(summary_path), f"not valid JSON ({exc})") from None
    if not isinstance(summary, dict) or summary.get("nlsid_format") != FORMAT:
        raise InputError(f"{summary_path}: nlsid_format", f"expected {FORMAT!r}")
    if summary.get("nlsid_format_version") != FORMAT_VERSION:
        raise InputError(f"{summary_path}: nlsid_format_version",
                         f"expected {FORMAT_VERSION}, got {summary.get('nlsid_format_version')!r}")
    if summary.get("kind") == "mimo":  # no results.h5 (nlsid.stages.mimo_diagnosis): nothing to draw
        raise InputError(f"{summary_path}: kind", "a diagnosis of a model of several outputs has no page or result "
                                                  "arrays yet: its summary.json holds the diagnosis (docs/mimo.md)")
    results = folder / RESULTS
    try:
        with h5py.File(results, "r") as handle:
            if handle.attrs.get("nlsid_format") != RESULTS_FORMAT:
                raise InputError(f"{results}:/", f"nlsid_format is not {RESULTS_FORMAT!r}")
            arrays = {section: [_read_group(handle[section][name]) for name in sorted(handle[section])]
                      for section in ("bla", "spectrum")}
            for section in ("time", "validation"):
                arrays[section] = _read_group(handle[section])
    except (OSError, KeyError) as exc:
        raise InputError(str(results), f"missing or damaged results file ({exc})") from None
    return summary, arrays
