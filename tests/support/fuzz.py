"""A seeded mutation fuzzer for the file readers (used by tests/cli/test_input_handling.py and
benchmarks/bench_fuzz.py).

``mutate(data, rng, hot)`` applies 1-4 random damages of the kinds a log meets in practice: bit/byte flips,
truncation (a log cut mid-record), inserted garbage, deleted bytes, duplicated chunks (a write repeated by
a flaky SD card) and damage to the first bytes (file header, DataFlash FMT records, ULog definitions).
With ``hot`` (offsets from :func:`hot_offsets`: record headers, message ids, length fields, FMT/ULog format
definitions, CSV delimiters) a fifth of the damages are aimed at the structure: a byte there set to a random
value, 0, 0xFF, +-1, the value of another structural byte, or a random 16/32-bit little-endian integer
written over it (a length or an id). ``check(name, data, workdir)`` writes the mutated bytes under the
reader's file name and loads them with ``companion.sources.load``: the outcome is ``"ok"`` (loaded, damaged
records counted), ``"refused"`` (one CompanionError line), ``"invalid"`` (loaded with impossible numbers) or
``"traceback"`` (any other exception: a bug), with the text of the error. Everything is deterministic for a
given seed.
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
import traceback
from pathlib import Path

import numpy as np

KINDS = ("flip", "truncate", "insert", "delete", "duplicate", "header")


def mutate(data: bytes, rng: np.random.Generator, hot: np.ndarray | None = None) -> bytes:
    """1-4 random damages of ``data`` (see the module docstring); ``hot``: structural offsets to aim at."""
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        if hot is not None and len(hot) and rng.random() < 0.2:
            _damage_structure(b, hot, rng)
            continue
        kind = KINDS[int(rng.integers(len(KINDS)))]
        n = len(b)
        if n == 0:
            break
        if kind == "flip":
            for i in rng.integers(0, n, int(rng.integers(1, 9))):
                if rng.random() < 0.5:
                    b[int(i)] ^= 1 << int(rng.integers(8))
                else:
                    b[int(i)] = int(rng.integers(256))
        elif kind == "truncate":
            del b[int(rng.integers(0, n)):]
        elif kind == "insert":
            at = int(rng.integers(0, n + 1))
            b[at:at] = rng.integers(0, 256, int(rng.integers(1, 65)), dtype=np.uint8).tobytes()
        elif kind == "delete":
            at = int(rng.integers(0, n))
            del b[at:at + int(rng.integers(1, 65))]
        elif kind == "duplicate":
            at = int(rng.integers(0, n))
            ln = int(rng.integers(1, 513))
            chunk = bytes(b[at:at + ln])
            to = int(rng.integers(0, n + 1))
            b[to:to] = chunk
        else:  # header: damage within the first 4 KiB, where formats and definitions live
            lim = min(n, 4096)
            for i in rng.integers(0, lim, int(rng.integers(1, 5))):
                b[int(i)] = int(rng.integers(256))
    return bytes(b)


def _damage_structure(b: bytearray, hot: np.ndarray, rng: np.random.Generator) -> None:
    """One damage at a structural offset (earlier damages may have shifted it: it stays a byte of the file)."""
    n = len(b)
    if n == 0:
        return
    at = int(hot[int(rng.integers(len(hot)))]) % n
    op = int(rng.integers(6))
    if op == 0:
        b[at] = int(rng.integers(256))
    elif op == 1:
        b[at] = 0
    elif op == 2:
        b[at] = 0xFF
    elif op == 3:
        b[at] = (b[at] + (1 if rng.random() < 0.5 else -1)) % 256
    elif op == 4:
        b[at] = b[int(hot[int(rng.integers(len(hot)))]) % n]
    else:
        width = 2 if rng.random() < 0.5 else 4
        value = int(rng.integers(0, 1 << (8 * width)))
        b[at:at + width] = struct.pack("<H" if width == 2 else "<I", value)[:max(0, n - at)]


def hot_offsets(ext: str, data: bytes) -> np.ndarray:
    """Offsets of the structure of an intact log ``data`` of kind ``ext`` (tlog, bin, ulg, csv)."""
    out: list = []
    if ext == "bin":
        from companion.sources.dataflash import FMT_TYPE, index

        log = index(np.frombuffer(data, dtype=np.uint8))
        for t, off in log.offsets.items():
            for p in off.tolist():
                out += range(p, p + (89 if t == FMT_TYPE else 11))  # header, type, FMT body / time stamp
    elif ext == "tlog":
        from companion.sources.tlog import scan

        idx = scan(data)
        for p, hl in zip(idx.pos.tolist(), idx.header_len.tolist()):
            out += range(max(p - 8, 0), p + hl)  # record stamp, magic, length, flags, seq, ids, message id
    elif ext == "ulg":
        out += range(0, min(16, len(data)))
        p = 16
        while p + 3 <= len(data):
            size, typ = struct.unpack_from("<HB", data, p)
            body = {ord("F"): size, ord("A"): 3, ord("D"): 2, ord("B"): 40, ord("P"): 1 + data[p + 3] if p + 3 < len(data) else 0}
            out += range(p, p + 3 + min(body.get(typ, 0), size))
            p += 3 + size
    else:
        first = data.find(b"\n")
        out += range(0, max(first, 0) + 1)
        out += [i for i, c in enumerate(data[:65536]) if c in b",\n-.eE"]
    return np.unique(np.asarray(out, dtype=np.int64))


def check(name: str, data: bytes, workdir) -> tuple[str, str]:
    """Load ``data`` as a file called ``name`` in ``workdir``: ("ok" | "refused" | "traceback" | "invalid",
    detail). "invalid": loaded, but a stream breaks the promises of :class:`companion.samples.ImuStream`
    (times finite and strictly increasing within each segment, no infinite values): silently wrong numbers.
    A traceback's detail starts with its signature line (:func:`signature`), then the traceback."""
    from companion.errors import CompanionError
    from companion.sources import load

    path = Path(workdir) / name
    path.write_bytes(data)
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            res = load(str(path))
        kind, detail = "ok", f"{len(res.imu_streams())} streams"
        broken = [f"{s.key.label()}: {why}" for s in res.streams for why in [broken_promise(s)] if why]
        if broken:
            kind, detail = "invalid", "; ".join(broken)
    except CompanionError as exc:
        kind, detail = "refused", str(exc)
    except Exception as exc:  # noqa: BLE001 - this is what the fuzzer looks for
        kind, detail = "traceback", signature(exc) + "\n" + traceback.format_exc()
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
    if out.getvalue() and kind != "traceback":
        kind, detail = "traceback", "stdout written by the reader: " + out.getvalue()[:200]
    return kind, detail


