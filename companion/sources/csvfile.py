"""CSV IMU files: ``time_s,gx,gy,gz,ax,ay,az`` (gyro rad/s, accel m/s^2), plain or gzip-compressed.

The header names the columns (any order; extra columns are ignored); every row must be numeric.
This is the format of ../shared/data/adis16405. One stream, keyed ``StreamKey(0, 0, "CSV", 0)``.
Any problem (missing file, not a CSV, not gzip, missing columns, a non-numeric value) is a
:class:`CompanionError` naming the file and, where it can, the line.
"""

from __future__ import annotations

import gzip
import io
import warnings
import zlib
from pathlib import Path

import numpy as np

from companion.allan.memo import release_free_memory
from companion.errors import CompanionError
from companion.sources.csvdecimal import parse_decimal
from companion.sources.kind import opens_as_gzip
from companion.samples import AXES, StreamKey
from companion.sources.decode import RawStream

COLUMNS = ("time_s",) + AXES
#: ``--time-unit`` choices: seconds per unit of the time column
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
#: plausible sample rates of a gyro log: MEMS and tactical gyros are read at 1 Hz (lab stills such as the NBS
#: test series, slow telemetry) up to 32 kHz (the fastest MEMS output data rates); 0.01 Hz - 100 kHz leaves a
#: margin each side. Outside it the time column is in another unit or broken, and the Allan numbers would be
#: off by the same factor's square root (a 1 kHz log read as 1 GHz gives N 1000x too small).
MIN_RATE_HZ, MAX_RATE_HZ = 0.01, 1e5
CSV_KEY = StreamKey(0, 0, "CSV", 0)
#: text decompressed and parsed at a time: large enough that numpy's parser dominates, small beside the columns
BLOCK_BYTES = 1 << 22
#: the shortest row of seven numbers ("0,0,0,0,0,0,0\\n"): the most rows a text of a given size can hold
MIN_ROW_BYTES = 14
#: times tested per block for whole numbers
WHOLE_BLOCK = 1 << 16
#: a gzip member's header and trailer take 18 bytes: a shorter file has no size trailer to read
GZIP_MIN_BYTES = 18
WHOLE_TOLERANCE = 1e-9  #: relative: a time this close to a whole number is one (float noise of a ms clock)
#: a restart (time stepping back) between runs this long (median) is a new series; shorter runs are rows out
#: of order: 100 rows is a second at 100 Hz, far more than a shuffled export's runs of about 2
RESTART_RUN_ROWS = 100


def _gzip_open(path: Path):
    """A gzip file opened for reading: through ISA-L (isal) where installed, a third of zlib's time on a large
    CSV (the decompression is a fifth of reading one), else the standard library's gzip."""
    try:
        from isal import igzip
    except ImportError:
        return gzip.open(path, "rb")
    return igzip.open(path, "rb")


def _gzip_errors() -> tuple[type[BaseException], ...]:
    """The exceptions of a corrupt gzip stream, isal's among them where installed."""
    try:
        from isal.isal_zlib import error as isal_error
    except ImportError:
        return gzip.BadGzipFile, zlib.error, EOFError
    return gzip.BadGzipFile, zlib.error, EOFError, isal_error


def _read_bytes(path: Path) -> bytes:
    try:
        if opens_as_gzip(path):
            with _gzip_open(path) as fh:
                return fh.read()
        return path.read_bytes()
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise CompanionError(f"{path}: is a directory, expected a CSV file") from None
    except _gzip_errors() as exc:
        raise CompanionError(f"{path}: not a readable gzip file ({exc})") from None
    except OSError as exc:
        raise CompanionError(f"{path}: cannot read ({exc.strerror or exc})") from None


