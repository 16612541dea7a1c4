"""Errors a user can cause, and the exit codes they map to.

Every error a user can provoke (bad config, bad file, impossible request) is raised as an
:class:`InputError` with one line naming the file, the key or dataset, and what was expected.
The command line turns it into that one line on stderr and exit code 2, never a traceback.
"""

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report an interrupted command


def one_line(text: str) -> str:
    """``text`` with every character that would break or garble a terminal line (newlines, the
    other line separators str.splitlines knows, control characters) written as an escape, e.g.
    ``\\x1e``: names from a user's file, quoted in a message, must not split its one line."""
    return "".join(ch if ch.isprintable() or ch == " " else
                   (f"\\x{ord(ch):02x}" if ord(ch) < 0x100 else f"\\u{ord(ch):04x}" if ord(ch) < 0x10000 else
                    f"\\U{ord(ch):08x}") for ch in text)


class NlsidError(Exception):
    """Base class of the errors nlsid reports to a user without a traceback."""

    exit_code = EXIT_BAD_INPUT


class InputError(NlsidError, ValueError):
    """Bad usage or bad input: a config, a file, a dataset, an argument or an impossible request.

    ``where`` names the file (and optionally the key path or dataset), or the argument of a library
    function, so the message reads ``where: what``. It is a ``ValueError``, as scipy's and numpy's
    errors of a bad argument are, so ``except ValueError`` in a user's script catches it.

    Parameters
    ----------
    where : str
        The file (with its key path or dataset), or the argument, at fault; "" for none.
    what : str
        What was expected and what was found.

    Attributes
    ----------
    where, what : str
        The two parts, each on one line: newlines and other control characters are written as
        escapes (``\\x0a``), so a name quoted from a user's file cannot break the message's line.
    exit_code : int
        2, the command line's exit code of bad input (:data:`EXIT_BAD_INPUT`).

    Examples
    --------
    >>> from nlsid.errors import InputError
    >>> error = InputError("confidence", "expected a probability in (0, 1), got 1.5")
    >>> str(error), isinstance(error, ValueError)
    ('confidence: expected a probability in (0, 1), got 1.5', True)
    >>> InputError("stage.h5:/runs/a\\nb", "no y").where
    'stage.h5:/runs/a\\\\x0ab'
    >>> import nlsid
    >>> try:
    ...     nlsid.design({"fs": -1.0, "multisine": {"period": 100, "band": [1.0, 10.0]}})
    ... except nlsid.InputError as error:
    ...     print(error.where, error.exit_code)
    fs 2
    """

    def __init__(self, where: str, what: str):
        self.where = one_line(str(where))
        self.what = one_line(what)
        super().__init__(f"{self.where}: {self.what}" if self.where else self.what)


class CheckFailed(NlsidError):
    """A check the user asked for (e.g. a ``--fail-if`` threshold) did not pass; the message reads
    ``where: what``, as for :class:`InputError` (two arguments gave a tuple's repr before)."""

    exit_code = EXIT_CHECK_FAILED

    def __init__(self, where: str, what: str):
        self.where = one_line(str(where))
        self.what = one_line(what)
        super().__init__(f"{self.where}: {self.what}" if self.where else self.what)
