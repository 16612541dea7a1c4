"""Outputs of ``nlsid fit``: the model config (YAML that ``nlsid simulate`` runs) and the fit report
(JSON) written beside it as ``<model>.fit.json``.

The model YAML starts with comment lines (tool, version, what was fitted) and holds a plain model
config (``docs/configs.md``). The report holds the numbers behind it (layouts in
``docs/formats.md``, section "nlsid fit outputs"): ``nlsid_format = "fit"``, version 1,
``provenance``, ``kind`` (``transfer_function`` or ``extension``) and the kind's fields.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import yaml

from nlsid.io.atomic import check_writable, write_text_atomic
from nlsid.io.result_file import json_safe

FORMAT = "fit"
FORMAT_VERSION = 1


def report_path(model_path: str | os.PathLike) -> Path:
    """``model.yaml`` -> ``model.fit.json`` (same folder)."""
    path = Path(model_path)
    return path.with_name(f"{path.stem}.fit.json")


def model_yaml(config: dict, header: list[str]) -> str:
    """YAML text of a model config with a comment header (numbers round-trip exactly)."""
    comments = "".join(f"# {line}\n" for line in header)
    return comments + yaml.safe_dump(json_safe(config), sort_keys=False, default_flow_style=None, width=100)


def write_fit(model_path: str | os.PathLike, config: dict, header: list[str], report: dict, provenance: dict,
              force: bool = False) -> tuple[Path, Path]:
    """Write the model YAML and its report atomically; neither is written when either exists (no --force)."""
    json_path = report_path(model_path)
    check_writable(model_path, force)
    check_writable(json_path, force)
    document = {"nlsid_format": FORMAT, "nlsid_format_version": FORMAT_VERSION, "provenance": provenance,
                **json_safe(report)}
    write_text_atomic(json_path, json.dumps(document, indent=2, sort_keys=True) + "\n", force=force)
    write_text_atomic(model_path, model_yaml(config, header), force=force)
    return Path(model_path), json_path
