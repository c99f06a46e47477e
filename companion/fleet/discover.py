"""Which files a ``fleet analyze LOGS...`` argument list names, and their content hashes.

Every argument is a file, a folder (searched recursively) or a glob pattern (``**`` allowed). Only
files whose names end in a supported log suffix are taken from folders and globs; a file named
explicitly is always taken (its reader then says what is wrong with it). The suffix list follows what
:func:`companion.sources.load` reads; formats added there (DataFlash ``.bin``, ULog ``.ulg``) are
listed here so that folders of them are found once their readers land.

Content hash: BLAKE2b with a 16-byte digest over the file's bytes (``hash_file``). The database keys a
log by it, so a renamed or copied log is still recognised. Hashing a 3.5 MB ten-minute tlog takes
a few milliseconds; :func:`hash_files` runs several files in threads (hashlib releases the GIL).
"""

from __future__ import annotations

import glob
import hashlib
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from companion.errors import CompanionError
from companion.sources.kind import LOG_SUFFIXES as _LOG_SUFFIXES
from companion.sources.kind import file_kind

#: log suffixes taken from folders and globs (lower case): every kind companion.sources.kind_of names
LOG_SUFFIXES = _LOG_SUFFIXES
#: the short format names the fleet store keeps, per source kind
FORMAT_NAMES = {"tlog": "tlog", "csv": "csv", "dataflash": "bin", "ulog": "ulg"}
_GLOB_CHARS = set("*?[")


@dataclass(frozen=True)
class LogFile:
    """A log file found on disk: absolute path, size in bytes and modification time (unix s)."""

    path: str
    size: int
    mtime: float


def is_log_name(name: str) -> bool:
    return file_kind(name) is not None


def log_format(path: str) -> str:
    """Short format name from the file name: tlog, csv, bin, ulg (or the suffix)."""
    kind = file_kind(path)
    if kind is not None:
        return FORMAT_NAMES[kind]
    low = path.lower()
    if low.endswith(".gz"):
        low = low[:-3]
    return Path(low).suffix.lstrip(".") or "unknown"


def _stat(path: str) -> LogFile:
    st = os.stat(path)
    return LogFile(os.path.abspath(path), int(st.st_size), float(st.st_mtime))


def discover(args) -> list[LogFile]:
    """Log files named by ``args`` (files, folders, globs), sorted by path, without duplicates.

    An argument that names nothing (a missing file, a folder without logs, a glob matching nothing)
    raises :class:`CompanionError`: a typo must not silently analyse fewer logs.
    """
    found: dict[str, LogFile] = {}
    for arg in args:
        arg = str(arg)
        hits: list[str] = []
        if os.path.isdir(arg):
            for root, dirs, files in os.walk(arg):
                dirs.sort()
                hits += [os.path.join(root, f) for f in sorted(files) if is_log_name(f)]
            if not hits:
                raise CompanionError(f"{arg}: no log files in this folder (looked for {', '.join(LOG_SUFFIXES)})")
        elif os.path.isfile(arg):
            hits = [arg]
        elif _GLOB_CHARS & set(arg):
            hits = [p for p in sorted(glob.glob(arg, recursive=True)) if os.path.isfile(p) and is_log_name(p)]
            if not hits:
                raise CompanionError(f"{arg}: the pattern matches no log file")
        else:
            raise CompanionError(f"{arg}: no such file or folder")
        for p in hits:
            try:
                lf = _stat(p)
            except OSError as exc:
                raise CompanionError(f"{p}: cannot read ({exc.strerror or exc})") from None
            found.setdefault(lf.path, lf)
    return [found[k] for k in sorted(found)]


def hash_bytes(data: bytes) -> str:
    return hashlib.blake2b(data, digest_size=16).hexdigest()


def hash_file(path: str, chunk: int = 1 << 20, prefix: int | None = None):
    """BLAKE2b-128 hex digest of the file's content; with ``prefix`` (bytes), ``(digest, digest of the
    first prefix bytes)`` in the same read (a log that grew since it was analysed: is the old content
    its beginning?). The prefix digest is None when the file is shorter than ``prefix``."""
    h = hashlib.blake2b(digest_size=16)
    head = hashlib.blake2b(digest_size=16) if prefix is not None else None
    seen = 0
    with open(path, "rb") as fh:
        while True:
            b = fh.read(chunk)
            if not b:
                break
            if head is not None and seen < prefix:
                head.update(b[:prefix - seen])
            seen += len(b)
            h.update(b)
    if head is None:
        return h.hexdigest()
    return h.hexdigest(), (head.hexdigest() if seen >= prefix else None)


def hash_files(paths, threads: int = 4, prefixes: dict | None = None) -> dict:
    """``{path: hex digest}`` for many files (an unreadable file maps to its OSError); a path in
    ``prefixes`` (``{path: bytes}``) maps to ``(digest, digest of its first bytes)`` (:func:`hash_file`)."""
    prefixes = prefixes or {}

    def one(p):
        try:
            return p, hash_file(p, prefix=prefixes.get(p))
        except OSError as exc:
            return p, exc

    paths = list(paths)
    if len(paths) < 4 or threads <= 1:
        return dict(one(p) for p in paths)
    with ThreadPoolExecutor(max_workers=threads) as ex:
        return dict(ex.map(one, paths))


def hash_chunk(paths, prefixes: dict | None = None) -> dict:
    """``{path: hex digest, (digest, prefix digest) or "error: reason"}``: a Dask task hashing files where
    they are stored (``prefixes`` as in :func:`hash_files`)."""
    out = {}
    for p, h in hash_files(paths, threads=2, prefixes=prefixes).items():
        out[p] = h if isinstance(h, (str, tuple)) else f"error: {getattr(h, 'strerror', None) or h}"
    return out
