"""The vectorised plain-decimal CSV parser gives np.loadtxt's doubles bit for bit, refuses (None) every text it does
not read, and a file it refuses reads and fails exactly as through loadtxt alone (the same values, the same
error line)."""

from __future__ import annotations

import io

import numpy as np
import pytest

from companion.errors import CompanionError
from companion.sources import csvdecimal, csvfile
from companion.sources.csvdecimal import parse_decimal

HEADER = "time_s,gx,gy,gz,ax,ay,az\n"


def _loadtxt(text: str, ncols: int) -> np.ndarray:
    return np.loadtxt(io.BytesIO(text.encode()), delimiter=",", ndmin=2, dtype=np.float64).reshape(-1, ncols)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _decimal_fields(rng, count: int) -> list[str]:
    """Plain decimals of 1-15 digits with the dot anywhere (also first or last), leading zeros, signs, zeros."""
    out = []
    for _ in range(count):
        nd = int(rng.integers(1, 16))
        digits = "".join(str(d) for d in rng.integers(0, 10, nd))
        if rng.random() < 0.1:
            digits = "0" * nd  # zero and -0
        dot = int(rng.integers(-1, nd + 1))  # -1: no dot
        s = digits if dot < 0 else digits[:dot] + "." + digits[dot:]
        out.append(("-" if rng.random() < 0.5 else "") + s)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_random_decimals_bit_identical_to_loadtxt(seed):
    """Fields of every width 1-15 digits, every dot place, half negative: the same doubles as loadtxt (which
    converts with a correctly rounded strtod), read in many small chunks as well as whole."""
    rng = np.random.default_rng(seed)
    ncols = int(rng.integers(1, 9))
    rows = 3000
    f = _decimal_fields(rng, rows * ncols)
    text = "\n".join(",".join(f[r * ncols:(r + 1) * ncols]) for r in range(rows)) + "\n"
    ref = _loadtxt(text, ncols)
    got = parse_decimal(text.encode(), ncols)
    assert got is not None and _same_bits(got, ref)
    old = csvdecimal.CHUNK_BYTES
    try:
        csvdecimal.CHUNK_BYTES = 211  # chunks of a few lines (a line longer than a chunk is refused)
        assert _same_bits(parse_decimal(text.encode(), ncols), ref)
    finally:
        csvdecimal.CHUNK_BYTES = old


def test_hard_roundings_and_edges():
    """Decimals next to a rounding boundary, the longest mantissas, the smallest and largest steps, -0, and a last
    row without its newline."""
    fields = ["0.1", "0.3", "2.675", "1.005", "999999999999999", "-99999999999999.9", "0.00000000000001",
              "-0.00000000000001", "-0", "12", "-12345678901234", "100", "0.", ".5", "-.5", "5.",
              "0000000000000.1", "9007199254740.99", "123456789012345", "0.30000000000000", "1.7976931348623"]
    text = "\n".join(f"{a},{b}" for a, b in zip(fields, fields[::-1]))
    got = parse_decimal(text.encode(), 2)
    ref = _loadtxt(text, 2)
    assert got is not None and _same_bits(got, ref)
    assert np.signbit(got[fields.index("-0"), 0])


@pytest.mark.parametrize("seed", range(3))
def test_exponent_fields_bit_identical_to_loadtxt(seed):
    """The %.Ne fields of np.savetxt and write_csv (1-15 significant digits, e/E, signed exponents of 1-3
    digits), beside plain decimals: the same doubles as loadtxt."""
    rng = np.random.default_rng(100 + seed)
    vals = rng.normal(size=(2000, 4)) * 10.0 ** rng.integers(-9, 9, size=(2000, 4))
    fields = []
    for v in vals.ravel():
        p = int(rng.integers(0, 15))
        p = min(p, 22 + int(f"{v:e}".split("e")[1]))  # 10^-22 at most below the mantissa (exact powers)
        s = f"{v:.{p}f}"
        if rng.random() < 0.8 or sum(c.isdigit() for c in s) > 15:  # 16+ digits: loadtxt's (tested above)
            s = f"{v:.{p}e}"
        if rng.random() < 0.2:
            s = s.replace("e", "E")
        if rng.random() < 0.2:
            s = s.replace("e-0", "e-").replace("e+0", "e")  # short and unsigned exponents
        fields.append(s)
    text = "\n".join(",".join(fields[r * 4:(r + 1) * 4]) for r in range(2000)) + "\n"
    got = parse_decimal(text.encode(), 4)
    assert got is not None and _same_bits(got, _loadtxt(text, 4))


