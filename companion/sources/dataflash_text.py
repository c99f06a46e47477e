"""ArduPilot DataFlash logs in text (Mission Planner's ``.log``, ``mavlogdump.py --format`` output): one message a
line, ``NAME, value, value, ...``, the layouts given by ``FMT, type, length, name, format, columns`` lines.

Each line is packed into the binary layout its FMT gives (``[0xA3 0x95 type][body]``), so the binary reader
(:mod:`companion.sources.dataflash`) reads the text log with the same rules and the same numbers. The text holds
the values DFReader prints: scaled formats (``c/C/e/E`` x 100, ``L`` x 1e7) are multiplied back; a flight mode
(``M``) printed by name is stored as 0 (its ``ModeNum`` column keeps the number). Lines that do not fit their
layout (a wrong count of values, a value that is no number) are skipped and counted, as DFReader does.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

HEAD = b"\xa3\x95"  #: the binary message header
FMT_TYPE = 0x80  #: FMT's own type
#: a DataFlash text log line that defines a layout: ``FMT, type, length, name, format, columns``
TEXT_FMT_LINE = re.compile(rb"^FMT, *\d+, *\d+, *[A-Za-z0-9_]+, *[A-Za-z]+,", re.MULTILINE)
#: format character -> (struct code, the factor the text value is multiplied by; None: an integer as written)
_PACK = {"b": ("b", None), "B": ("B", None), "h": ("h", None), "H": ("H", None), "i": ("i", None),
         "I": ("I", None), "q": ("q", None), "Q": ("Q", None), "M": ("B", None), "f": ("f", 1.0), "d": ("d", 1.0),
         "g": ("e", 1.0), "c": ("h", 100.0), "C": ("H", 100.0), "e": ("i", 100.0), "E": ("I", 100.0),
         "L": ("i", 1e7), "n": ("4s", 0), "N": ("16s", 0), "Z": ("64s", 0)}


@dataclass(frozen=True)
class _Layout:
    """One message type of the text log: its binary type id, record length and how each value is packed."""

    type: int
    length: int
    format: str
    packer: struct.Struct


def is_text_log(head: bytes) -> bool:
    """True when ``head`` (a file's first bytes) holds a DataFlash text log's FMT line."""
    return bool(TEXT_FMT_LINE.search(head))


def _layout(fields: list[str]) -> tuple[str, _Layout] | None:
    """The layout of an FMT line's fields (after ``FMT``), None when it cannot be packed ('a' arrays)."""
    try:
        typ, length, name, fmt = int(fields[0]), int(fields[1]), fields[2], fields[3]
    except (ValueError, IndexError):
        return None
    if any(c not in _PACK for c in fmt):
        return None
    packer = struct.Struct("<" + "".join(_PACK[c][0] for c in fmt))
    if packer.size + 3 > length or not 0 <= typ < 256:
        return None
    return name, _Layout(typ, length, fmt, packer)


def _value(ch: str, text: str):
    code, factor = _PACK[ch]
    if factor == 0:
        return text.encode("utf-8")
    if factor is None:
        try:
            return int(text)
        except ValueError:
            if ch == "M":
                return 0  # a mode printed by its name
            return int(float(text))
    return round(float(text) * factor) if factor != 1.0 else float(text)


def _record(lay: _Layout, values: list[str]) -> bytes | None:
    """The binary message of one text line's values, None when they do not fit the layout."""
    if lay.format and lay.format[-1] in "nNZ" and len(values) > len(lay.format):
        values = values[:len(lay.format) - 1] + [", ".join(values[len(lay.format) - 1:])]  # a text with commas
    if len(values) != len(lay.format):
        return None
    try:
        body = lay.packer.pack(*(_value(c, v) for c, v in zip(lay.format, values)))
    except (ValueError, struct.error, OverflowError):
        return None
    return HEAD + bytes([lay.type]) + body + bytes(lay.length - 3 - len(body))


def _fmt_record(fields: list[str]) -> bytes:
    typ, length, name, fmt = int(fields[0]), int(fields[1]), fields[2], fields[3]
    columns = ",".join(fields[4:])
    return HEAD + bytes([FMT_TYPE]) + struct.pack("<BB4s16s64s", typ, length, name.encode(), fmt.encode(),
                                                  columns.encode())


def to_binary(text: bytes) -> tuple[bytes, int]:
    """The binary DataFlash log of a text log, and the number of lines skipped (not fitting their layout)."""
    layouts: dict[str, _Layout] = {}
    out = bytearray()
    skipped = 0
    for raw in text.decode("utf-8", errors="replace").splitlines():
        fields = [f.strip() for f in raw.split(",")]
        if len(fields) < 2 or not fields[0]:
            continue
        if fields[0] == "FMT":
            got = _layout(fields[1:])
            if got is None:
                skipped += 1
                continue
            layouts[got[0]] = got[1]
            out += _fmt_record(fields[1:])
            continue
        lay = layouts.get(fields[0])
        rec = None if lay is None else _record(lay, fields[1:])
        if rec is None:
            skipped += 1
            continue
        out += rec
    return bytes(out), skipped
