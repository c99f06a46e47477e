"""Write a copy of a tlog whose gyro of one IMU message type reads 0 from a given time on (a gyro dying
mid-flight), or is changed by any function of its int16 values (:func:`edit_gyro`: clipped, biased), for
the figures of bench_telemetry_rates.py.

The frames are found by the project's walker (companion.sources.tlog.scan); in each selected frame the
xgyro, ygyro, zgyro bytes are set to the new values and the frame's CRC is recomputed (CRC-16/MCRF4XX with the
message's CRC_EXTRA, companion.sources.messages.crc_x25_rows); every other byte is copied as it was.
"From the middle on" is from the middle one of the message's frames in file order; that frame's message
time (time_boot_ms / time_usec) is the onset the benchmark measures delays from.

    python -m benchmarks.tlog_zero_gyro IN.tlog OUT.tlog --message RAW_IMU [--from-s T]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from companion.sources import messages as M
from companion.sources import tlog


def zero_gyro(src, dst, message: str, from_frac: float = 0.5, from_s: float | None = None) -> dict:
    """Copy ``src`` to ``dst`` with the gyro of ``message`` (sysid of its first frame) set to 0 in every
    frame at or after ``from_s`` of message time (default: every frame from the one ``from_frac`` of the
    way through its frames, in file order). Returns {"t0": the first zeroed frame's time (s), "frames":
    frames zeroed, "total": frames}."""
    return edit_gyro(src, dst, message, np.zeros_like, from_frac, from_s)


def gyro_values(src, message: str) -> tuple[np.ndarray, np.ndarray]:
    """(t, gyro int16 (n, 3)) of ``message`` (sysid of its first frame) in file order."""
    idx, sel, lay = _frames(tlog.read_file(Path(src)), message, src)
    rec = idx.payloads(sel, lay.full_len).view(lay.dtype).reshape(-1)
    return _times(rec, lay), np.column_stack([rec[f] for f in ("xgyro", "ygyro", "zgyro")])


def _frames(data, message: str, src):
    idx = tlog.scan(data)
    lay = M.IMU_LAYOUTS[message]
    sel = np.flatnonzero(idx.msgid == lay.msgid)
    if sel.size == 0:
        raise SystemExit(f"tlog_zero_gyro: no {message} in {src}")
    return idx, sel[idx.sysid[sel] == idx.sysid[sel[0]]], lay


def _times(rec, lay) -> np.ndarray:
    tname = lay.dtype.names[0]
    return rec[tname].astype(np.float64) * (1e-6 if tname == "time_usec" else 1e-3)


def edit_gyro(src, dst, message: str, fn, from_frac: float = 0.5, from_s: float | None = None) -> dict:
    """:func:`zero_gyro` with the gyro set to ``fn(gyro)`` (int16 (n, 3) in, the same shape out) instead of 0.
    A value that would need a byte a MAVLink 2 frame cut at its trailing zeros does not hold is left as it
    was; ``"kept"`` counts them."""
    data = tlog.read_file(Path(src))
    idx, sel, lay = _frames(data, message, src)
    rec = idx.payloads(sel, lay.full_len).view(lay.dtype).reshape(-1)
    t = _times(rec, lay)
    if from_s is None:  # from the middle frame on, in file order (a log with a reboot restarts its time)
        k0 = int(from_frac * (t.size - 1))
        t0, k = float(t[k0]), np.arange(k0, t.size)
    else:
        t0 = float(from_s)
        k = np.flatnonzero(t >= t0)
    hit = sel[k]
    old = np.column_stack([rec[f][k] for f in ("xgyro", "ygyro", "zgyro")])
    new = np.clip(np.rint(fn(old.astype(np.float64))), -32768, 32767).astype("<i2")
    buf = idx.buf.copy()
    offs = [lay.dtype.fields[f][1] for f in ("xgyro", "ygyro", "zgyro")]
    kept = 0
    for r, f in enumerate(hit.tolist()):
        start = int(idx.pos[f] + idx.header_len[f])
        ln = int(idx.length[f])
        for a, o in enumerate(offs):
            b = new[r, a].tobytes()
            if o + 1 < ln:
                buf[start + o], buf[start + o + 1] = b[0], b[1]
            elif new[r, a] != 0:  # a MAVLink 2 payload cut at its trailing zeros holds 0 there
                kept += 1
        body = buf[int(idx.pos[f]) + 1:start + ln][None, :]
        crc = int(M.crc_x25_rows(body, lay.crc_extra)[0])
        buf[start + ln] = crc & 0xFF
        buf[start + ln + 1] = crc >> 8
    Path(dst).write_bytes(buf.tobytes())
    return {"t0": t0, "frames": int(hit.size), "total": int(sel.size), "kept": kept}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("src")
    p.add_argument("dst")
    p.add_argument("--message", default="RAW_IMU", choices=sorted(M.IMU_LAYOUTS))
    p.add_argument("--from-s", type=float, default=None, help="message time (s) from which the gyro reads 0 "
                   "(default: half-way through the message's frames)")
    a = p.parse_args(argv)
    r = zero_gyro(a.src, a.dst, a.message, from_s=a.from_s)
    print(f"{a.message}: gyro 0 from {r['t0']:.1f} s: {r['frames']} of {r['total']} frames")


if __name__ == "__main__":
    main()
