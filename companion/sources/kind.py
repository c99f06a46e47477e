"""Which kind of source a spec names: the one rule that load, run (replay or live), replay and fleet
discovery all use, so that a file one command reads is read the same way by every other.

A file's kind comes from its content (:func:`content_kind`: magic bytes and structure, through gzip when the
file is gzip-compressed), with the name as a hint: where the content is not recognised the name decides (the
reader of that kind then says what is wrong with the file); where the two disagree the content wins and
:func:`decide` returns a one-line note naming both (a DataFlash text log, Mission Planner's ``.log``, is read as
DataFlash with such a note). A file that holds no log (a Git LFS pointer) is refused with what it is and what
to do. A spec that is not an existing file is classified by name: a log suffix (optionally followed by
``.gz``), else a connection string.
Tlog names are tested before DataFlash ``.bin`` because MAVProxy/QGC also write ``.tlog.bin``.
"""

from __future__ import annotations

import gzip
import re
import zlib
from dataclasses import dataclass
from pathlib import Path

from companion.errors import CompanionError
from companion.sources.dataflash_text import is_text_log

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
#: how a note names each kind's content
KIND_WORDS = {"tlog": "a MAVLink telemetry log (tlog)", "csv": "a CSV file", "dataflash": "a DataFlash log",
              "ulog": "a PX4 ULog"}
TEXT_LOG_WORD = "a DataFlash text log (Mission Planner .log)"  #: how a note names a text log's content
#: how the reading is named ("read as DataFlash")
KIND_NAMES = {"tlog": "tlog", "csv": "CSV", "dataflash": "DataFlash", "ulog": "ULog"}

GZIP_MAGIC = b"\x1f\x8b"  #: the first two bytes of every gzip member (RFC 1952)
ULOG_MAGIC = b"ULog\x01\x12\x35"  #: the first 7 bytes of a ULog file (PX4 ULog file format, header)
DATAFLASH_FMT = b"\xa3\x95\x80"  #: a DataFlash message header whose type is FMT (128): every .bin starts so
LFS_POINTER = b"version https://git-lfs.github.com/spec/v1"  #: the first line of a Git LFS pointer file
HEAD_BYTES = 65536  #: bytes of a file's (decompressed) start read to decide its kind: dozens of records
TLOG_RECORDS = 3  #: consecutive well-formed tlog records needed (chance of 3 in random bytes < 1e-7)
TLOG_SEARCH = 1024  #: a tlog may start mid-record (a capture joined late): look for the chain this far in
STAMP_BYTES = 8  #: a tlog record's big-endian unix-microsecond time stamp before each frame


@dataclass(frozen=True)
class Content:
    """What a file's start holds: one of :data:`FILE_KINDS` (or None: not recognised) and, for a file that
    cannot be read as a log at all, the one-line refusal."""

    kind: str | None
    gzip: bool = False
    refusal: str | None = None
    text: bool = False  # a DataFlash text log (Mission Planner .log)


@dataclass(frozen=True)
class Decision:
    """A spec's kind (:data:`KINDS`) and, when a file's name and content disagree, the note naming both."""

    kind: str
    note: str | None = None


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
    """True for a gzip-compressed log name (``.gz``)."""
    return str(name).lower().endswith(".gz")


def opens_as_gzip(path) -> bool:
    """True when a reader must open ``path`` through gzip: a ``.gz`` name (a damaged one then gets the
    gzip error) or a file that starts with the gzip magic whatever its name."""
    if is_gzip(path):
        return True
    try:
        with open(path, "rb") as fh:
            return fh.read(2) == GZIP_MAGIC
    except OSError:
        return False  # the reader reports what is wrong with the file


@dataclass(frozen=True)
class _Head:
    """A file's first :data:`HEAD_BYTES`, decompressed when it is gzip (None: a gzip stream cut short)."""

    data: bytes | None
    gzip: bool


