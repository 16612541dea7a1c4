"""The pipeline config that ``nlsid run`` reads: a root folder and a list of stage command lines.

::

    root: ..                  # folder the paths are relative to, itself relative to this file
    steps:
      - design configs/stage_design.yaml -o out/excitation.h5
      - bla sample_data/stage.h5 -o out/bla.h5 --plots out/figures
"""

from __future__ import annotations

import shlex

from pydantic import Field

from nlsid.io.config import ConfigValueError, StrictModel

OUTPUT_FLAGS = ("-o", "--output")


class PipelineConfig(StrictModel):
    root: str = "."
    steps: list[str] = Field(min_length=1)

    def check(self) -> None:
        for i, step in enumerate(self.steps):
            try:
                args = shlex.split(step)
            except ValueError as exc:
                raise ConfigValueError(("steps", i), f"cannot split the command line: {exc}") from None
            if not args or args[0] in ("run", "-h", "--help"):
                raise ConfigValueError(("steps", i), "expected a stage command line, e.g. 'bla rec.h5 -o bla.h5'")
            if not any(flag in args[:-1] for flag in OUTPUT_FLAGS):
                raise ConfigValueError(("steps", i), "names no output: give it -o PATH")