def read_csv(path, time_unit: str | None = None) -> RawStream:
    """Read an IMU CSV file into a :class:`RawStream` (arrival order; timing is analysed by the caller).

    ``time_unit``: "s", "ms" or "us", the unit of the ``time_s`` column; None: seconds, and a column that
    evidently is in ms or us is refused (:func:`check_time_unit`)."""
    path = Path(path)
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise CompanionError(f"time unit {time_unit!r}: expected one of {', '.join(TIME_UNITS)}")
    cols = _read_columns(path)
    if cols is None:  # a file the block reader refuses: read whole, for the error's line number
        cols = _columns_of(_read_whole(path))
    t, gyro, accel = cols
    if t.shape[0] == 0:
        raise CompanionError(f"{path}: no data rows after the header")
    if not (np.isfinite(t).all() and np.isfinite(gyro).all() and np.isfinite(accel).all()):
        bad = ~(np.isfinite(t) & np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(accel), axis=1))
        raise CompanionError(f"{path}: non-finite value (nan/inf) on data row {int(np.flatnonzero(bad)[0]) + 1}")
    check_resolution(path, t)
    step = _median_step(t)  # once: each check below needs it, and it costs a sort-sized pass over the column
    if time_unit is None:
        check_time_unit(path, t, step)
    else:
        t *= TIME_UNITS[time_unit]
        step = _median_step(t)
    check_rate(path, t, step)
    order, notes = in_time_order(path, t, step)
    if order is not None:
        t, gyro, accel = t[order], gyro[order], accel[order]
    return RawStream(CSV_KEY, t, gyro, accel, None, True, None, None, 0.0, notes)


def _usecols(path, head: bytes) -> list[int]:
    """The indices of COLUMNS in the header line ``head``."""
    try:
        header = head.decode("utf-8-sig").strip()
    except UnicodeDecodeError:
        raise CompanionError(f"{path}: not a text CSV file (expected header {','.join(COLUMNS)})") from None
    names = [c.strip().lower() for c in header.split(",")]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise CompanionError(f"{path}: missing column(s) {', '.join(missing)}; expected header "
                             f"{','.join(COLUMNS)} (gyro rad/s, accel m/s^2)")
    return [names.index(c) for c in COLUMNS]


