"""Why little can be estimated from a source, stream by stream (the sentences ``inspect`` and ``analyze`` print)."""

from __future__ import annotations

import math

from companion.analysis.sufficiency import LONG_TERMS_S, SHORT_TAU_RATE_HZ, fast_enough
from companion.health.dead import dead_gyro_text


def notes(res) -> list[str]:
    """Why little can be estimated, stream by stream (plain sentences)."""
    out = list((getattr(res, "meta", None) or {}).get("notes", []))
    fmt = (getattr(res, "meta", None) or {}).get("format")
    for s in res.streams:
        lab = s.key.label()
        if not s.is_imu:
            out.append(f"{lab}: accel and gyro are zero in every sample: a compass-only instance, not an IMU.")
            continue
        dead = dead_gyro_text(lab, s.gyro, getattr(s, "gyro_lsb", None))
        if dead:
            out.append(dead)
        t = s.timing
        if t.damaged:
            out.append(f"{lab}: {t.damaged} sample(s) with a non-finite time or an impossible value skipped "
                       "(damaged records).")
        if t.duplicates or t.backwards or t.resets:
            out.append(f"{lab}: dropped {t.duplicates} duplicate and {t.backwards} backward timestamps; "
                       f"{t.resets} reboot(s) (time reset) -> {len(s.segments)} segments.")
        if s.samples < 2 or not math.isfinite(t.rate_hz):
            out.append(f"{lab}: too few samples for any estimate.")
            continue
        a, b = s.longest_segment()
        longest = float(s.t[b - 1] - s.t[a]) if b > a else 0.0
        if not fast_enough(t.rate_hz, SHORT_TAU_RATE_HZ):
            out.append(f"{lab}: only {t.rate_hz:.3g} Hz: the Allan curve starts at tau = {1 / t.rate_hz:.3g} s, "
                       "so quantisation and white noise (Q, N) are aliased together; " + _faster_hint(fmt, s.key.message))
        if longest < LONG_TERMS_S:
            out.append(f"{lab}: longest contiguous segment {longest:.0f} s: even at rest throughout, Allan deviation "
                       f"would reach tau of about {longest / 10:.3g} s with useful confidence; bias instability and "
                       "rate random walk need hours at rest.")
        if s.gyro_lsb and s.samples:
            import numpy as np

            sd = float(np.median(np.std(s.gyro[a:b], axis=0))) if b - a > 1 else 0.0
            if sd < 2 * s.gyro_lsb:
                out.append(f"{lab}: gyro noise (std {sd:.2g} rad/s) is within 2 LSB ({s.gyro_lsb:.2g} rad/s): "
                           "int16 quantisation dominates the short-tau Allan deviation.")
    return out


def _faster_hint(fmt, message: str) -> str:
    if fmt == "dataflash":
        return ("log the IMU faster (INS_LOG_BAT_MASK / INS_LOG_BAT_OPT batch sampler, or LOG_BITMASK IMU_FAST, "
                "or INS_RAW_LOG_OPT) for a usable estimate.")
    if fmt == "ulog":
        return ("log this topic at full rate (SDLOG_PROFILE high rate / sensor_gyro_fifo) for a usable estimate.")
    if fmt == "csv":
        return "record faster for a usable estimate."
    return "stream RAW_IMU faster (SRn_RAW_SENS or MAV_CMD_SET_MESSAGE_INTERVAL) for a usable estimate."
