"""A seeded mutation fuzzer for the file readers (used by tests/test_fuzz.py and benchmarks/bench_fuzz.py).

``mutate(data, rng)`` applies 1-4 random damages of the kinds a log meets in practice: bit/byte flips,
truncation (a log cut mid-record), inserted garbage, deleted bytes, duplicated chunks (a write repeated by
a flaky SD card) and damage to the first bytes (file header, DataFlash FMT records, ULog definitions).
``check(name, data, workdir)`` writes the mutated bytes under the reader's file name and loads them with
``companion.sources.load``: the outcome is ``"ok"`` (loaded, damaged records counted), ``"refused"`` (one
CompanionError line) or ``"traceback"`` (any other exception: a bug), with the text of the error.
Everything is deterministic for a given seed.
"""

from __future__ import annotations

import contextlib
import io
import os
import traceback
from pathlib import Path

import numpy as np

KINDS = ("flip", "truncate", "insert", "delete", "duplicate", "header")


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """1-4 random damages of ``data`` (see the module docstring)."""
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
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


def check(name: str, data: bytes, workdir) -> tuple[str, str]:
    """Load ``data`` as a file called ``name`` in ``workdir``: ("ok" | "refused" | "traceback", detail)."""
    from companion.errors import CompanionError
    from companion.sources import load

    path = Path(workdir) / name
    path.write_bytes(data)
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            res = load(str(path))
        detail = f"{len(res.imu_streams())} streams"
        kind = "ok"
    except CompanionError as exc:
        kind, detail = "refused", str(exc)
    except Exception:  # noqa: BLE001 - this is what the fuzzer looks for
        kind, detail = "traceback", traceback.format_exc()
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
    if out.getvalue() and kind != "traceback":
        kind, detail = "traceback", "stdout written by the reader: " + out.getvalue()[:200]
    return kind, detail


def seeds_of(data: bytes, count: int, seed: int):
    """``count`` mutated copies of ``data`` from one seed: (index, mutated bytes)."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        yield i, mutate(data, rng)
