"""A one-line progress bar on stderr (only on a terminal, only when the caller says the input is long)."""

from __future__ import annotations

import sys


class Progress:
    """``NAME [#####.....] 3/6 label``, redrawn in place; ``close()`` clears the line."""

    def __init__(self, name: str, total: int, enabled: bool):
        self.name = name
        self.total, self.done = max(total, 1), 0
        self.enabled = enabled and sys.stderr.isatty()

    def step(self, label: str):
        self.done += 1
        if self.enabled:
            k = int(30 * self.done / self.total)
            sys.stderr.write(f"\r{self.name} [{'#' * k}{'.' * (30 - k)}] {self.done}/{self.total} {label:<28}")
            sys.stderr.flush()

    def close(self):
        if self.enabled:
            sys.stderr.write(f"\r{' ' * 80}\r")
            sys.stderr.flush()
