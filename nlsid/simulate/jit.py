"""numba for nlsid's kernels, with the compiled code cached per user, never inside the package.

Every numba import in nlsid goes through this module: it picks the cache folder and hands it to
numba in ``NUMBA_CACHE_DIR`` before it imports numba, and :func:`njit` is ``numba.njit``.

Why: by default numba writes a ``cache=True`` function's compiled code (a ``.nbi`` index and
``.nbc`` code files) into the ``__pycache__`` folder next to its source file. For an installed
nlsid that is site-packages/nlsid/simulate/__pycache__, which pip does not know about: ``pip
uninstall`` (and so the reinstall of ``pip install -e .``) leaves the folder behind, and the
``nlsid`` folder around it, now without ``__init__.py``, is a namespace package that shadows the
editable install (``cannot import name '__version__' from 'nlsid' (unknown location)``).

The cache folder is the first of these that is writable:

1. ``NUMBA_CACHE_DIR``, if set (then it holds all numba code of the process, as the user asked);
2. ``$XDG_CACHE_HOME/nlsid/numba``, or ``~/.cache/nlsid/numba`` when XDG_CACHE_HOME is unset or
   not absolute;
3. ``nlsid-UID/numba`` in the temp folder (a home that cannot be written, such as a service
   account's), if that folder is this user's and private: the cache files are pickles, and loading
   ones another user planted would run their code.

If none is, the kernels run uncached (compiled anew in every process). The choice is logged at
debug level on the ``nlsid`` logger (``nlsid -vv``).

numba's own fallbacks do not do this (numba 0.68, numba/core/caching.py): the locator for
``NUMBA_CACHE_DIR`` creates the folder and writes a temporary file in it, and if that fails it
silently moves on to the in-tree ``__pycache__`` (the package again), then to ``~/.cache/numba``;
if none can be written, decorating a ``cache=True`` function raises RuntimeError ("no locator
available"), so a read-only install with an unwritable home would not even import. numba reads
``NUMBA_CACHE_DIR`` when it is imported and again when it compiles (config.reload_config), and
chooses a function's folder when it is decorated; if numba was imported before this module, its
configuration is reloaded here so that nlsid's kernels see the folder chosen.

The folder's sub-folders are named after the source folder's path (numba hashes it), so a regular
and an editable install of nlsid never share entries, and an entry is stale once its source file's
content changes (numba stores the file's hash). Kernel variants built at run time keep their own
names (:func:`nlsid.simulate.kernels._make_loop`), so they keep separate entries here as well.
"""

from __future__ import annotations

import logging
import os
import stat
import sys
import tempfile
from collections.abc import Mapping
from pathlib import Path

LOGGER = logging.getLogger("nlsid")


def writable(folder: Path) -> bool:
    """numba's own test of a cache folder (``_CacheLocator.ensure_cache_path``): it can be created
    and a temporary file can be written in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def user_cache_folder(environ: Mapping[str, str]) -> Path:
    """``$XDG_CACHE_HOME/nlsid/numba``, or ``~/.cache/nlsid/numba`` (the XDG default)."""
    xdg = environ.get("XDG_CACHE_HOME", "")
    if os.path.isabs(xdg):
        return Path(xdg) / "nlsid" / "numba"
    home = environ.get("HOME") or os.path.expanduser("~")
    return Path(home) / ".cache" / "nlsid" / "numba"


def temp_cache_folder() -> Path | None:
    """``nlsid-UID/numba`` in the temp folder, or None if that folder cannot be made or is not a
    directory of this user's that only this user can write (and read)."""
    own = hasattr(os, "getuid")  # elsewhere (Windows) the temp folder is the user's own already
    base = Path(tempfile.gettempdir()) / (f"nlsid-{os.getuid()}" if own else "nlsid")
    try:
        base.mkdir(mode=0o700, exist_ok=True)
        st = base.lstat()
    except OSError:
        return None
    if own and (not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & 0o077):
        LOGGER.debug("numba cache: %s is not a private folder of this user's; not used", base)
        return None
    return base / "numba"


def choose_cache_folder(environ: Mapping[str, str]) -> Path | None:
    """The first writable folder of the module docstring's list, None if there is none."""
    candidates = []
    if environ.get("NUMBA_CACHE_DIR"):
        candidates.append(("NUMBA_CACHE_DIR", Path(environ["NUMBA_CACHE_DIR"])))
    candidates.append(("the user cache", user_cache_folder(environ)))
    for origin, folder in candidates:
        if writable(folder):
            LOGGER.debug("numba cache: %s (%s)", folder, origin)
            return folder
        LOGGER.debug("numba cache: %s (%s) cannot be written", folder, origin)
    folder = temp_cache_folder()
    if folder is not None and writable(folder):
        LOGGER.debug("numba cache: %s (the temp folder, as no other could be written)", folder)
        return folder
    LOGGER.debug("numba cache: no folder can be written; kernels run uncached (compiled in every process)")
    return None


def _configure() -> bool:
    """Set ``NUMBA_CACHE_DIR`` for this process (and its children); False if running uncached."""
    folder = choose_cache_folder(os.environ)
    if folder is None:
        return False
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # imported before nlsid: make it read the folder now
        sys.modules["numba"].core.config.reload_config()
    return True


CACHING = _configure()

import numba  # noqa: E402  (after NUMBA_CACHE_DIR is set)


def njit(*args, **options):
    """``numba.njit``, with ``cache`` switched off when no cache folder can be written."""
    if not CACHING:
        options["cache"] = False
    return numba.njit(*args, **options)
