"""Saving and restoring the run state (baseline, estimator and detector state) atomically.

The state is one JSON file. Saving writes a temporary file in the same directory, flushes and fsyncs
it, then renames it over the old one (``os.replace``: atomic on POSIX), so a power cut leaves either
the old or the new state, never a torn file. Loading never crashes: a missing file is a fresh start, a
corrupt or foreign file (not JSON, another format, another vehicle) gives one warning line and a fresh
start (the bad file is kept next to it as ``<name>.bad`` for inspection).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Callable


def save_state(path, state: dict) -> None:
    """Write ``state`` (JSON-serialisable) to ``path`` atomically (temp file + fsync + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(state, fh, separators=(",", ":"), allow_nan=True)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:  # make the rename itself durable
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


FINGERPRINT_BYTES = 1 << 20  # bytes hashed at each end of a log: enough to tell logs apart, cheap on a 1-GB log


def fingerprint(path) -> dict:
    """What identifies a log's content whatever its name or place: its size and the SHA-256 of its size and
    its first and last ``FINGERPRINT_BYTES`` (a copy or a renamed file is the same log; reading a 1-GB log
    whole for this is not needed)."""
    path = Path(path)
    size = path.stat().st_size
    h = hashlib.sha256(str(size).encode())
    with open(path, "rb") as fh:
        h.update(fh.read(FINGERPRINT_BYTES))
        if size > FINGERPRINT_BYTES:
            fh.seek(max(FINGERPRINT_BYTES, size - FINGERPRINT_BYTES))
            h.update(fh.read())
    return {"sha256": h.hexdigest(), "size": size, "name": path.name}


def load_state(path, restore: Callable[[dict], None], warn: Callable[[str], None]) -> bool:
    """Read ``path`` and hand it to ``restore`` (which raises ValueError/KeyError/TypeError if it is not
    usable). Returns True when restored; on any problem calls ``warn`` once and returns False."""
    path = Path(path)
    if not path.exists():
        return False
    try:
        with open(path) as fh:
            data = json.load(fh)
        restore(data)
        return True
    except (OSError, ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
        bad = path.with_name(path.name + ".bad")
        try:
            os.replace(path, bad)
            kept = f"; kept as {bad}"
        except OSError:
            kept = ""
        warn(f"state file {path} not usable ({type(exc).__name__}: {str(exc)[:120]}); starting fresh{kept}")
        return False
