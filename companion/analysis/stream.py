"""The report entry of one IMU stream: every axis analysed over the still ranges, with warnings."""

from __future__ import annotations

import math

import numpy as np

from companion.analysis.axis import analyze_axis
from companion.analysis.sufficiency import FIT_MIN_RATE_HZ, FIT_MIN_SECONDS, fast_enough
from companion.samples import GYRO_AXES


def analyze_stream(stream, axes, taus, progress=None, online=False, ranges=None, filters=None) -> dict:
    """The JSON ``streams`` entry of one :class:`companion.samples.ImuStream`.

    ``ranges``: index ranges to analyse (the still segments, pooled); None: the longest segment.
    ``filters``: {"gyro": Hz, "accel": Hz} low-pass cut-offs of the logged data (modelled in the white-noise
    term of the offline fit and of the online report). The entry carries ``warnings`` (rate < 10 Hz, < 60 s analysed) and the stream's timing.
    """
    if ranges is None:
        ranges = [stream.longest_segment()] if stream.samples else []
    rate = float(stream.rate_hz)
    used = sum(b - a for a, b in ranges)
    secs = sum(float(stream.t[b - 1] - stream.t[a]) + (1.0 / rate if rate > 0 else 0.0) for a, b in ranges if b > a)
    t = stream.timing
    entry = {"message": stream.key.message, "instance": stream.key.instance, "sysid": stream.key.sysid,
             "compid": stream.key.compid, "rate_hz": rate, "samples": int(used), "duration_s": float(secs),
             "segments": len(stream.segments) or 1, "still_segments": len(ranges),
             "ranges_s": [[float(stream.t[a]), float(stream.t[b - 1])] for a, b in ranges if b > a],
             "timing": {"gaps": t.gaps, "duplicates": t.duplicates, "backwards": t.backwards, "resets": t.resets},
             "filters_hz": dict(filters or {}), "warnings": [], "axes": {}}
    if not fast_enough(rate, FIT_MIN_RATE_HZ):
        entry["warnings"].append(f"only {rate:.3g} Hz (< {FIT_MIN_RATE_HZ:g} Hz): the Allan curve starts at "
                                 f"{1 / rate if rate > 0 else float('inf'):.3g} s, N is aliased with every faster effect")
    if secs < FIT_MIN_SECONDS:
        shown = math.floor(secs * 100) / 100  # rounded down: never "only 0 s" nor "only 60 s (< 60 s)"
        entry["warnings"].append(f"only {shown:g} s analysed (< {FIT_MIN_SECONDS:g} s): too few clusters for a usable N")
    for axis in axes:
        lsb = stream.gyro_lsb if axis in GYRO_AXES else stream.accel_lsb
        fc = (filters or {}).get("gyro" if axis in GYRO_AXES else "accel")
        if not (rate > 0 and math.isfinite(rate)):
            entry["axes"][axis] = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [],
                                   "status": "too_short", "note": "no sample rate"}
        else:
            col = stream.axis(axis)
            samp = stream_sampling(stream)
            entry["axes"][axis] = axis_entry(stream, axis, ranges, filters, taus, lsb=lsb)
            if online and entry["axes"][axis]["status"] == "ok":
                from companion.estimators import make_estimator

                # the online estimator over the same still pieces, pooled as the offline analysis pools them
                # (no cluster straddles a junction; the report's covariance is the pooled one)
                est = make_estimator("octave", rate_hz=rate, filter_hz=float(fc) if fc else None, sampling=samp)
                for a, b in ranges:
                    y = col[a:b]
                    y = y[np.isfinite(y)]
                    if y.size >= 8:  # as the offline analysis: shorter pieces carry no cluster
                        est.new_segment()
                        est.update(y)
                entry["axes"][axis]["online"] = est.terms(full=True)
        if progress:
            progress.step(f"{stream.key.message}[{stream.key.instance}] {axis}")
    return entry


def axis_entry(stream, axis: str, ranges, filters=None, taus="octave", lsb=None) -> dict:
    """The analysis of one axis of ``stream`` over the index ``ranges`` (pooled), with the low-pass cut-off
    of ``filters`` modelled as the log's signal path has it (:func:`stream_sampling`): the one estimate
    ``analyze``, ``gap`` and the Kalibr file report. ``lsb``: the output step (None: the stream's)."""
    if lsb is None:
        lsb = stream.gyro_lsb if axis in GYRO_AXES else stream.accel_lsb
    col = stream.axis(axis)
    return pieces_entry([col[a:b] for a, b in ranges], float(stream.rate_hz), axis, stream.key.message, filters,
                        taus, lsb)


def pieces_entry(pieces, rate_hz: float, axis: str, message: str, filters=None, taus="octave", lsb=None) -> dict:
    """The analysis of one axis over still ``pieces`` (arrays of one axis' samples at ``rate_hz``, pooled) of a
    stream of IMU ``message``: the function behind :func:`axis_entry`, and the final report of ``companion run``
    on the still blocks it kept (:mod:`companion.service.still_record`), so both give one figure for one set of
    samples. ``filters``: {"gyro": Hz, "accel": Hz}; ``lsb``: the output step (None: none modelled)."""
    from companion.analysis.filters import sampling

    fc = (filters or {}).get("gyro" if axis in GYRO_AXES else "accel")
    samp = sampling(message)
    wf = {"filter_hz": float(fc), "sample_hz": rate_hz if samp == "point" else None} if fc else None
    return analyze_axis(None, rate_hz, taus, lsb=lsb, segments=list(pieces), white_filter=wf, sampling=samp)


def stream_sampling(stream) -> str:
    """How a stream's samples were taken from its filtered signal (:func:`companion.analysis.filters.sampling`)."""
    from companion.analysis.filters import sampling

    return sampling(stream.key.message)


def stream_filters(stream, meta: dict) -> dict:
    """Low-pass cut-offs (Hz) of a stream's logged data from the log's parameters (empty if unknown): DataFlash
    and ULog parameters, a tlog's PARAM_VALUE messages (:func:`companion.analysis.filters.filters_from_params`)."""
    from companion.analysis.filters import filters_from_params

    meta = meta or {}
    return filters_from_params(meta.get("params"), stream.key.message, meta.get("format"))
