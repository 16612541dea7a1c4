"""nlsid.io.atomic.atomic_folder: a result folder appears whole or not at all."""

from __future__ import annotations

import pytest

from nlsid.errors import InputError
from nlsid.io.atomic import atomic_folder


def test_a_folder_written_whole_replaces_the_old_one_only_with_force(tmp_path):
    target = tmp_path / "out"
    with atomic_folder(target) as tmp:
        (tmp / "a.txt").write_text("new")
    assert sorted(p.name for p in target.iterdir()) == ["a.txt"]
    assert (target.stat().st_mode & 0o777) == 0o755
    with pytest.raises(InputError, match="--force"):
        with atomic_folder(target):
            pass
    with atomic_folder(target, force=True) as tmp:
        (tmp / "b.txt").write_text("newer")
    assert sorted(p.name for p in target.iterdir()) == ["b.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing left beside it


def test_a_failure_half_way_leaves_the_old_folder_and_no_temporary_one(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "old.txt").write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_folder(target, force=True) as tmp:
            (tmp / "half.txt").write_text("half")
            raise RuntimeError("failed while writing")
    assert sorted(p.name for p in target.iterdir()) == ["old.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