def broken_promise(s) -> str | None:
    """What is wrong with a loaded stream's numbers (None: nothing)."""
    t = s.t
    if not np.all(np.isfinite(t)):
        return f"{int(np.count_nonzero(~np.isfinite(t)))} non-finite sample times"
    for a, b in s.segments:
        if b - a > 1 and not np.all(np.diff(t[a:b]) > 0):
            return f"times not increasing within segment {a}-{b}"
    for what, v in (("gyro", s.gyro), ("accel", s.accel), ("temperature", s.temperature)):
        if v is not None and np.any(np.isinf(v)):
            return f"{int(np.count_nonzero(np.isinf(v)))} infinite {what} values"
    return None


def signature(exc: BaseException) -> str:
    """``Type at file:line in function`` of the innermost companion frame (else the innermost one): the
    class of a traceback, to count distinct bugs rather than inputs."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if "/companion/" in f.filename.replace(os.sep, "/")]
    f = (ours or frames or [None])[-1]
    where = f"{Path(f.filename).name}:{f.lineno} in {f.name}" if f else "?"
    msg = str(exc).splitlines()[0][:100] if str(exc) else ""
    return f"{type(exc).__name__} at {where}: {msg}"


def seeds_of(data: bytes, count: int, seed: int, hot: np.ndarray | None = None):
    """``count`` mutated copies of ``data`` from one seed: (index, mutated bytes)."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        yield i, mutate(data, rng, hot)
