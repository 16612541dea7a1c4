"""The interface every recording reader shares (HDF5, MCAP): runs read one at a time."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Iterator

from nlsid.errors import InputError
from nlsid.io.run import Run


class RecordingReader(ABC):
    """An open recording. Subclasses set ``path``, ``format``, ``provenance`` and ``run_ids``
    and implement :meth:`load` and :meth:`close`. Iterating yields validated runs in ``run_ids``
    order, one at a time, so memory does not grow with the number of runs."""

    run_ids: list[str]

    @abstractmethod
    def load(self, run_id: str) -> Run:
        """Read and validate one run."""

    @abstractmethod
    def close(self) -> None:
        """Release the file."""

    def output_error(self) -> InputError | None:
        """What opening the file with ``require_y=True`` refuses (an excitation: no measured output
        y), or None. Shared by the reader and ``nlsid info`` (:mod:`nlsid.feeds`)."""
        return None

    def run_where(self, run_id: str) -> str:
        """How :meth:`load` names run ``run_id`` in its errors."""
        return f"{self.path}:/runs/{run_id}"

    def __iter__(self) -> Iterator[Run]:
        for run_id in self.run_ids:
            yield self.load(run_id)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
