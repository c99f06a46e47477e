"""A vectorised reader of plain decimal CSV text, bit for bit the values of ``np.loadtxt`` at a third of its time.

A 2.8 h, 100 Hz recording holds 7 M numbers; ``np.loadtxt`` parses them in about 1.3 s, most of ``analyze``'s
load. Most IMU CSVs hold only plain decimals (``-0.000872664626``, ``9999.99``): an optional leading minus,
digits and at most one dot. For those the parse is done on whole arrays:

* each field's bytes are read as two little-endian 8-byte words ending at its separator, the bytes outside the
  field masked off, the digits turned into their value and every 8 into one number with the SWAR steps of
  fast_float (Lemire 2021, "Number parsing at a gigabyte per second") -- the dot counted as a zero digit,
  taken out after from the dot's place;
* the value is mantissa / 10**k (k decimals). With mantissa < 2**53 and k <= 22 both are exact doubles and one
  IEEE division is correctly rounded (Clinger 1990), as is strtod's (loadtxt's) conversion of the same
  decimal: the two are the same double. Fields of more than 15 digits are not read here.

Anything else (an exponent, nan, inf, a plus sign, spaces, a CR, an empty field, a row of another length, a
field of more than 15 digits) returns None and the caller parses with ``np.loadtxt`` as before, with its errors.
"""

from __future__ import annotations

import sys

import numpy as np

#: text parsed at a time: its index arrays stay in the cache, and the temporaries are a few MB
CHUNK_BYTES = 1 << 18
WIDTH = 16  #: the longest field read here (its sign aside): 15 digits and a dot
MAX_DIGITS = 15  #: mantissas below 10**15 < 2**53 are exact doubles
_U = np.uint64
_LOW_NIBBLES = _U(0x0F0F0F0F0F0F0F0F)
_BYTE_ONES = _U(0x0101010101010101)
_SEVENS = _U(0x7F7F7F7F7F7F7F7F)
_DOTS = _U(0x2E2E2E2E2E2E2E2E)
_PAIRS = _U(0x000000FF000000FF)
_MUL1 = _U(100 + (1_000_000 << 32))
_MUL2 = _U(1 + (10_000 << 32))
_POW10_INT = np.array([10**k for k in range(WIDTH + 1)], dtype=np.uint64)
_POW10 = np.array([10.0**k for k in range(WIDTH + 1)])


def _top_bytes(keep: int) -> int:
    """A word's mask keeping its ``keep`` most significant bytes (the last ``keep`` characters in the text)."""
    keep = max(0, min(keep, 8))
    return ((1 << (8 * keep)) - 1) << (8 * (8 - keep)) if keep else 0


#: per field length L (sign aside): the masks of its (first, second) word, the field the last L of the 16 bytes
_FIELD_MASK = np.array([[_top_bytes(n - 8), _top_bytes(n)] for n in range(WIDTH + 1)], dtype=np.uint64)


def parse_decimal(text: bytes, ncols: int) -> np.ndarray | None:
    """The ``(rows, ncols)`` values of ``text`` (rows of ``ncols`` comma-separated plain decimals, the last newline
    optional), the doubles ``np.loadtxt`` gives; None where any part of the text is not of that form."""
    if sys.byteorder != "little" or not text:
        return None
    out = []
    pos = 0
    view = memoryview(text)  # chunks without copies
    while pos < len(text):
        cut = text.rfind(b"\n", pos, pos + CHUNK_BYTES) + 1 if pos + CHUNK_BYTES < len(text) else len(text)
        if cut <= pos:  # a line longer than a chunk: not a plain numeric row
            return None
        arr = _parse_chunk(view[pos:cut], ncols)
        if arr is None:
            return None
        out.append(arr)
        pos = cut
    return out[0] if len(out) == 1 else np.concatenate(out)


