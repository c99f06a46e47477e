"""User-facing errors.

Anything a user can cause (missing file, bad YAML, unknown connection string, a log without IMU data)
is raised as :class:`CompanionError`; the CLI prints ``companion: error: <message>`` on one line and
exits with ``exit_code`` (2 by default). Never a traceback for bad input.

The exit statuses of every command (README "Exit status"; docs/errors.md) are named here, so the CLI,
the service and the fleet use one table. 1 is left to Python (an uncaught exception, a bug): a script that
gates on :data:`EXIT_FAULTS` must not take a crash for a finding.
"""

EXIT_OK = 0  #: done, and every IMU looked at is healthy
EXIT_USAGE = 2  #: a usage error or bad input (one line ``companion: error: ...``)
EXIT_TIME_LIMIT = 3  #: ``fleet analyze`` stopped at its --time-limit (rerun to resume)
EXIT_FAULTS = 4  #: done, and a gyro fault or degradation was found (dead, stuck, saturated, a rising trend ...)
EXIT_NO_DATA = 5  #: done, but nothing usable: no IMU data arrived, every log failed, every stream unusable
EXIT_NUMERICS = 6  #: ``compensate``: a filter's covariance factor lost validity (results written, warned)
EXIT_INTERRUPTED = 130  #: Ctrl-C (128 + SIGINT)
EXIT_TERMINATED = 143  #: SIGTERM (128 + SIGTERM)


class CompanionError(Exception):
    """An error caused by the user's input, reported as one line and a non-zero exit."""

    def __init__(self, message: str, exit_code: int = 2):
        super().__init__(message)
        self.exit_code = exit_code


class NoUsableData(CompanionError):
    """The input was read but held nothing to work on: no IMU message in a log, nothing on a live link,
    every stream unusable. One line, exit status :data:`EXIT_NO_DATA`."""

    def __init__(self, message: str):
        super().__init__(message, EXIT_NO_DATA)


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

    exit_code = EXIT_TERMINATED
