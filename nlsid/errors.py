"""Errors a user can cause, and the exit codes they map to.

Every error a user can provoke (bad config, bad file, impossible request) is raised as an
:class:`InputError` with one line naming the file, the key or dataset, and what was expected.
The command line turns it into that one line on stderr and exit code 2, never a traceback.
"""

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2


class NlsidError(Exception):
    """Base class of the errors nlsid reports to a user without a traceback."""

    exit_code = EXIT_BAD_INPUT


class InputError(NlsidError):
    """Bad usage or bad input: a config, a file, a dataset or an impossible request.

    ``where`` names the file (and optionally the key path or dataset) so the message reads
    ``where: what``.
    """

    def __init__(self, where: str, what: str):
        self.where = str(where)
        self.what = what
        super().__init__(f"{self.where}: {what}" if self.where else what)


class CheckFailed(NlsidError):
    """A check the user asked for (e.g. a ``--fail-if`` threshold) did not pass."""

    exit_code = EXIT_CHECK_FAILED
