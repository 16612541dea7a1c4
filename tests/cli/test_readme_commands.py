"""The README's two commands, in order, in one fresh virtual environment (issue #14).

The commands are read from the README's ``sh`` blocks, so the test runs what a new user runs:
``pip install . && nlsid run configs/pipeline_stage.yaml`` in a copy of the checkout, then the
install part of ``pip install -e '.[test]' && pytest`` in the same environment, and instead of the
whole suite (no pytest inside pytest) the collection of it, ``pytest --collect-only -q``.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
STEP_TIMEOUT = 1200  # s, per command (a cold pip install on a slow link)


def readme_commands() -> list[list[list[str]]]:
    """The README's ``sh`` blocks, each a list of its ``&&``-joined commands as argument lists."""
    blocks = re.findall(r"```sh\n(.*?)```", (REPO / "README.md").read_text(), re.S)
    return [[shlex.split(part) for part in block.strip().split("&&")] for block in blocks]


def cache_files(folder: Path) -> dict[Path, int]:
    """numba's cache files (index .nbi, code .nbc) below ``folder``, with their modification times."""
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*") if p.suffix in (".nbi", ".nbc")}


def outer_pip_cache() -> str:
    out = subprocess.run([sys.executable, "-m", "pip", "cache", "dir"], capture_output=True, text=True)
    if out.returncode == 0 and out.stdout.strip():
        return out.stdout.strip()
    return os.environ.get("PIP_CACHE_DIR") or str(Path.home() / ".cache" / "pip")


@pytest.mark.slow
def test_the_readme_commands_in_order_in_one_fresh_venv(tmp_path):
    """What a new user does: install and run the pipeline, then install for development and test.

    On the code before issue #14 this fails twice over: numba wrote the kernels' compiled code
    (.nbi/.nbc) into site-packages/nlsid/simulate/__pycache__, where the first assertion on the
    venv looks; and ``pip install -e`` then left that folder behind (pip uninstalls only the files
    it installed), so the ``nlsid`` folder without ``__init__.py`` became a namespace package that
    the import system finds before the editable install's finder: ``nlsid --version`` failed with
    "cannot import name '__version__' from 'nlsid' (unknown location)" and the collection exited 4.
    The compiled code must be in the user cache instead ($XDG_CACHE_HOME/nlsid/numba, pointed into
    tmp_path with HOME), and a new process that reruns a step (the simulate step, its output
    deleted) must load it from there (no cache file rewritten). Runs the whole pipeline cold, so it
    takes minutes; the times are printed (-s).
    """
    (install, run), (dev_install, test) = readme_commands()
    assert install[:2] == ["pip", "install"] and run[:2] == ["nlsid", "run"], (install, run)
    assert dev_install[:3] == ["pip", "install", "-e"] and test == ["pytest"], (dev_install, test)

    venv = tmp_path / "venv"
    made = subprocess.run([sys.executable, "-m", "venv", str(venv)], capture_output=True, text=True)
    if made.returncode != 0:
        pytest.skip(f"python -m venv is unavailable here: {made.stderr.strip().splitlines()[-1:]}")
    try:
        urllib.request.urlopen("https://pypi.org/simple/pip/", timeout=20).close()
    except OSError as exc:
        pytest.skip(f"PyPI (https://pypi.org) cannot be reached from here: {exc}")

    # The checkout's files as a clone of it would have them: tracked, and new ones not ignored (the
    # same as tracked on a clean checkout, as in CI).
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"], cwd=REPO,
                            capture_output=True, text=True, check=True).stdout.split("\0")
    tree = tmp_path / "nlsid"
    for name in filter(None, listed):
        if (REPO / name).is_file():  # a tracked file deleted in the working tree is left out
            (tree / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, tree / name)
    assert (tree / "nlsid" / "simulate" / "kernels.py").is_file()

    user_cache = tmp_path / "home" / ".cache"
    outer_config = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH", "PYTHONHOME",
                                                             "VIRTUAL_ENV", "PYTHONSTARTUP")}
    env.update(HOME=str(tmp_path / "home"), XDG_CACHE_HOME=str(user_cache), MPLBACKEND="Agg",
               PATH=f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
               PIP_CACHE_DIR=outer_pip_cache(),  # the downloads of this machine, not a fresh home's
               XDG_CONFIG_HOME=outer_config)  # pip's user configuration (an index mirror) as well
    times: dict[str, float] = {}

    def sh(label: str, argv: list[str], check: bool = True) -> subprocess.CompletedProcess:
        exe = shutil.which(argv[0], path=str(venv / "bin"))
        assert exe, f"{argv[0]} is not in the venv"
        started = time.perf_counter()
        out = subprocess.run([exe, *argv[1:]], cwd=tree, env=env, capture_output=True, text=True,
                             timeout=STEP_TIMEOUT)
        times[label] = time.perf_counter() - started
        if check:
            assert out.returncode == 0, f"{shlex.join(argv)} exited {out.returncode}:\n{out.stdout}\n{out.stderr}"
        return out

    sh("pip install .", install)
    first = sh("nlsid run (first)", run)
    site = sorted({p.resolve() for p in venv.glob("lib*/python*/site-packages")})  # lib64 may link to lib
    assert site and (site[0] / "nlsid" / "simulate" / "kernels.py").is_file(), "not a regular install"
    in_package = sorted(str(p.relative_to(folder)) for folder in site for p in cache_files(folder))
    assert not in_package, f"{len(in_package)} compiled-code files inside site-packages: {in_package[:4]}"
    cached = cache_files(user_cache / "nlsid" / "numba")
    assert any(p.name.startswith("kernels.") and p.suffix == ".nbi" for p in cached), list(cached)
    assert (tree / "out" / "report.html").is_file()

    outputs = {p: p.stat().st_mtime_ns for p in (tree / "out").rglob("*") if p.is_file()}
    sh("nlsid run (up to date)", run)
    assert {p: p.stat().st_mtime_ns for p in (tree / "out").rglob("*") if p.is_file()} == outputs
    # A new process that needs the kernels again loads them from the user cache. One step's output
    # deleted is enough to show it (the simulate step runs the model through the kernels); redoing
    # the whole pipeline here cost a minute of the suite for the same check.
    (tree / "out" / "model_recording.h5").unlink()
    warm = sh("nlsid run (warm, simulate redone)", run)
    assert (tree / "out" / "model_recording.h5").is_file(), warm.stderr[-2000:]
    assert cache_files(user_cache / "nlsid" / "numba") == cached, "the warm run compiled again"

    sh("pip install -e '.[test]'", dev_install)
    version = re.search(r'^version = "(.+)"', (tree / "pyproject.toml").read_text(), re.M).group(1)
    shown = sh("nlsid --version", ["nlsid", "--version"], check=False)
    assert shown.returncode == 0 and version in shown.stdout, (shown.stdout, shown.stderr)
    # `pytest`, as the README says (not `python -m pytest`, which would put the checkout's own
    # nlsid/ first on sys.path and hide a shadowed install: on the old code it exited 0, `pytest` 4)
    collected = sh("pytest --collect-only", [*test, "--collect-only", "-q"], check=False)
    assert collected.returncode == 0, collected.stdout[-3000:] + collected.stderr[-3000:]
    count = re.search(r"^(\d+) tests? collected", collected.stdout, re.M)
    assert count and int(count.group(1)) > 100, collected.stdout[-500:]

    print("\nREADME commands, fresh venv: " + "; ".join(f"{k} {v:.1f} s" for k, v in times.items()))
    print("first run's steps:\n" + first.stderr[-2500:] + "\nwarm run's steps:\n" + warm.stderr[-2500:])
