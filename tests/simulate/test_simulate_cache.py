"""Where the kernels' compiled code is cached (nlsid.simulate.jit): never inside the package.

The folder choice is checked as a function of the environment; the subprocess tests import the
kernels in a fresh interpreter (numba reads NUMBA_CACHE_DIR at its import and picks a function's
folder when it is decorated) and ask numba itself which folder and locator a kernel got. A folder
"cannot be written" here because its path runs through a regular file (the tests may run as
root, whom permission bits do not stop).
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from nlsid.simulate import jit

UID = f"nlsid-{os.getuid()}" if hasattr(os, "getuid") else "nlsid"


@pytest.fixture
def debug_log():
    """The debug records of the ``nlsid`` logger (a handler on it: the CLI turns its propagation off)."""
    records: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())

    logger, handler = logging.getLogger("nlsid"), Keep(logging.DEBUG)
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    yield records
    logger.removeHandler(handler)
    logger.setLevel(level)


@pytest.fixture
def blocked(tmp_path) -> Path:
    """A regular file: no folder can be made below it."""
    path = tmp_path / "a-file"
    path.write_text("")
    return path


@pytest.fixture
def temp_dir(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr("tempfile.tempdir", str(folder))
    return folder


def test_a_writable_numba_cache_dir_is_used_as_it_is(tmp_path, temp_dir):
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "mine"), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert jit.choose_cache_folder(env) == tmp_path / "mine"
    assert (tmp_path / "mine").is_dir() and not (tmp_path / "xdg").exists()


def test_the_user_cache_follows_xdg_and_else_home(tmp_path, temp_dir):
    home = str(tmp_path / "home")
    assert jit.choose_cache_folder({"XDG_CACHE_HOME": str(tmp_path / "xdg"), "HOME": home}) == \
        tmp_path / "xdg" / "nlsid" / "numba"
    # the XDG spec: a relative XDG_CACHE_HOME is invalid and ignored
    assert jit.choose_cache_folder({"XDG_CACHE_HOME": "relative/cache", "HOME": home}) == \
        tmp_path / "home" / ".cache" / "nlsid" / "numba"


def test_an_unwritable_numba_cache_dir_falls_back_to_the_user_cache(tmp_path, blocked, temp_dir, debug_log):
    env = {"NUMBA_CACHE_DIR": str(blocked / "numba"), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert jit.choose_cache_folder(env) == tmp_path / "xdg" / "nlsid" / "numba"
    assert any(str(blocked / "numba") in m and "cannot be written" in m for m in debug_log), debug_log


def test_an_unwritable_home_falls_back_to_a_private_temp_folder(blocked, temp_dir, debug_log):
    folder = jit.choose_cache_folder({"HOME": str(blocked)})
    assert folder == temp_dir / UID / "numba" and folder.is_dir()
    assert folder.parent.stat().st_mode & 0o077 == 0  # only this user's
    assert any("temp folder" in m for m in debug_log), debug_log


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="no user ids on this platform: the temp folder is the user's")
@pytest.mark.parametrize("kind", ["open to all", "a symlink"])
def test_a_temp_folder_others_can_write_is_not_used_and_kernels_run_uncached(tmp_path, blocked, temp_dir, debug_log,
                                                                               kind):
    """Cache files are pickles: a folder someone else can write (or a link someone else may have
    planted) must not be loaded from."""
    if kind == "open to all":
        (temp_dir / UID).mkdir()
        (temp_dir / UID).chmod(0o777)
    else:
        (tmp_path / "elsewhere").mkdir(mode=0o700)
        (temp_dir / UID).symlink_to(tmp_path / "elsewhere")
    assert jit.choose_cache_folder({"HOME": str(blocked)}) is None
    assert any("not a private folder" in m for m in debug_log), debug_log
    assert any("uncached" in m for m in debug_log), debug_log
    assert not (tmp_path / "elsewhere" / "numba").exists()


def kernel_in_fresh_process(env: dict, prelude: str = "") -> dict:
    """Import the kernels in a new interpreter with ``env`` (nothing of this process's numba cache
    settings), run the backlash (play operator) along a signal, and report what numba chose."""
    script = prelude + (
        "import json, logging, sys\n"
        "logging.getLogger('nlsid').addHandler(logging.StreamHandler(sys.stderr))\n"
        "logging.getLogger('nlsid').setLevel(logging.DEBUG)\n"
        "import numpy as np\n"
        "from nlsid.models import blocks\n"
        "from nlsid.simulate import jit, kernels\n"
        "y = kernels.apply_block(blocks.BACKLASH, np.array([0.5]), np.array([0.0, 1.0, 2.0, 1.0, 0.0]))\n"
        "cache = kernels.apply_block._cache\n"
        "print(json.dumps({'y': y.tolist(), 'caching': jit.CACHING, 'path': getattr(cache, '_cache_path', None),\n"
        "                  'locator': type(getattr(cache, '_impl', None) and cache._impl.locator).__name__}))\n")
    base = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "TMPDIR")}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env={**base, **env},
                         timeout=300)
    assert out.returncode == 0, out.stderr
    return {**json.loads(out.stdout.splitlines()[-1]), "log": out.stderr}


# the play operator of half width 0.5 from memory 0: it follows x only when x leaves the band
# [memory - 0.5, memory + 0.5], by x -+ 0.5 (hand-computed)
BACKLASH_Y = [0.0, 0.5, 1.5, 1.5, 0.5]


@pytest.mark.parametrize("numba_first", [False, True], ids=["nlsid first", "numba imported before nlsid"])
def test_a_fresh_process_caches_kernels_in_the_user_cache(tmp_path, numba_first):
    """The kernel's locator is numba's for NUMBA_CACHE_DIR, below $XDG_CACHE_HOME/nlsid/numba, and
    its files are written there. Without the module numba would take the in-tree locator (the
    package's __pycache__); with numba imported first, also unless its configuration is reloaded."""
    got = kernel_in_fresh_process({"XDG_CACHE_HOME": str(tmp_path / "xdg"), "HOME": str(tmp_path / "home")},
                                  "import numba\n" if numba_first else "")
    assert got["y"] == BACKLASH_Y
    folder = tmp_path / "xdg" / "nlsid" / "numba"
    assert got["caching"] and got["locator"] == "UserProvidedCacheLocator"
    assert Path(got["path"]).parent == folder
    assert any(p.name.startswith("kernels.apply_block") for p in folder.rglob("*.nbi")), list(folder.rglob("*"))


def test_a_fresh_process_with_nowhere_to_write_runs_uncached_and_says_so(tmp_path, blocked):
    """Home and XDG cache unwritable, the temp fallback refused (open to all): the kernels still
    import and compute (numba would have raised 'no locator available' on a read-only install, or
    written into the package), uncached, and the debug log says so."""
    (tmp_path / "tmp" / UID).mkdir(parents=True)
    (tmp_path / "tmp" / UID).chmod(0o777)
    got = kernel_in_fresh_process({"HOME": str(blocked), "XDG_CACHE_HOME": str(blocked / "xdg"),
                                   "TMPDIR": str(tmp_path / "tmp")})
    assert got["y"] == BACKLASH_Y
    assert got["caching"] is False and got["path"] is None
    assert "kernels run uncached" in got["log"], got["log"]
    assert not list(tmp_path.rglob("*.nbi"))