def _eight_digits(v: np.ndarray) -> np.ndarray:
    """The numbers of 8 digit values per word (first character the least significant byte, most significant
    digit), fast_float's ``parse_eight_digits_unrolled``."""
    v = v * _U(10) + (v >> _U(8))
    return ((v & _PAIRS) * _MUL1 + ((v >> _U(16)) & _PAIRS) * _MUL2) >> _U(32)


def _dot_bytes(w: np.ndarray) -> np.ndarray:
    """0x80 in each byte of ``w`` that is '.', 0 elsewhere (the exact zero-byte test of w ^ '........')."""
    y = w ^ _DOTS
    return ~(((y & _SEVENS) + _SEVENS) | y | _SEVENS)


def _parse_chunk(text: memoryview, ncols: int) -> np.ndarray | None:
    n = len(text)
    buf = np.empty(WIDTH + n + 1, np.uint8)
    buf[:WIDTH] = 44  # room for the first field's words: masked off
    b = buf[WIDTH:WIDTH + n]
    b[:] = np.frombuffer(text, np.uint8)
    if b[-1] == 10:
        buf = buf[:-1]
    else:
        buf[-1] = 10
        b = buf[WIDTH:]
        n += 1
    newline = b == 10
    sep = np.flatnonzero(newline | (b == 44))
    nf = sep.size
    n_dots = np.count_nonzero(b == 46)
    n_minus = np.count_nonzero(b == 45)
    # only digits, separators, dots and minus signs; every row ncols fields
    if (np.count_nonzero((b - np.uint8(48)) < 10) + nf + n_dots + n_minus != n or nf % ncols
            or np.count_nonzero(newline) != nf // ncols or not newline[sep[ncols - 1::ncols]].all()):
        return None
    length = np.diff(sep, prepend=-1) - 1
    neg = b[sep - length] == 45
    if np.count_nonzero(neg) != n_minus:  # a minus anywhere but first
        return None
    body = length - neg  # digits and dot: the words hold them, the sign is read above
    if body.max() > WIDTH:
        return None
    # unaligned 8-byte words at every offset of buf: the field ending at text offset s is words[s], words[s + 8]
    words = np.ndarray((buf.size - 7,), dtype=np.uint64, buffer=buf, strides=(1,))
    mask = _FIELD_MASK[body]
    first = words[sep] & mask[:, 0]
    second = words[sep + 8] & mask[:, 1]
    dot1, dot2 = _dot_bytes(first), _dot_bytes(second)
    in1, in2 = dot1 != 0, dot2 != 0
    has_dot = in1 | in2
    if np.count_nonzero(has_dot) != n_dots or np.count_nonzero(in1 & in2):  # two dots in a field
        return None
    digits = body - has_dot
    if digits.min() < 1 or digits.max() > MAX_DIGITS:
        return None
    # the dot's bit (8 byte + 7 in its word) gives its byte, and the decimals after it
    bit = np.frexp((dot1 | dot2).astype(np.float64))[1] - 1
    k = np.where(has_dot, np.where(in2, 7, 15) - (bit >> 3), WIDTH)  # no dot: at 10^16, above every digit
    # digit bytes keep their low nibble; '-', '.', ',' and newline (bit 4 clear) become 0
    first &= ((first >> _U(4)) & _BYTE_ONES) * _U(255) & _LOW_NIBBLES
    second &= ((second >> _U(4)) & _BYTE_ONES) * _U(255) & _LOW_NIBBLES
    x = _eight_digits(first) * _U(100_000_000) + _eight_digits(second)
    # x = I 10^(k+1) + F (the dot a zero digit); the mantissa is I 10^k + F (x itself without a dot: I = 0)
    p = _POW10_INT[k]
    mantissa = x - _U(9) * (x // (p * _U(10))) * p
    val = mantissa.astype(np.float64) / _POW10[np.where(has_dot, k, 0)]
    np.negative(val, out=val, where=neg)
    return val.reshape(-1, ncols)
