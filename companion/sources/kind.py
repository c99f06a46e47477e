"""Which kind of source a spec names: the one rule that load, run (replay or live), replay and fleet
discovery all use, so that a file one command reads is read the same way by every other.

The kind comes from the name: a log suffix (optionally followed by ``.gz``), else a connection string.
Tlog names are tested before DataFlash ``.bin`` because MAVProxy/QGC also write ``.tlog.bin``.
"""

from __future__ import annotations

#: kind -> file-name suffixes (lower case, without a trailing ``.gz``), in the order they are tested
FILE_SUFFIXES = {
    "tlog": (".tlog", ".tlog.bin", ".mavlink"),
    "csv": (".csv",),
    "dataflash": (".bin",),
    "ulog": (".ulg",),
}
FILE_KINDS = tuple(FILE_SUFFIXES)
KINDS = FILE_KINDS + ("connection", "unknown")
#: every log file name suffix, plain and gzip-compressed (what fleet discovery takes from folders and globs)
LOG_SUFFIXES = tuple(s + gz for suffixes in FILE_SUFFIXES.values() for s in suffixes for gz in ("", ".gz"))


def file_kind(name) -> str | None:
    """The kind of a log file name (``tlog``, ``csv``, ``dataflash``, ``ulog``), or None."""
    low = str(name).lower()
    if low.endswith(".gz"):
        low = low[:-3]
    for kind, suffixes in FILE_SUFFIXES.items():
        if low.endswith(suffixes):
            return kind
    return None


def is_gzip(name) -> bool:
    """True for a gzip-compressed log name (``.gz``): every reader opens those through gzip."""
    return str(name).lower().endswith(".gz")


def kind_of(spec) -> str:
    """``tlog``, ``dataflash``, ``ulog``, ``csv`` (by file name, each maybe ``.gz``), ``connection`` (a
    network link or serial device, :func:`companion.sources.connection.is_connection_string`) or ``unknown``."""
    kind = file_kind(spec)
    if kind is not None:
        return kind
    from companion.sources.connection import is_connection_string

    return "connection" if is_connection_string(str(spec)) else "unknown"
