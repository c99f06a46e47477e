"""A vectorised reader of plain decimal CSV text, bit for bit the values of ``np.loadtxt`` at a third of its time.

A 2.8 h, 100 Hz recording holds 7 M numbers; ``np.loadtxt`` parses them in about 1.3 s, most of ``analyze``'s
load. Most IMU CSVs hold only plain decimals (``-0.000872664626``, ``9999.99``, ``-1.234567890e-04``): an
optional leading minus, digits with at most one dot, and an optional exponent. For those the parse is done on
whole arrays:

* each field's digits and dot are read as two little-endian 8-byte words ending where they end, the bytes
  outside masked off, the digits turned into their value and every 8 into one number with the SWAR steps of
  fast_float (Lemire 2021, "Number parsing at a gigabyte per second") -- the dot counted as a zero digit,
  taken out after from the dot's place;
* the value is mantissa x 10**e (e the exponent less the decimals), one product or quotient of two exact
  doubles where mantissa < 2**53 and |e| <= 22: correctly rounded (Clinger 1990), as is strtod's (loadtxt's)
  conversion of the same decimal, so the two are the same double. Fields of more than 15 digits are not read
  here.

Anything else (nan, inf, a plus sign but in an exponent, spaces, a CR, an empty field, a row of another length,
a field of more than 15 digits, |e| > 22) returns None and the caller parses with ``np.loadtxt`` as before,
with its errors.
"""

from __future__ import annotations

import sys

import numpy as np

#: text parsed at a time: its index arrays stay in the cache, and the temporaries are a few MB
CHUNK_BYTES = 1 << 18
WIDTH = 16  #: the longest field read here (its sign aside): 15 digits and a dot
MAX_DIGITS = 15  #: mantissas below 10**15 < 2**53 are exact doubles
MAX_POWER = 22  #: 10**22 is the largest exact power of ten in a double
_U = np.uint64
_LOW_NIBBLES = _U(0x0F0F0F0F0F0F0F0F)
_BYTE_ONES = _U(0x0101010101010101)
_SEVENS = _U(0x7F7F7F7F7F7F7F7F)
_DOTS = _U(0x2E2E2E2E2E2E2E2E)
_PAIRS = _U(0x000000FF000000FF)
_MUL1 = _U(100 + (1_000_000 << 32))
_MUL2 = _U(1 + (10_000 << 32))
_POW10_INT = np.array([10**k for k in range(WIDTH + 1)], dtype=np.uint64)
_POW10 = np.array([10.0**k for k in range(MAX_POWER + 1)])


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


def _buffer(text: memoryview):
    """(buf, b, n): the chunk's bytes ``b`` (n of them, a newline added where the last is missing) in ``buf``
    after WIDTH bytes of room for the first field's words."""
    n = len(text)
    buf = np.empty(WIDTH + n + 1, np.uint8)
    buf[:WIDTH] = 44  # masked off
    b = buf[WIDTH:WIDTH + n]
    b[:] = np.frombuffer(text, np.uint8)
    if b[-1] == 10:
        return buf[:-1], b, n
    buf[-1] = 10
    return buf, buf[WIDTH:], n + 1


def _exponents(b, sep, is_e, n_minus: int, n_plus: int):
    """(end of each field's mantissa, its power of ten, minus signs of the exponents) where fields carry an
    exponent (e or E, an optional sign, 1-3 digits); None where one does not read so."""
    at = np.flatnonzero(is_e)
    field = np.searchsorted(sep, at)
    if field.size > 1 and not (field[1:] > field[:-1]).all():  # two exponents in a field
        return None
    sign = b[at + 1]
    minus, plus = sign == 45, sign == 43
    if np.count_nonzero(plus) != n_plus or np.count_nonzero(minus) > n_minus:  # signs elsewhere
        return None
    end = sep[field]
    count = end - at - 1 - (minus | plus)
    if count.min() < 1 or count.max() > 3:
        return None
    value = np.zeros(at.size, np.int64)
    for i in range(1, 4):  # the exponent's last digit, then the ones before it
        d = b[end - i].astype(np.int64) - 48
        value += np.where(count >= i, d * 10 ** (i - 1), 0)
    power = np.zeros(sep.size, np.int64)
    power[field] = np.where(minus, -value, value)
    mantissa_end = sep.copy()
    mantissa_end[field] = at
    return mantissa_end, power, int(np.count_nonzero(minus))


def _parse_chunk(text: memoryview, ncols: int) -> np.ndarray | None:
    buf, b, n = _buffer(text)
    newline = b == 10
    sep = np.flatnonzero(newline | (b == 44))
    nf = sep.size
    n_dots = np.count_nonzero(b == 46)
    n_minus = np.count_nonzero(b == 45)
    is_e = (b | np.uint8(32)) == 101  # e or E
    n_e = np.count_nonzero(is_e)
    n_plus = np.count_nonzero(b == 43) if n_e else 0
    # only digits, separators, dots, signs and exponents' e; every row ncols fields
    if (np.count_nonzero((b - np.uint8(48)) < 10) + nf + n_dots + n_minus + n_e + n_plus != n or nf % ncols
            or np.count_nonzero(newline) != nf // ncols or not newline[sep[ncols - 1::ncols]].all()):
        return None
    start = sep - (np.diff(sep, prepend=-1) - 1)
    neg = b[start] == 45
    end, power, exp_minus = sep, None, 0
    if n_e:
        got = _exponents(b, sep, is_e, n_minus, n_plus)
        if got is None:
            return None
        end, power, exp_minus = got
    if np.count_nonzero(neg) + exp_minus != n_minus:  # a minus anywhere but first or after e
        return None
    body = end - start - neg  # digits and dot: the words hold them, the sign is read above
    if body.max() > WIDTH:
        return None
    mantissa, decimals = _mantissas(buf, end, body, n_dots)
    if mantissa is None:
        return None
    if power is None:
        val = mantissa / _POW10[decimals]
    else:
        # value = mantissa 10^e: one product or quotient of exact doubles, correctly rounded where |e| <= 22
        e = power - decimals
        if np.abs(e).max() > MAX_POWER:
            return None
        val = np.where(e >= 0, mantissa * _POW10[np.maximum(e, 0)], mantissa / _POW10[np.maximum(-e, 0)])
    np.negative(val, out=val, where=neg)
    return val.reshape(-1, ncols)


def _mantissas(buf, end, body, n_dots: int):
    """(mantissa as a double, decimals) of every field whose digits and dot (``body`` bytes) end before buf offset
    ``end`` + WIDTH; (None, None) where a field has two dots, no digit or more than MAX_DIGITS."""
    # unaligned 8-byte words at every offset of buf: the bytes before text offset s are words[s], words[s + 8]
    words = np.ndarray((buf.size - 7,), dtype=np.uint64, buffer=buf, strides=(1,))
    mask = _FIELD_MASK[body]
    first = words[end] & mask[:, 0]
    second = words[end + 8] & mask[:, 1]
    dot1, dot2 = _dot_bytes(first), _dot_bytes(second)
    in1, in2 = dot1 != 0, dot2 != 0
    has_dot = in1 | in2
    if np.count_nonzero(has_dot) != n_dots or np.count_nonzero(in1 & in2):  # two dots in a field
        return None, None
    digits = body - has_dot
    if digits.min() < 1 or digits.max() > MAX_DIGITS:
        return None, None
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
    return mantissa.astype(np.float64), np.where(has_dot, k, 0)
