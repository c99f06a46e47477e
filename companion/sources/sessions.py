"""Boot sessions of one log laid end to end on one time axis.

A log that spans autopilot reboots (a ground station's tlog across a power cycle; ULog or DataFlash files
written across a restart) has message times that start again at each boot. Every stream keeps its samples in
file order, split into segments at the resets (:mod:`companion.sources.timestamps`), but the still selection,
the armed intervals and ``--start/--end`` work on one time axis: with the times of several sessions
overlapping, a record would run backwards (its last sample before its first) and could not be analysed.

:func:`join_sessions` shifts every session after the first so that it starts ``SESSION_GAP_S`` after the
previous one ended (the gap keeps them separate segments and the still selection's guards apart), the same
shift for every stream and for the armed transitions of that session, and says so in a note. The samples,
their order and the segments are unchanged; only the times of later sessions move.

Sessions are the reference stream's (the IMU stream with the most samples): its resets, in file order. Another
stream's k-th session is the reference's k-th where both have the same number; otherwise each of its sessions
goes to the reference session whose span overlaps it most, in order. Armed transitions (file order) move to
the next session where their time steps back by more than the reset threshold.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

SESSION_GAP_S = 60.0  # s between the end of one session and the start of the next, once joined
#: a time since boot beyond this (116 days; time_boot_ms wraps at 49.7) is a damaged timestamp, not a boot:
#: the log is left as it is (a mutated log's one sample at 1.2e13 s made a "session" whose end pushed the next
#: by 1.2e13 s, where float64 time has a resolution of 2 ms and consecutive samples became equal)
MAX_TIME_S = 1e7
RESET_S = 1.0  # a step back by more than this is a reboot (the timing rules' smallest reset threshold)


def _sessions(t: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges of the runs of ``t`` between steps back (the kept samples only step back at resets)."""
    if t.size == 0:
        return []
    cut = np.flatnonzero(np.diff(t) < -RESET_S) + 1
    edges = np.r_[0, cut, t.size]
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def join_sessions(res):
    """``res`` (a :class:`companion.sources.LoadResult`) with later boot sessions shifted to follow the
    earlier ones (see the module docstring); ``res`` itself where the log has one session."""
    imus = [s for s in res.streams if s.samples >= 2]
    if not imus:
        return res
    ref = max(imus, key=lambda s: s.samples)
    ref_sess = _sessions(ref.t)
    if len(ref_sess) < 2:
        return res
    spans = [(float(ref.t[a]), float(ref.t[b - 1])) for a, b in ref_sess]
    if any(not (abs(a) < MAX_TIME_S and abs(b) < MAX_TIME_S) for a, b in spans):
        return res
    offsets, end = [0.0], spans[0][1]
    for a, b in spans[1:]:
        offsets.append(end + SESSION_GAP_S - a)
        end = end + SESSION_GAP_S + (b - a)
    streams = [_shift(s, spans, offsets) for s in res.streams]
    meta = dict(res.meta)
    if meta.get("armed"):
        meta["armed"] = _shift_events(meta["armed"], len(spans), offsets)
    note = (f"{len(spans)} boot sessions (the message time starts again at each reboot): analysed on one time "
            "axis, each session after the first shifted to start " + f"{SESSION_GAP_S:.0f} s after the one before ("
            + ", ".join(f"session {k + 1} at {spans[k][0]:.1f}-{spans[k][1]:.1f} s shifted by {offsets[k]:+.1f} s"
                        for k in range(1, len(spans))) + "; --start/--end take the shifted times)")
    meta["notes"] = list(meta.get("notes") or []) + [note]
    meta["sessions"] = [{"span": list(sp), "shift_s": off} for sp, off in zip(spans, offsets)]
    return replace(res, streams=streams, meta=meta)


def _shift(stream, spans, offsets):
    sess = _sessions(stream.t)
    if not sess:
        return stream
    t = stream.t.copy()
    if len(sess) == len(spans):
        owner = list(range(len(sess)))
    else:  # the reference session each of this stream's sessions overlaps most, never going back
        owner, k = [], 0
        for a, b in sess:
            lo, hi = float(stream.t[a]), float(stream.t[b - 1])
            over = [min(hi, sb) - max(lo, sa) for sa, sb in spans]
            best = max(range(k, len(spans)), key=lambda i: over[i])
            owner.append(best)
            k = best
    for (a, b), k in zip(sess, owner):
        t[a:b] += offsets[k]
    return replace(stream, t=t)


def _shift_events(events, n_sessions, offsets):
    out, k, prev = [], 0, None
    for t, v in events:
        if prev is not None and t < prev - RESET_S and k + 1 < n_sessions:
            k += 1
        prev = t
        out.append((t + offsets[k], v))
    return out
