"""The console-script entry point, kept apart from the click application so that an interrupt
during start-up (while the commands are imported) also ends in one line and exit code 130."""

import gc
import os
import signal
import sys

EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report an interrupted command


def main() -> None:
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
