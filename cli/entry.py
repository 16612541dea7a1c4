"""The console-script entry point, kept apart from the click application so that an interrupt
during start-up (while the commands are imported) also ends in one line and exit code 130."""

import gc
import os
import signal
import sys

from nlsid.errors import EXIT_INTERRUPTED


def _interrupt_again(unraisable) -> None:
    """``sys.unraisablehook``: an interrupt that lands in a finalizer or a weakref callback during a
    garbage collection is, for Python, an exception it cannot raise: it prints "Exception ignored
    in ... Traceback ... KeyboardInterrupt" and goes on. Delivered again, by a thread once this
    hook has returned (raised in the hook, it would be another exception Python cannot raise), it
    ends the command as any interrupt does (one line, exit 130); other such exceptions go to
    Python's hook."""
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        import _thread

        _thread.start_new_thread(_thread.interrupt_main, ())  # not threading's: its start() waits
    else:
        sys.__unraisablehook__(unraisable)


def main() -> None:
    sys.unraisablehook = _interrupt_again
    # One BLAS thread unless the user says otherwise: nlsid's matrix products are small or run in
    # its own worker threads, and OpenBLAS's spinning helpers cost a core for nothing (bla spent
    # twice the CPU with them, benchmarks/bla.py). Set before numpy is first imported.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        from .main import cli

        cli.main(prog_name="nlsid")
    except KeyboardInterrupt:
        sys.stderr.write("nlsid: interrupted\n")
        sys.exit(EXIT_INTERRUPTED)
    except SystemExit:
        # The command is done, its outputs written and its exit code set: an interrupt now would
        # only cut the interpreter's teardown short and replace that code by a signal.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        # Nor need the teardown's garbage collections trace the ~30k objects of numpy, h5py, rich
        # and click once more (0.05-0.1 s of `nlsid bla`, benchmarks/bla.py): frozen, they are
        # left out of those collections; atexit handlers still run and the modules are still cleared.
        gc.freeze()
        raise
