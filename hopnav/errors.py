"""The command line's one error convention.

Every user-facing failure of a ``hopnav`` command is one line on stderr,
``hopnav COMMAND: what went wrong, and where`` (the file, key, line or argument), and an exit
code: 2 for bad input (arguments, files, settings: nothing was done), 1 for a run that
started and did not complete (a failed or interrupted run: what had finished is kept). No
traceback reaches the user; ``HOPNAV_DEBUG=1`` lets an unexpected one through.

Commands raise :class:`UsageError` or :class:`RunFailed`; :func:`hopnav.cli.main` prints and
maps them.
"""

from __future__ import annotations

#: Exit code of bad input.
EXIT_USAGE = 2
#: Exit code of a run that started and did not complete.
EXIT_FAILED = 1


class CommandError(Exception):
    """A failure reported as one line on stderr, then ``exit_code``."""

    exit_code = EXIT_FAILED

    def one_line(self) -> str:
        """The message on one line (later lines joined with ``"; "``)."""
        return "; ".join(part.strip() for part in str(self).splitlines() if part.strip())


class UsageError(CommandError):
    """Bad input: an argument, a file or a setting (exit code 2, before any work)."""

    exit_code = EXIT_USAGE


class RunFailed(CommandError):
    """The work started and did not complete (exit code 1); finished results are kept."""

    exit_code = EXIT_FAILED


def is_interrupt(err: BaseException) -> bool:
    """Whether ``err`` is a Ctrl-C: a :class:`KeyboardInterrupt`, or the ``SystemError``
    CPython raises when the interrupt's handler ran inside a compiled (numba) function
    ("returned a result with an exception set"), whose cause chain holds the interrupt."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False
