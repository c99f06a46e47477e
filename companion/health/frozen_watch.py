"""A gyro axis that holds one value while the vehicle visibly moves: dead (exactly 0) or frozen, at any rate.

The block tests (health/stuck.py) need several samples per 1-s block; a telemetry stream at 1-4 Hz (a
ground station's tlog, a busy radio link) gives one to four. This test works sample by sample instead,
on pairs of consecutive samples of one IMU, whatever the rate:

* a pair is *equal* on an axis when both samples read exactly the same value;
* it is *motion* on that axis when the vehicle's rotation visibly changed between the two instants:
  another IMU's same axis moved by at least ``TWIN_STEP`` (0.05 rad/s = 50 steps of RAW_IMU's 1 mrad/s)
  between its samples nearest to them, or, when all three axes of this gyro are equal, the accelerometer
  turned by at least ``ACCEL_TURN`` (0.1 rad) or changed by at least ``ACCEL_STEP`` (2 m/s^2).

A live gyro reads a new value when its rotation changes by 50 of its steps (its noise in motion is several
steps too): on the real tlogs of benchmarks/bench_telemetry_rates.py (1-4 Hz copters, hexacopter, ROV,
SITL; 8 healthy IMU streams, 5 of them with a twin) not one equal pair was motion, among some 2000 pairs
where the twin moved. An axis is named after ``NEED`` (6) motion pairs within one run of equal values:
"dead" when the value is exactly 0, "stuck" otherwise; it clears after ``CLEAR`` (3) pairs in a row that
change. How many samples that takes depends on how often the vehicle moves, not on the rate: a copter
flying at 1 Hz gives a motion pair every 3 samples or so (about 20 samples), a vehicle at rest none.

At rest (calm pairs: no twin moving, the accelerometer still) a gyro that resolves its own noise changes
value in a share p of the pairs, learned per axis (CALM_*): where p >= 0.8, L calm equal pairs with
(1 - (p - 0.25))^L < 1e-12 name it too (about 20 samples at p = 0.9; "reads exactly 0: dead"). An int16
gyro quieter than its 1 mrad/s step (ArduPilot SITL) has p far below that and reads 0 at rest by
resolution: this test never names it, and the summary says so once it changed values in motion.

Pure numpy; the caller (service/frozen_hook.py) hands it each IMU's samples in message-time order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.health.faults import FaultEvent
from companion.health.hold import FAULT, OK

AXES = ("gx", "gy", "gz")
TWIN_STEP = 0.05  # rad/s: a twin axis moving this much between two instants is motion on that axis
ACCEL_TURN = 0.1  # rad: the accelerometer turning this much between two samples is motion
ACCEL_STEP = 2.0  # m/s^2: or changing this much
NEED = 6  # motion pairs within one run of equal values that name the axis
CLEAR = 3  # pairs in a row that change, which clear it
#: at rest (no twin moving, the accelerometer within CALM_TURN and CALM_STEP between the two samples) a gyro
#: that resolves its own noise changes value in a share p of the pairs, learned over CALM_LEARN calm pairs;
#: where p >= CALM_P an axis holding one value for L calm pairs with (1 - (p - CALM_MARGIN))^L < CALM_ALPHA
#: is named too (a single IMU that died while its vehicle rests); a gyro quieter than its step never is
CALM_TURN = 0.02  # rad
CALM_STEP = 0.3  # m/s^2
CALM_LEARN = 100
CALM_STREAK = 5  # equal pairs in a row beyond which calm pairs are not learned (a dead run would lower p)
CALM_P = 0.8
CALM_MARGIN = 0.25
CALM_ALPHA = 1e-12
HISTORY_S = 30.0  # seconds of samples kept per IMU (the twins' look-up, the pending pairs)
REST_ZERO_SHARE = 0.5  # below resolution: at least this share of the pairs at rest read 0 twice in a row (a gyro
# whose noise spans 2-3 steps does so on about 2 % of its pairs; one quieter than its step on nearly all)
WAIT_S = 5.0  # a pair waits for the other IMUs' samples up to this long, then is judged with what there is


@dataclass
class AxisRun:
    """The run of equal values of one axis: its motion pairs so far, the changes in a row, the state."""

    motion: float = 0.0  # evidence of the run so far: 1 names it (NEED motion pairs, or calm pairs, see CALM_P)
    changes: int = 0
    state: int = OK
    value: float = math.nan
    kind: str = "dead"  # what it was named: "dead" (exactly 0) or "stuck"
    streak: int = 0  # equal pairs in a row up to the last judged pair
    moved: int = 0  # motion pairs in the run (named "while moving" when the motion alone names it)
    detail: str = "moving"  # the words of the naming: "moving", or "float" ("reads exactly 0") at rest


@dataclass
class ImuTrack:
    """Recent samples of one IMU: times, gyro and accel; the index of the first pair not yet judged."""

    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    g: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    a: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    next_pair: int = 1  # the pair (k - 1, k) is judged next
    inbox: list = field(default_factory=list)  # (t, g, a) handed in since the last judge
    last_in: float = -math.inf  # the newest time handed in
    runs: list = field(default_factory=lambda: [AxisRun() for _ in AXES])
    equal_pairs: int = 0
    motion_pairs: int = 0  # equal pairs that were motion (all axes counted)
    #: per axis: pairs reading 0 twice without motion, and pairs that changed while motion showed (a gyro
    #: reading 0 at rest but alive in motion is below the message's resolution: the summary's note)
    zero_still: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    rest_pairs: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))  # pairs with no motion
    alive_moving: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))
    calm: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))  # calm pairs while healthy
    calm_changed: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.int64))  # ... that changed

    def calm_weight(self) -> np.ndarray:
        """Per axis the evidence of one calm equal pair (0 where the rest share p is unknown or low)."""
        w = np.zeros(3)
        for j in range(3):
            if self.calm[j] >= CALM_LEARN:
                p = self.calm_changed[j] / self.calm[j]
                if p >= CALM_P:
                    w[j] = math.log(1.0 - (p - CALM_MARGIN)) / math.log(CALM_ALPHA)
        return w


class FrozenWatch:
    """Every IMU of one vehicle: :meth:`add` samples, :meth:`judge` them: FaultEvents (``dead`` or ``stuck``)."""

    def __init__(self):
        self.imus: dict[int, ImuTrack] = {}

    def add(self, imu: int, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> None:
        """Samples of ``imu`` (increasing times; rows out of order are left out), kept until :meth:`judge`
        (a few microseconds a call: the live loop hands one row at a time, at up to 400 Hz per IMU)."""
        tr = self.imus.setdefault(imu, ImuTrack())
        t = np.asarray(t, dtype=float).reshape(-1)
        if t.size == 0:
            return
        if t[0] < tr.last_in - 1.0:  # a reboot: the time starts again
            tr.t, tr.g, tr.a, tr.next_pair, tr.inbox = np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), 1, []
            tr.last_in = -math.inf
        if t.size == 1:  # the live loop's one row: a float comparison (numpy's per-call cost is most of it)
            if t[0] > tr.last_in:
                tr.inbox.append((t, np.asarray(gyro, dtype=float).reshape(1, 3),
                                 np.asarray(accel, dtype=float).reshape(1, 3)))
                tr.last_in = float(t[0])
            return
        keep = t > np.maximum.accumulate(np.concatenate(([tr.last_in], t[:-1])))
        if not keep.all():
            t = t[keep]
            if t.size == 0:
                return
        g = np.asarray(gyro, dtype=float).reshape(-1, 3)
        a = np.asarray(accel, dtype=float).reshape(-1, 3)
        tr.inbox.append((t, g if keep.all() else g[keep], a if keep.all() else a[keep]))
        tr.last_in = float(t[-1])

    def judge(self) -> list[tuple[float, FaultEvent]]:
        """Every pair that can be judged now, of every IMU; the events, each with the message time of the
        sample that decided it, in time order: the same however the samples were split into :meth:`add`
        calls (as long as the IMUs' samples came within WAIT_S of each other)."""
        for tr in self.imus.values():
            if tr.inbox:
                tr.t = np.concatenate([tr.t] + [b[0] for b in tr.inbox])
                tr.g = np.concatenate([tr.g] + [b[1] for b in tr.inbox])
                tr.a = np.concatenate([tr.a] + [b[2] for b in tr.inbox])
                tr.inbox = []
        out = []
        for i in sorted(self.imus):
            out += self._judge(i)
        for tr in self.imus.values():
            self._trim(tr)
        return sorted(out, key=lambda te: te[0])

    def _horizon(self, imu: int) -> float:
        """The time up to which the other IMUs' samples are in (those still sending)."""
        me = self.imus[imu].t[-1]
        others = [tr.t[-1] for i, tr in self.imus.items() if i != imu and tr.t.size and tr.t[-1] > me - WAIT_S]
        return min(others) if others else math.inf

    def _judge(self, imu: int) -> list[tuple[float, FaultEvent]]:
        tr = self.imus[imu]
        n = tr.t.size
        if n < 2 or tr.next_pair >= n:
            return []
        horizon = self._horizon(imu)
        end = n
        k = np.arange(max(tr.next_pair, 1), end)
        if math.isfinite(horizon):  # pairs whose twin look-up the others' samples do not cover yet wait (WAIT_S)
            reach = tr.t[k] + 0.5 * (tr.t[k] - tr.t[k - 1])
            wait = np.flatnonzero((reach > horizon) & (tr.t[k] > tr.t[-1] - WAIT_S))
            k = k[:wait[0]] if wait.size else k
        if k.size == 0:
            return []
        tr.next_pair = int(k[-1]) + 1
        equal = tr.g[k] == tr.g[k - 1]
        motion = self._twin_motion(imu, tr.t[k - 1], tr.t[k])
        turn = accel_motion(tr.a[k - 1], tr.a[k])
        tr.alive_moving += ((motion | turn[:, None]) & ~equal).sum(axis=0)
        calm = accel_calm(tr.a[k - 1], tr.a[k]) & ~np.any(motion, axis=1)
        motion |= (turn & np.all(equal, axis=1))[:, None]
        weight = np.where(motion & equal, 1.0 / NEED, 0.0) + np.where(calm[:, None] & equal, tr.calm_weight(), 0.0)
        learn = calm[:, None] & (self._streaks(tr, equal) <= CALM_STREAK)
        tr.calm += learn.sum(axis=0)
        tr.calm_changed += (learn & ~equal).sum(axis=0)
        tr.equal_pairs += int(equal.sum())
        tr.motion_pairs += int((equal & motion).sum())
        tr.zero_still += (equal & ~motion & (tr.g[k] == 0.0)).sum(axis=0)
        tr.rest_pairs += (~motion).sum(axis=0)
        events = []
        for j, ax in enumerate(AXES):
            run = tr.runs[j]
            for i, state, value in step_axis(run, equal[:, j], weight[:, j], tr.g[k, j], motion[:, j]):
                if state == FAULT:
                    run.kind = "dead" if value == 0.0 else "stuck"
                    run.detail = "moving" if run.moved >= NEED else "float"
                events.append((float(tr.t[k[i]]), FaultEvent(imu, ax, run.kind, state, value, detail=run.detail,
                                                              critical=True)))
        return events

    @staticmethod
    def _streaks(tr: ImuTrack, equal: np.ndarray) -> np.ndarray:
        """(n, 3): equal pairs in a row ending at each pair (0 at a change), carried over from the last call."""
        n = equal.shape[0]
        i = np.arange(n)[:, None]
        last = np.maximum.accumulate(np.where(~equal, i, -1), axis=0)
        carry = np.array([r.streak for r in tr.runs])[None, :]
        streak = np.where(last < 0, i + 1 + carry, i - last)
        for j, r in enumerate(tr.runs):
            r.streak = int(streak[-1, j])
        return streak

    def _twin_motion(self, imu: int, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """(n, 3): another IMU's axis moved by TWIN_STEP between its samples nearest ``t0`` and ``t1``
        (each within half the pair's interval)."""
        out = np.zeros((t0.size, 3), dtype=bool)
        tol = 0.5 * (t1 - t0)
        for i, o in self.imus.items():
            if i == imu or o.t.size < 2:
                continue
            j0, ok0 = nearest(o.t, t0, tol)
            j1, ok1 = nearest(o.t, t1, tol)
            ok = ok0 & ok1 & (j1 > j0)
            out |= ok[:, None] & (np.abs(o.g[j1] - o.g[j0]) >= TWIN_STEP)
        return out

    def _trim(self, tr: ImuTrack) -> None:
        if tr.t.size and tr.t[0] < tr.t[-1] - 2 * HISTORY_S:
            cut = int(np.searchsorted(tr.t, tr.t[-1] - HISTORY_S))
            cut = min(cut, tr.next_pair - 1)
            if cut > 0:
                tr.t, tr.g, tr.a = tr.t[cut:], tr.g[cut:], tr.a[cut:]
                tr.next_pair -= cut

    def below_resolution(self, imu: int, min_pairs: int = 20) -> list[str]:
        """The axes that read 0 at rest (``min_pairs`` pairs or more, and most of the pairs at rest: a gyro whose
        noise spans a few steps reads 0 twice in a row now and then) and changed while the vehicle moved
        (``min_pairs`` too), and are not held dead: alive, quieter than the message's step at rest."""
        tr = self.imus.get(imu)
        if tr is None:
            return []
        zero_enough = np.maximum(min_pairs, REST_ZERO_SHARE * tr.rest_pairs)
        return [ax for j, ax in enumerate(AXES) if tr.zero_still[j] >= zero_enough[j]
                and tr.alive_moving[j] >= min_pairs and tr.runs[j].state == OK]

    def detail(self, imu: int, axis: str) -> str:
        """The words of an axis this test holds: "moving" or "float" (named at rest)."""
        return self.imus[imu].runs[AXES.index(axis)].detail

    def active(self, imu: int) -> list[tuple[str, str]]:
        """(kind, axis) of the axes this test holds as dead or stuck."""
        tr = self.imus.get(imu)
        if tr is None:
            return []
        return [(r.kind, ax) for ax, r in zip(AXES, tr.runs) if r.state == FAULT]


def nearest(t: np.ndarray, q: np.ndarray, tol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the sample of increasing ``t`` nearest each of ``q``, and whether it lies within ``tol``."""
    j = np.clip(np.searchsorted(t, q), 1, t.size - 1)
    j = np.where(np.abs(t[j - 1] - q) <= np.abs(t[j] - q), j - 1, j)
    return j, np.abs(t[j] - q) <= tol


def accel_motion(a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """(n,): the accelerometer turned by ACCEL_TURN or changed by ACCEL_STEP between the two samples
    (an accelerometer reading 0, a compass-only instance, shows nothing)."""
    n0, n1 = np.linalg.norm(a0, axis=1), np.linalg.norm(a1, axis=1)
    valid = (n0 > 0) & (n1 > 0) & np.all(np.isfinite(a0) & np.isfinite(a1), axis=1)
    cos = np.sum(a0 * a1, axis=1) / np.where(valid, n0 * n1, 1.0)
    turn = np.arccos(np.clip(cos, -1.0, 1.0)) >= ACCEL_TURN
    step = np.linalg.norm(a1 - a0, axis=1) >= ACCEL_STEP
    return valid & (turn | step)


def accel_calm(a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """(n,): the accelerometer turned by less than CALM_TURN and changed by less than CALM_STEP."""
    n0, n1 = np.linalg.norm(a0, axis=1), np.linalg.norm(a1, axis=1)
    valid = (n0 > 0) & (n1 > 0) & np.all(np.isfinite(a0) & np.isfinite(a1), axis=1)
    cos = np.sum(a0 * a1, axis=1) / np.where(valid, n0 * n1, 1.0)
    turn = np.arccos(np.clip(cos, -1.0, 1.0))
    return valid & (turn < CALM_TURN) & (np.linalg.norm(a1 - a0, axis=1) < CALM_STEP)


def step_axis(run: AxisRun, equal: np.ndarray, weight: np.ndarray, value: np.ndarray,
              motion: np.ndarray | None = None) -> list[tuple[int, int, float]]:
    """Advance one axis' run over judged pairs (``weight``: each equal pair's evidence); its state changes in
    order, as (pair, state, value)."""
    moving = (weight > 0) & equal
    motion = np.zeros_like(equal) if motion is None else motion & equal
    if run.state == OK and not moving.any():  # the usual case, at any rate: nothing to count one by one
        if not equal.all():
            run.motion, run.moved = 0.0, 0
            run.changes = int(equal.size - 1 - np.flatnonzero(equal)[-1]) if equal.any() else run.changes + equal.size
        run.value = float(value[-1])
        return []
    out = []
    for i, (e, m, v, mv) in enumerate(zip(equal.tolist(), np.where(moving, weight, 0.0).tolist(), value.tolist(),
                                          motion.tolist())):
        if e:
            if run.value != v:
                run.motion, run.moved = 0.0, 0
            run.value, run.changes = v, 0
            run.motion += m
            run.moved += int(mv)
            if run.state == OK and run.motion >= 1.0 - 1e-9:
                run.state = FAULT
                out.append((i, FAULT, v))
        else:
            run.motion, run.moved, run.value = 0.0, 0, v
            run.changes += 1
            if run.state == FAULT and run.changes >= CLEAR:
                run.state = OK
                out.append((i, OK, v))
    return out
