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
