"""Two IMUs' samples at common instants for the in-flight noise (service/inflight_live.py), and which IMUs' pairs
it suspends (an IMU held dead, stuck or saturated)."""

from __future__ import annotations

import numpy as np

# the disagreement test's choice of common instants and its minimum count
from companion.service.imu_group import MIN_ALIGNED, SAME_RATE, _period


def aligned(ci, cj, t_done: float):
    """(t, gi, gj) of two channels' recent blocks after ``t_done``, at the slower stream's instants (the
    faster one linearly interpolated there, only within 1.5 of its periods of a sample), or None."""
    ti = np.concatenate([b[0] for b in ci.recent])
    tj = np.concatenate([b[0] for b in cj.recent])
    gi = np.concatenate([b[1] for b in ci.recent])
    gj = np.concatenate([b[1] for b in cj.recent])
    pi_, pj_ = _period(ti), _period(tj)
    base_i = pi_ >= pj_ or pj_ <= SAME_RATE * pi_
    (ts, gs), (tf, gf), pf = ((ti, gi), (tj, gj), pj_) if base_i else ((tj, gj), (ti, gi), pi_)
    t_end = min(ti[-1], tj[-1])
    mask = (ts > t_done) & (ts <= t_end) & (ts >= tf[0])
    if np.count_nonzero(mask) < MIN_ALIGNED:
        return None
    t = ts[mask]
    k = np.clip(np.searchsorted(tf, t), 1, tf.size - 1)
    ok = np.minimum(np.abs(tf[k] - t), np.abs(tf[k - 1] - t)) <= 1.5 * pf
    if np.count_nonzero(ok) < MIN_ALIGNED:
        return None
    t = t[ok]
    g_slow = gs[mask][ok]
    g_fast = np.column_stack([np.interp(t, tf, gf[:, a]) for a in range(3)])
    return (t, g_slow, g_fast) if base_i else (t, g_fast, g_slow)


#: fault kinds of an IMU (health/monitor.py ImuFaults) that suspend its pairs: its gyro does not follow the
#: body, so a pair's difference is the body's motion, not the IMUs' noise (the fault itself names the IMU)
SUSPEND_KINDS = ("dead", "stuck", "saturation")


def _held_faulty(ch) -> bool:
    faults = getattr(ch, "faults", None)
    return faults is not None and any(k in SUSPEND_KINDS for k, _ in faults.active())