def _head(path: Path) -> _Head | None:
    """The start of the file (see :class:`_Head`); None when the file cannot be read."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read(HEAD_BYTES)
        if not raw.startswith(GZIP_MAGIC):
            return _Head(raw, False)
        with gzip.open(path, "rb") as fh:
            try:
                return _Head(fh.read(HEAD_BYTES), True)
            except EOFError:
                return _Head(None, True)
    except (OSError, EOFError, zlib.error):
        return None


def _tlog_chain(head: bytes, start: int) -> bool:
    """True when :data:`TLOG_RECORDS` tlog records follow each other from ``start`` (or fewer up to the end
    of a short file): [8-byte stamp][0xFE len seq sys comp id payload crc2] (MAVLink 1, 8 + len bytes) or
    [0xFD len incompat compat seq sys comp id3 payload crc2 (sig13 when incompat bit 0)] (MAVLink 2)."""
    p, records = start, 0
    while records < TLOG_RECORDS:
        if p == len(head) and records:
            return True  # a short file that ends with a whole record
        if p + STAMP_BYTES + 3 > len(head):
            return False
        magic, length = head[p + STAMP_BYTES], head[p + STAMP_BYTES + 1]
        if magic == 0xFE:
            size = 8 + length
        elif magic == 0xFD and head[p + STAMP_BYTES + 2] in (0, 1):
            size = 12 + length + (13 if head[p + STAMP_BYTES + 2] & 1 else 0)
        else:
            return False
        p += STAMP_BYTES + size
        if p > len(head) and records + 1 < TLOG_RECORDS:
            return False
        records += 1
    return True


def _is_tlog(head: bytes) -> bool:
    return any(_tlog_chain(head, s) for s in range(min(TLOG_SEARCH, len(head)))
               if len(head) > s + STAMP_BYTES and head[s + STAMP_BYTES] in (0xFE, 0xFD))


def _has_dataflash_fmt(head: bytes) -> bool:
    """An FMT record in the head whose name is 4 printable bytes (a log whose start is damaged)."""
    for m in re.finditer(re.escape(DATAFLASH_FMT), head):
        name = head[m.start() + 5:m.start() + 9].rstrip(b"\0")
        if name and all(48 <= c < 123 for c in name):
            return True
    return False


def _text_kind(path: Path, head: bytes) -> Content:
    """A text file: a Git LFS pointer, a DataFlash text log, a CSV with a header naming ``time_s``."""
    if head.startswith(LFS_POINTER):
        size = re.search(rb"^size (\d+)", head, re.MULTILINE)
        what = f" of a {int(size.group(1)):,} byte file" if size else ""
        return Content(None, refusal=f"{path}: a Git LFS pointer{what}, not the log itself: fetch the log "
                                     "with `git lfs pull` (in the repository that holds it) and read it again")
    if is_text_log(head):
        return Content("dataflash", text=True)
    first = head.split(b"\n", 1)[0].decode("utf-8-sig", errors="replace").lower()
    if "time_s" in [c.strip() for c in first.split(",")]:
        return Content("csv")
    return Content(None)


def content_kind(path) -> Content | None:
    """The kind of an existing file from its first bytes (through gzip when it is compressed); None when it
    cannot be read (the reader then reports why)."""
    path = Path(path)
    got = _head(path)
    if got is None:
        return None
    head, gz = got.data, got.gzip
    if head is None:
        return Content(None, gz)
    if head.startswith(ULOG_MAGIC):
        return Content("ulog", gz)
    if head.startswith(DATAFLASH_FMT):
        return Content("dataflash", gz)
    if _is_tlog(head):
        return Content("tlog", gz)
    if _has_dataflash_fmt(head):
        return Content("dataflash", gz)
    c = _text_kind(path, head)
    return Content(c.kind, gz, c.refusal, c.text)


def decide(spec) -> Decision:
    """The kind of ``spec`` (see the module docstring) and the note when a file's name and content disagree.
    Raises :class:`CompanionError` for a file that holds no log (empty, a Git LFS pointer)."""
    by_name = file_kind(spec)
    path = Path(str(spec))
    if path.is_file():
        if path.stat().st_size == 0:
            raise CompanionError(f"{path}: empty file (0 bytes): no log to read")
        content = content_kind(path)
        if content is not None and content.refusal:
            raise CompanionError(content.refusal)
        if content is not None and content.kind is not None and (content.kind != by_name or content.text):
            kind = content.kind
            word = TEXT_LOG_WORD if content.text else KIND_WORDS[kind]
            return Decision(kind, f"{path.name}: the content is {word}; read as {KIND_NAMES[kind]}")
    if by_name is not None:
        return Decision(by_name)
    from companion.sources.connection import is_connection_string

    return Decision("connection" if is_connection_string(str(spec)) else "unknown")


def kind_of(spec) -> str:
    """``tlog``, ``dataflash``, ``ulog``, ``csv`` (an existing file by content, else by name, each maybe
    gzip-compressed), ``connection`` (a network link or serial device,
    :func:`companion.sources.connection.is_connection_string`) or ``unknown``; see :func:`decide`."""
    return decide(spec).kind