@pytest.mark.parametrize("text", ["1e,2\n", "e5,2\n", "1e5e5,2\n", "1e+-5,2\n", "1e1234,2\n", "1e-30,2\n",
                                  "1e5.5,2\n", "1.5e+,2\n", "1-e5,2\n", "1e5-,2\n", "1+e5,2\n"])
def test_refused_exponents(text):
    """Exponents that are not one e, an optional sign and 1-3 digits, or beyond 10^+-22 of the mantissa."""
    assert parse_decimal(text.encode(), 2) is None


@pytest.mark.parametrize("text", [
    "nan,2\n", "inf,2\n", "-inf,2\n", "+1.0,2\n", " 1.0,2\n", "1.0 ,2\n", "1.0,2\r\n",
    "1..2,3\n", "1.2.3,4\n", "1-2,3\n", "--1,2\n", "-,2\n", ".,2\n", ",2\n", "1,2\n\n3,4\n", "1,2,3\n",
    "1\n", "1,2\n3\n", "1234567890123456,1\n", "0.1234567890123456,1\n", "#c\n1,2\n", "0x10,1\n", "1_0,2\n",
    "1;2\n", "\n",
])
def test_refused_texts(text):
    """Anything but rows of plain decimals is left to loadtxt: nan, inf, a plus sign, spaces, a CR,
    empty fields, blank lines, rows of another length, 16+ digits, comments, other separators."""
    assert parse_decimal(text.encode(), 2) is None


def _read(path, fast: bool, monkeypatch):
    """read_csv with the fast parser, or with loadtxt alone (the fast parser refusing everything)."""
    with monkeypatch.context() as m:
        if not fast:
            m.setattr(csvfile, "parse_decimal", lambda text, ncols: None)
        try:
            raw = csvfile.read_csv(path)
        except CompanionError as exc:
            return str(exc)
        return np.column_stack([raw.t, raw.gyro, raw.accel])


@pytest.mark.parametrize("body", [
    "0.00,1,2,3,4,5,6\n0.01,1e-5,2,3,4,5,6\n0.02,1,2,3,4,5,6\n",  # an exponent
    "0.00,1,2,3,4,5,6\n0.01,1e-45,2,3,4,5,6\n",  # beyond the exact powers: read by loadtxt
    "0.00,1,2,3,4,5,6\n0.01,1,2,3,4,5\n",  # a short row
    "0.00,1,2,3,4,5,6\n0.01,1,2,3,4,5,6,7\n",  # a long row
    "0.00,1,2,3,4,5,6\n0.01,1,x,3,4,5,6\n",  # not a number
    "0.00,1,2,3,4,5,6\n0.01,1,2,3,4,5,nan\n",  # nan
    "0.00,1,2,3,4,5,6\n0.01,1,2,,4,5,6\n",  # an empty field
    "0.00,1,2,3,4,5,6\n0.01, 1,2,3,4,5,6\n",  # a space
    "0.00,1,2,3,4,5,6\r\n0.01,1,2,3,4,5,6\r\n",  # CRLF
    "0.00,1,2,3,4,5,6\n\n0.01,1,2,3,4,5,6\n",  # a blank line
    "0.00,-0.5,2,3,4,5,6\n0.01,1.25,-2,3,4,5,6",  # plain, no final newline
])
def test_files_read_and_fail_as_through_loadtxt(tmp_path, monkeypatch, body):
    """Whole files, good and bad: the same values (bit for bit) or the same one error line, with the fast parser
    and without it."""
    p = tmp_path / "x.csv"
    p.write_text(HEADER + body)
    fast, slow = _read(p, True, monkeypatch), _read(p, False, monkeypatch)
    if isinstance(slow, str):
        assert fast == slow and "\n" not in fast
    else:
        assert not isinstance(fast, str) and _same_bits(fast, slow)


@pytest.mark.parametrize("bad,expect", [(lambda r: r.rsplit(",", 1)[0], "fewer columns"),
                                        (lambda r: r.replace(",", ",x", 1), "line 1502")])
def test_bad_row_in_a_late_block(tmp_path, monkeypatch, bad, expect):
    """A short or non-numeric row deep in a file read in small blocks (the earlier blocks through the fast
    parser): the one error line of loadtxt alone, naming the file's line where it can."""
    monkeypatch.setattr(csvfile, "BLOCK_BYTES", 4096)
    rng = np.random.default_rng(3)
    rows = [f"{i / 100:.2f}," + ",".join(f"{v:.9f}" for v in rng.normal(size=6)) for i in range(2000)]
    rows[1500] = bad(rows[1500])
    p = tmp_path / "late.csv"
    p.write_text(HEADER + "\n".join(rows) + "\n")
    fast, slow = _read(p, True, monkeypatch), _read(p, False, monkeypatch)
    assert isinstance(fast, str) and fast == slow and expect in fast
