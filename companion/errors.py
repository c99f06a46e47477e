"""User-facing errors.

Anything a user can cause (missing file, bad YAML, unknown connection string, a log without IMU data)
is raised as :class:`CompanionError`; the CLI prints ``companion: error: <message>`` on one line and
exits with ``exit_code`` (2 by default). Never a traceback for bad input.
"""


class CompanionError(Exception):
    """An error caused by the user's input, reported as one line and a non-zero exit."""

    def __init__(self, message: str, exit_code: int = 2):
        super().__init__(message)
        self.exit_code = exit_code


def not_text(path, exc: UnicodeDecodeError, what: str) -> CompanionError:
    """The error for a binary file given where a text file (YAML, JSON) belongs: a log passed as a model,
    say. Which byte is not UTF-8 and where, so that a text file with one bad byte can be mended."""
    byte = exc.object[exc.start:exc.start + 1]
    code = f" (byte 0x{byte[0]:02x} at offset {exc.start} is not UTF-8)" if byte else ""
    return CompanionError(f"{path}: not a text file{code}: {what}")


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch system's time limit, systemd stopping a unit) turned into an exception
    that stops a run the way Ctrl-C does (what is recorded stays), with the shell's exit status for
    death by SIGTERM: 128 + 15."""

    exit_code = 143
