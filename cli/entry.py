"""The console-script entry point, kept apart from the click application so that an interrupt
during start-up (while the commands are imported) also ends in one line and exit code 130."""

import sys

EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report an interrupted command


def main() -> None:
    try:
        from .main import cli

        cli.main(prog_name="nlsid")
    except KeyboardInterrupt:
        sys.stderr.write("nlsid: interrupted\n")
        sys.exit(EXIT_INTERRUPTED)
