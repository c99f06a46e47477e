"""A bounded memo of computed arrays: the fits ask for the same columns and covariance forms many times (each
model-search step, each re-selection of the online report, each gap profile), and each costs far more than a
lookup. Keys must be hashable; values are treated as read-only. When full (``maxsize`` values, or ``max_bytes`` of
array values), the memo forgets everything (the working set of one analysis is below the bound, so a full memo
means the inputs moved on)."""

from __future__ import annotations

import ctypes
import ctypes.util
from typing import Callable, Hashable


def release_free_memory() -> None:
    """Give the heap's free pages back to the system (glibc ``malloc_trim``; nothing elsewhere). Arrays between
    1 and 32 MB come from the heap once one of that size was freed, and the small memo values left between them
    keep the freed pages resident: on a 1 M-sample record the resident size grows by ~10 MB per axis without
    this."""
    global _LIBC
    if _LIBC is None:
        name = ctypes.util.find_library("c")
        try:
            _LIBC = ctypes.CDLL(name) if name else False
        except OSError:
            _LIBC = False
    trim = getattr(_LIBC, "malloc_trim", None) if _LIBC else None
    if trim is not None:
        trim(0)


_LIBC = None  # the C library once looked up (False: none with malloc_trim)


class BoundedMemo:
    """``memo.get(key, compute)``: the value remembered for ``key``, else ``compute()`` remembered (an array
    value made read-only when ``read_only``: the callers share it)."""

    def __init__(self, maxsize: int, read_only: bool = False, max_bytes: int | None = None):
        self.maxsize = int(maxsize)
        self.read_only = read_only
        self.max_bytes = max_bytes
        self._bytes = 0
        self._values: dict = {}

    def get(self, key: Hashable, compute: Callable[[], object]):
        value = self._values.get(key)
        if value is None:
            value = compute()
            size = int(getattr(value, "nbytes", 0))
            if len(self._values) >= self.maxsize or (self.max_bytes is not None
                                                     and self._bytes + size > self.max_bytes):
                self.clear()
            if self.read_only:
                value.setflags(write=False)
            self._values[key] = value
            self._bytes += size
        return value

    def peek(self, key: Hashable):
        """The value remembered for ``key``, else None."""
        return self._values.get(key)

    def __len__(self) -> int:
        return len(self._values)

    def clear(self) -> None:
        self._values.clear()
        self._bytes = 0
