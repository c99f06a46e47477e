"""One axis of one IMU stream as a contiguous series at rest: what ``compensate`` works on.

:func:`select_series` picks the stream, checks it carries the axis, takes the longest still, gap-free piece
(:func:`companion.sources.still.longest_still_range`) and refuses, with one error line that says what to
do instead, a piece too short for the analysis or one whose samples are all equal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.errors import CompanionError
from companion.units import rate_display


@dataclass
class AxisSeries:
    """Samples ``z`` (SI) at times ``t`` (s) of one axis, at ``rate_hz``, from the stream named ``label``."""

    t: np.ndarray
    z: np.ndarray
    rate_hz: float
    label: str


def has_axis(stream, axis: str) -> bool:
    """Whether the stream carries data for ``axis`` (a batch-sampler burst of one sensor has NaN for the other)."""
    return bool(np.any(np.isfinite(stream.axis(axis))))


def _stream(res, axis: str, stream_index: int):
    """(the IMU streams of ``res``, the one ``stream_index``, which must carry ``axis``)."""
    from companion.samples import GYRO_AXES

    streams = res.imu_streams()
    if not streams:
        raise CompanionError(f"{res.source}: no IMU stream")
    if not 0 <= stream_index < len(streams):
        labels = "; ".join(f"{i}: {s.key.label()}" for i, s in enumerate(streams))
        raise CompanionError(f"--stream {stream_index} out of range; IMU streams: {labels}")
    s = streams[stream_index]
    kind = "gyro" if axis in GYRO_AXES else "accel"
    if not has_axis(s, axis):
        other = "accel" if kind == "gyro" else "gyro"
        usable = [f"{i}: {o.key.label()}" for i, o in enumerate(streams) if has_axis(o, axis)]
        where = (f"{kind} streams: {'; '.join(usable)} (choose one with --stream I)" if usable
                 else f"this source has no {kind} stream")
        raise CompanionError(f"{s.key.label()} (--stream {stream_index}) has no {kind} data ({other} only); {where}")
    return streams, s


def select_series(res, axis: str, stream_index: int, max_samples: int | None, min_samples: int,
                  purpose: str, warn=None) -> AxisSeries:
    """The longest still, gap-free piece of ``axis`` of IMU stream ``stream_index`` of the loaded source
    ``res`` (its first ``max_samples``); at least ``min_samples`` long (``purpose`` names what needs them).
    ``warn`` (a callable) is told when no still piece exists and the longest segment is used."""
    from companion.sources.still import longest_still_range

    streams, s = _stream(res, axis, stream_index)
    a, b = longest_still_range(res, s, warn=warn)
    if max_samples is not None:
        if max_samples < 1:
            raise CompanionError("--max-samples must be at least 1")
        b = min(b, a + max_samples)
    rate = float(s.rate_hz)
    if not rate > 0:
        raise CompanionError(f"{s.key.label()}: no usable sample rate")
    if b - a < min_samples:
        longer = [f"{i}: {o.key.label()} ({o.samples} samples)" for i, o in enumerate(streams)
                  if i != stream_index and o.samples >= min_samples and has_axis(o, axis)]
        hint = f"; streams with more data: {'; '.join(longer)}" if longer else ""
        raise CompanionError(f"{s.key.label()} {axis}: {b - a} samples ({(b - a) / rate:.1f} s at {rate:g} Hz) are too "
                             f"few for {purpose} (need at least {min_samples}){hint}")
    z = np.asarray(s.axis(axis)[a:b], dtype=float)
    if np.all(z == z[0]):
        scale, unit = rate_display(axis)
        raise CompanionError(f"{s.key.label()} {axis}: all {b - a} samples are {z[0] * scale:g} {unit} "
                             f"(stuck, absent or not logged): nothing to compensate")
    return AxisSeries(s.t[a:b], z, rate, s.key.label())
