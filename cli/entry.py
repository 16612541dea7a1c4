"""The console-script entry point, kept apart from the click application so that an interrupt
during start-up (while the commands are imported) also ends in one line and exit code 130."""

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
        raise
