"""How many threads nlsid's simulations use, and numpy's BLAS kept out of their way.

Simulations run in a pool of :func:`thread_count` threads (:func:`nlsid.simulate.batch.simulate_all`;
the numba kernels release the GIL). Between the pool's batches the optimiser works in the main
thread with numpy, whose BLAS (OpenBLAS, MKL) starts threads of its own on every core and lets them
spin-wait after each call: on a machine whose cores the simulations already fill, those threads take
the cores from them. :func:`blas_in_one_thread` limits BLAS to one thread (threadpoolctl) while a
stage that interleaves both runs; the fits' matrices (tens of thousands of rows by a few columns) lose
nothing by it. Measured on 2 cores (``benchmarks/blas_threads.py``), ``diagnose`` on the battery's
Coulomb + cubic spring case (18 runs): 28.0 s with BLAS in two threads, 16.6 s in one.
"""

from __future__ import annotations

import functools
import os
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Callable, Iterator

from nlsid.errors import InputError

THREADS_VARIABLE = "NLSID_THREADS"  # the default number of simulation threads of a process
_threads: ContextVar[int | None] = ContextVar("nlsid_threads", default=None)


def thread_count(workers: int | None = None) -> int:
    """The simulation threads to use: ``workers`` when given, else the default of the command
    running (:func:`default_threads`, e.g. ``diagnose --workers``), else the environment's
    ``NLSID_THREADS`` (``nlsid batch`` sets it to cores / worker processes in its workers), else
    every core."""
    default = workers or _threads.get()
    if default:
        return default
    text = os.environ.get(THREADS_VARIABLE, "").strip()
    if text:
        if not text.isdigit() or int(text) < 1:
            raise InputError(THREADS_VARIABLE, f"expected a whole number of threads, 1 or more; got {text!r}")
        return int(text)
    return os.cpu_count() or 1


@contextmanager
def default_threads(workers: int | None) -> Iterator[None]:
    """Within the block, :func:`thread_count` without an explicit number gives ``workers`` (None:
    no command default, so ``NLSID_THREADS`` or every core)."""
    token = _threads.set(workers)
    try:
        yield
    finally:
        _threads.reset(token)


def blas_in_one_thread(function: Callable) -> Callable:
    """``function`` run with numpy's and scipy's BLAS limited to one thread (module docstring);
    the previous limits are restored when it returns, also when it raises. scipy's BLAS (a
    library of its own) is loaded first: a limit reaches only the libraries loaded when it is set,
    and the fits import scipy's optimiser lazily."""
    @functools.wraps(function)
    def limited(*args, **kwargs):
        import scipy.linalg  # noqa: F401  (loads scipy's BLAS, see above)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return function(*args, **kwargs)

    return limited


def in_threads(function: Callable, items: list, workers: int | None = None) -> list:
    """``[function(item) for item in items]`` in a pool of :func:`thread_count` threads (``workers``
    when given), in order (for numba kernels, which release the GIL); one item runs in the calling
    thread."""
    if len(items) < 2:
        return [function(item) for item in items]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=min(thread_count(workers), len(items))) as pool:
        return list(pool.map(function, items))