def _read_whole(path) -> np.ndarray:
    """The data rows (COLUMNS order) of the whole file parsed at once: the errors name the file's line."""
    data = _read_bytes(path)
    head, _, body = data.partition(b"\n")
    usecols = _usecols(path, head)
    try:
        return _parse(body, usecols, len(head.split(b",")))
    except (ValueError, IndexError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "invalid column index" in msg:
            raise CompanionError(f"{path}: a data row has fewer columns than the header "
                                 f"({len(head.split(b','))})") from None
        msg = _to_file_lines(msg)  # numpy counts data rows from 0; the file has a header line first
        raise CompanionError(f"{path}: bad CSV data: {msg}") from None


def _parse(text: bytes, usecols, ncols: int) -> np.ndarray:
    """The ``usecols`` columns of the rows in ``text`` (``ncols`` fields a row in the header): plain decimals through
    :func:`~companion.sources.csvdecimal.parse_decimal` (the same doubles), anything else through loadtxt."""
    arr = parse_decimal(text, ncols)
    if arr is not None:
        return arr if list(usecols) == list(range(ncols)) else arr[:, usecols]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported by the caller
        return np.loadtxt(io.BytesIO(text), delimiter=",", usecols=usecols, ndmin=2, dtype=np.float64)


def _columns_of(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return arr[:, 0].copy(), arr[:, 1:4].copy(), arr[:, 4:7].copy()


class _Columns:
    """Time, gyro and accel columns filled block by block, with room for ``capacity`` rows (grown when short).
    Rows not yet filled are never touched, so an over-estimated capacity costs address space, not memory."""

    def __init__(self, capacity: int):
        self.n = 0
        self.t, self.gyro, self.accel = np.empty(capacity), np.empty((capacity, 3)), np.empty((capacity, 3))

    def add(self, arr: np.ndarray) -> None:
        k = arr.shape[0]
        if self.n + k > self.t.shape[0]:
            self._grow(max(2 * self.t.shape[0], self.n + k))
        self.t[self.n:self.n + k] = arr[:, 0]
        self.gyro[self.n:self.n + k] = arr[:, 1:4]
        self.accel[self.n:self.n + k] = arr[:, 4:7]
        self.n += k

    def _grow(self, cap: int) -> None:
        t, gyro, accel = np.empty(cap), np.empty((cap, 3)), np.empty((cap, 3))
        t[:self.n], gyro[:self.n], accel[:self.n] = self.t[:self.n], self.gyro[:self.n], self.accel[:self.n]
        self.t, self.gyro, self.accel = t, gyro, accel

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.t[:self.n], self.gyro[:self.n], self.accel[:self.n]


def _open(path: Path):
    """(binary stream of the file's text, its size in bytes: for a gzip file the trailer's, modulo 2^32)."""
    size = path.stat().st_size
    if not opens_as_gzip(path):
        return open(path, "rb"), size
    if size >= GZIP_MIN_BYTES:
        with open(path, "rb") as fh:
            fh.seek(-4, 2)
            size = int.from_bytes(fh.read(4), "little")
    return _gzip_open(path), size


def _read_columns(path: Path):
    """The columns read in blocks of BLOCK_BYTES (a block is parsed whole rows at a time, and the whole text is
    never held: the peak memory is the columns themselves); None where a block does not parse, the caller
    then reads the file whole for the error message with its line number."""
    try:
        fh, size = _open(path)
        with fh:
            head = fh.readline()
            usecols, ncols = _usecols(path, head), len(head.split(b","))
            cols = _Columns(max(size // MIN_ROW_BYTES, 1))
            rest = b""
            while True:
                block = fh.read(BLOCK_BYTES)
                text = rest + block
                cut = text.rfind(b"\n") + 1 if block else len(text)
                rest = text[cut:]
                # a block of whole rows is never blank but for a few trailing blank lines (tested without
                # copying a full block)
                if cut and (cut > 256 or text[:cut].strip()):
                    arr = _parse(text[:cut], usecols, ncols)
                    if arr.shape[1] != len(COLUMNS):
                        return None
                    cols.add(arr)
                if not block:
                    # the blocks' parse leaves free heap pages between the columns' (30 MB on a 1 M-row file),
                    # which the reads after would add to
                    release_free_memory()
                    return cols.arrays()
    except (ValueError, IndexError, OSError) + _gzip_errors():
        return None


def check_resolution(path, t: np.ndarray) -> None:
    """Refuse a time column coarser than the sample rate: more than half the rows repeat the time of the row
    before (whole-second times on 100 rows a second). Read at any unit, the repeats would be dropped as
    duplicates and the few rows left give a rate and noise density off by the rows-per-tick factor; a few
    repeated rows (a logger writing a row twice) stay below the half and are counted by the timing rules."""
    n = t.shape[0]
    if n < 3:
        return
    distinct = n - int(np.count_nonzero(np.diff(t) == 0))  # runs of equal times, in file order
    if 2 * distinct < n:
        raise CompanionError(f"{path}: {n} rows carry only {distinct} distinct times ({n / distinct:.3g} rows per "
                             "time value): the time column's resolution is coarser than the sample rate, so the "
                             "samples cannot be timed; write time_s with more digits")


def check_time_unit(path, t: np.ndarray, step: float | None = -1.0) -> None:
    """Refuse a ``time_s`` column whose spacing says it is not in seconds, or may not be.

    The unit is decided from the median spacing of the sorted times (robust to gaps and a few bad rows). A
    median step below 1 is seconds (gyro logs run at >= 1 Hz). A median step >= 1 with whole numbers (up to
    float noise, :func:`_whole_numbers`) or times beyond 1e5 (more than a day "since boot") is a clock in ms
    (step 1-100) or us (step >= 100). Any other step >= 1 is ambiguous (2.5 is 0.4 Hz in s and 400 Hz in
    ms): refused with the rates each unit gives. Read as seconds, a 100 Hz ms log looks like 0.1 Hz data and
    its N is 30x too large, so the user chooses with --time-unit."""
    if t.shape[0] < 3:
        return
    step = _median_step(t) if step == -1.0 else step
    if step is None or step < 1.0:
        return
    integral = _whole_numbers(t)
    if integral or float(np.max(np.abs(t))) > 1e5:
        unit, div = ("microseconds", 1e6) if step >= 100.0 else ("milliseconds", 1e3)
        raise CompanionError(f"{path}: time_s looks like {unit} (median step {step:g}, "
                             f"{'whole numbers' if integral else 'values up to %g' % float(np.max(t))}): "
                             f"pass --time-unit {'us' if div == 1e6 else 'ms'} (or divide the column by {div:g}); "
                             "--time-unit s if the times really are whole seconds")
    raise CompanionError(f"{path}: time_s steps by a median of {step:g}: {1 / step:.3g} Hz in seconds, "
                         f"{1e3 / step:.3g} Hz in milliseconds, {1e6 / step:.3g} Hz in microseconds; pass "
                         "--time-unit s, ms or us to say which")


def check_rate(path, t: np.ndarray, step: float | None = -1.0) -> None:
    """Refuse a sample rate no gyro log has (see ``MIN_RATE_HZ``, ``MAX_RATE_HZ``), with the reason. ``step``: the
    column's :func:`_median_step` when known (-1: computed here)."""
    step = _median_step(t) if step == -1.0 else step
    if step is None:
        return
    rate = 1.0 / step
    if not (MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
        raise CompanionError(f"{path}: time_s gives {rate:.3g} Hz (median step {step:.3g} s), outside the "
                             f"{MIN_RATE_HZ:g} Hz - {MAX_RATE_HZ:.0f} Hz of any gyro log: a wrong time unit "
                             "(--time-unit s|ms|us) or a broken time column")


def _median_step(t: np.ndarray) -> float | None:
    """The median of the positive steps of the sorted times (None without any); a column already in order
    (the usual case) is not copied to be sorted."""
    d = np.diff(t)
    if np.any(d < 0):
        d = np.diff(np.sort(t))
    if not np.all(d > 0):
        d = d[d > 0]
    return float(np.median(d)) if d.shape[0] else None


def _whole_numbers(t: np.ndarray) -> bool:
    """True when every time is a whole number up to float noise (30.000000000000004 from 3 * 10.0 ms): a
    relative tolerance of 1e-9 is a million times float64's rounding and far below any clock's tick. Tested a
    block at a time (no rounded copy of the whole column)."""
    return all(bool(np.all(np.abs(b - np.round(b)) <= WHOLE_TOLERANCE * np.maximum(1.0, np.abs(b))))
               for b in np.array_split(t, max(1, t.shape[0] // WHOLE_BLOCK)))


def in_time_order(path, t: np.ndarray, step: float | None = -1.0) -> tuple[np.ndarray | None, list[str]]:
    """The order to read the rows in (None: as they are; time in s) and the note on that order.

    Rows in time order are kept. Where the time restarts (steps back by more than the reset threshold of
    :mod:`companion.sources.timestamps`, max(1 s, 10 periods), between runs of at least ``RESTART_RUN_ROWS``
    rows, median) the file holds series one after another: the rows stay in file order and the timing rules
    make each restart a new segment, as a reboot in a log; sorting would interleave the series into one
    with doubled rate. Otherwise the backward steps are rows out of order (an export that shuffled them):
    the rows are sorted by time."""
    name = Path(path).name
    d = np.diff(t)
    back = int(np.count_nonzero(d < 0))
    if not back:
        return None, []
    from companion.sources.timestamps import step_rules

    reset_s = step_rules((_median_step(t) if step == -1.0 else step) or 1.0).reset_s
    restarts = np.flatnonzero(d < -reset_s)
    if restarts.shape[0]:
        runs = np.diff(np.r_[0, restarts + 1, t.shape[0]])
        if float(np.median(runs)) >= RESTART_RUN_ROWS:
            lines = ", ".join(str(int(i) + 3) for i in restarts[:3]) + (", ..." if restarts.shape[0] > 3 else "")
            return None, [f"{name}: time_s restarts {restarts.shape[0]} time(s) (line {lines}): the rows are read "
                          "in file order, each restart a new segment, not sorted into the earlier rows"]
    return np.argsort(t, kind="stable"), [f"{name}: rows were not in time order ({back} backward steps): sorted by time_s"]


def _to_file_lines(msg: str) -> str:
    import re

    msg = re.sub(r"at row (\d+)", lambda m: f"on line {int(m.group(1)) + 2}", msg)
    return re.sub(r"the number of columns changed from (\d+) to (\d+) at row (\d+)",
                  lambda m: f"line {int(m.group(3)) + 2} has {m.group(2)} columns, expected {m.group(1)}", msg)


def write_csv(path: str, t, gyro, accel) -> None:
    """Write ``time_s,gx,gy,gz,ax,ay,az`` rows (SI; gzip-compressed for a ``.gz`` path): the format read above."""
    opener = gzip.open if path.lower().endswith(".gz") else open
    arr = np.column_stack([t, gyro, accel])
    with opener(path, "wt") as f:
        f.write("time_s,gx,gy,gz,ax,ay,az\n")
        np.savetxt(f, arr, fmt=["%.6f"] + ["%.9e"] * 6, delimiter=",")
