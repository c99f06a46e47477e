"""From MAVLink messages to estimates, health and reports, in message time only.

Per IMU (``StreamKey.instance``; the first IMU message type seen for an instance is used, other types
carrying the same IMU are ignored) and per gyro axis (accel axes optional):

1. Samples are cut into blocks of ``block_s`` seconds of message time. Each block is *still* when
   the vehicle is disarmed (its autopilot's HEARTBEAT ``base_mode`` bit 128 clear; no HEARTBEAT at all
   counts as disarmed) AND the motion gate (:meth:`Pipeline._still`) agrees; it decides from the
   accelerometer and from the agreement of IMUs and axes, never from one gyro axis' own noise level.
   A block is fed only if the next block is still too (one block of look-ahead, so the start of a
   handling never leaks in) and the vehicle has been still for ``settle_s`` before it.
1b. Every block, still or not, goes through the fault detectors (companion.health.monitor: stuck,
   spikes, saturation, timing; on still fed blocks also noise, bias jump/drift, resolution) and, with two
   or more IMUs, the pairwise disagreement test (companion.health.disagreement) on the time both cover;
   each transition is a STATUSTEXT and sets ``IMU{i}G_HLTH`` / ``IMU{i}G_FLT`` at once.
2. Fed blocks go to two online estimators per axis (companion.estimators.make_estimator): a *fast*
   one (exponential memory ``forgetting_fast_s``) for Q and N, a *slow* one (``forgetting_slow_s``) for
   B, K and R, and during learning a third one without forgetting whose terms become the baseline after
   ``baseline_s`` seconds of still data (unless a baseline was loaded).
3. Every ``check_s`` of message time the current terms are reported and tested against the baseline
   (companion.health.detector), health transitions produce a STATUSTEXT.

Timing: a timestamp ``reset_s`` or more behind the last one is an autopilot reboot (the partial block is
dropped, settling starts again); smaller steps back and duplicates are dropped and counted; a gap longer
than ``gap_s`` ends the block and restarts settling. Messages of other system ids are ignored.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, fields
from typing import Callable, Mapping

import numpy as np

from companion.estimators import from_state_dict as estimator_from_state, make_estimator
from companion.estimators.report import health_params as _health_params
from companion.health.baseline import Baseline
from companion.service.baseline_match import check_baseline, stream_meta, units_mismatch
from companion.health.detector import DEGRADING, LEARNING, DetectorConfig, HealthDetector, STATE_NAMES
from companion.health.disagreement import PairDisagreement
from companion.health.limits import FaultLimits
from companion.health.faults import FAULT, OK, FaultEvent, Observation, block_stats
from companion.health.monitor import ImuFaults
from companion.mavlink.reporter import (MAV_SEVERITY_CRITICAL, MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING,
                                        Reporter, health_name)
from companion.samples import ACCEL_AXES, GYRO_AXES
from companion.sources.timing import period_of, stamp_resolution

FAST_PARAMS = ("Q", "N")
SLOW_PARAMS = ("B", "K", "R")
STATE_FORMAT = "companion-run-state"


@dataclass
class PipelineConfig:
    sysid: int | None = None  # vehicle system id; None: the first one sending IMU data
    block_s: float = 1.0
    settle_s: float = 10.0
    baseline_s: float = 600.0
    check_s: float = 10.0
    min_report_s: float = 30.0  # still data an estimator needs before its values are reported
    forgetting_fast_s: float = 600.0
    forgetting_slow_s: float = 7200.0
    accel: bool = False  # also estimate and report the accelerometer axes
    baseline_force: bool = False  # use a loaded baseline even if it does not match the stream (issue 13)
    gyro_mean: float = 0.1  # rad/s
    gyro_std_factor: float = 5.0
    accel_shift: float = 0.3  # m/s^2
    accel_std: float = 0.5  # m/s^2
    accel_std_factor: float = 3.0  # accel axis std above this x its still reference = moving (handling)
    accel_std_min: float = 0.05  # m/s^2: ... and above this
    gyro_limit: float = 32.767  # rad/s: range limit of the gyro (int16 mrad/s); a sample there is saturated
    fault_ref_s: float = 30.0  # still data learned as the reference of the fast fault detectors
    reset_s: float = 1.0
    gap_s: float = 0.5
    estimator: dict = field(default_factory=dict)  # passed to make_estimator (e.g. effects, phases, max_tau_s)
    health: DetectorConfig = field(default_factory=DetectorConfig)
    faults: FaultLimits = field(default_factory=FaultLimits)  # magnitude floors of the fault detectors

    @classmethod
    def from_mapping(cls, cfg: Mapping | None) -> "PipelineConfig":
        out = cls()
        names = {f.name for f in fields(cls)}
        for k, v in dict(cfg or {}).items():
            if k not in names:
                raise ValueError(f"run: unknown key {k!r}")
            if k == "health":
                out.health = DetectorConfig.from_mapping(v)
            elif k == "faults":
                out.faults = FaultLimits.from_mapping(v)
            elif k == "estimator":
                out.estimator = dict(v or {})
            elif k == "sysid":
                out.sysid = None if v is None else int(v)
            elif k in ("accel", "baseline_force"):
                setattr(out, k, bool(v))
            else:
                out.__setattr__(k, float(v))
                if not float(v) > 0:
                    raise ValueError(f"run: {k} must be > 0, got {v!r}")
        return out


class Channel:
    """One IMU: timing, blocks, motion state, estimators, baseline learning and its health detector."""

    def __init__(self, imu: int, message: str, cfg: PipelineConfig):
        self.imu, self.message, self.cfg = imu, message, cfg
        self.time_res = stamp_resolution(message)  # 1 ms for time_boot_ms: 400 Hz comes as 2 and 3 ms steps
        self.gyro_lsb = None if message in ("HIGHRES_IMU", "CSV") else 1e-3  # set from the scale table in on_sample
        self.axes = GYRO_AXES + (ACCEL_AXES if cfg.accel else ())
        self.last_t: float | None = None
        self.dts: deque = deque(maxlen=64)
        self.rate_hz: float | None = None
        self.block: list = []
        self.block_arrays: list = []  # the same block, as arrays (Pipeline.on_samples)
        self.block_t0: float | None = None
        self.pending = None  # still block waiting for the look-ahead
        self.still_run_s = 0.0
        self.ref_accel = None
        self.fast: dict = {}
        self.slow: dict = {}
        self.learn: dict = {}
        self.learned_s = 0.0
        self.fed_s = 0.0
        self.feed_buf: list = []
        self.feed_buf_s = 0.0
        self.next_check_t: float | None = None
        self.detector = HealthDetector(imu, cfg.health)
        self.faults = ImuFaults(imu, cfg.gyro_limit, max(1, int(round(cfg.fault_ref_s / cfg.block_s))),
                                stamp_res=self.time_res, limits=cfg.faults)
        self.last_stats = None  # BlockStats of the last closed block (motion consensus between IMUs)
        self.pending_stats = None
        self.ref_accel_std = None
        self.recent: deque = deque(maxlen=3)  # (t, gyro) of the last closed blocks (IMU disagreement)
        self.counts = {"samples": 0, "duplicates": 0, "backwards": 0, "resets": 0, "gaps": 0,
                       "blocks_still": 0, "blocks_moving": 0, "blocks_fed": 0, "rate_changes": 0}
        self.current: dict[str, dict[str, tuple[float, float]]] = {}

    def make_estimators(self, learning: bool) -> None:
        est = {k: v for k, v in self.cfg.estimator.items() if k != "forgetting_s"}
        self.fast = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=self.cfg.forgetting_fast_s, **est) for a in self.axes}
        self.slow = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=self.cfg.forgetting_slow_s, **est) for a in self.axes}
        self.learn = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=None, **est) for a in self.axes} if learning else {}
        self.learned_s = 0.0
        self.fed_s = 0.0
        self.feed_buf, self.feed_buf_s = [], 0.0


class Pipeline:
    """Feed it pymavlink messages (:meth:`handle`) or decoded samples (:meth:`on_heartbeat`, :meth:`on_sample`)."""

    def __init__(self, cfg: PipelineConfig, reporter: Reporter, baseline: Baseline | None = None,
                 log: Callable[[str], None] | None = None, scales=None):
        self.cfg = cfg
        self.reporter = reporter
        self.baseline = baseline  # loaded from a file or restored state; None: learn it
        self.baseline_fixed = baseline is not None
        self.log = log or (lambda line: None)
        self.scales = scales
        self.sysid = cfg.sysid
        self.armed = False
        self.channels: dict[int, Channel] = {}
        self.ignored = {"other_sysid": 0, "other_message": 0}
        self.transitions: list[str] = []
        self.pairs: dict[tuple[int, int], PairDisagreement] = {}
        self.pair_done: dict[tuple[int, int], float] = {}
        self.disagree: dict[tuple[int, str], str] = {}  # (imu, axis) -> detail of an active disagreement
        self._decode = None

    # ------------------------------------------------------------------ input
    def handle(self, msg) -> bool:
        """One pymavlink message; returns True when it was an IMU sample of the vehicle that was used."""
        mtype = msg.get_type()
        if mtype == "HEARTBEAT":
            self.on_heartbeat(msg.get_srcSystem(), msg.type, msg.autopilot, msg.base_mode)
            return False
        if mtype not in ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU"):
            return False
        if self._decode is None:
            from companion.sources.decode import imu_sample_from_message

            self._decode = imu_sample_from_message
        s = self._decode(msg, self.scales)
        if s is None or not s.is_imu:
            return False
        return self.on_sample(s.key, s.t_s, s.gyro, s.accel)

    def on_heartbeat(self, sysid: int, mav_type: int, autopilot: int, base_mode: int) -> None:
        if autopilot == 8 or mav_type in (6, 18):  # MAV_AUTOPILOT_INVALID, GCS, onboard controller: not the vehicle
            return
        if self.sysid is not None and sysid != self.sysid:
            return
        armed = bool(base_mode & 128)
        if armed != self.armed:
            self.log(f"vehicle {'armed' if armed else 'disarmed'}")
        self.armed = armed

    def on_sample(self, key, t: float, gyro, accel) -> bool:
        if self.sysid is None:
            self.sysid = key.sysid
            self.log(f"vehicle: system id {key.sysid}")
        elif key.sysid != self.sysid:
            self.ignored["other_sysid"] += 1
            return False
        ch = self.channels.get(key.instance)
        if ch is None:
            ch = self.channels[key.instance] = Channel(key.instance, key.message, self.cfg)
            ch.gyro_lsb = None if key.message in ("HIGHRES_IMU", "CSV") else (
                self.scales.lookup(key)[0] if self.scales is not None else 1e-3)
            self.log(f"IMU{key.instance}: {key.message} from {key.label()}")
        elif ch.message != key.message:
            self.ignored["other_message"] += 1
            return False
        t = float(t)
        c = ch.counts
        if ch.last_t is not None:
            dt = t - ch.last_t
            if dt <= -self.cfg.reset_s:
                c["resets"] += 1
                self.log(f"IMU{ch.imu}: timestamps reset ({ch.last_t:.3f} s -> {t:.3f} s): autopilot reboot")
                self._break(ch)
                ch.last_t = t
            elif dt == 0.0:
                c["duplicates"] += 1
                return False
            elif dt < 0.0:
                c["backwards"] += 1
                return False
            else:
                if dt > self.cfg.gap_s:
                    c["gaps"] += 1
                    self._break(ch)
                else:
                    ch.dts.append(dt)
        ch.last_t = t
        c["samples"] += 1
        if ch.block_t0 is None:
            ch.block_t0 = t
        if ch.block_arrays:
            ch.block_arrays.append(np.array([(t, *gyro, *accel)], dtype=float))
        else:
            ch.block.append((t, *gyro, *accel))
        if t - ch.block_t0 >= self.cfg.block_s - 0.5 * self._period(ch):
            self._close_block(ch)
        if ch.next_check_t is not None and t >= ch.next_check_t:
            self._check(ch, t)
        self.reporter.tick(t)
        return True

    def on_samples(self, key, t, gyro, accel) -> int:
        """Many samples of one IMU at once (arrays (n,), (n, 3), (n, 3)): the same blocks, checks and
        reports as :meth:`on_sample` one by one, much faster. Timestamps that are not strictly increasing
        within ``gap_s`` (and the first samples of a stream) take the sample-by-sample path. Returns the
        number of samples used."""
        t = np.asarray(t, dtype=float)
        gyro = np.asarray(gyro, dtype=float).reshape(-1, 3)
        accel = np.asarray(accel, dtype=float).reshape(-1, 3)
        ch = self.channels.get(key.instance)
        n = t.size
        start = 0
        if ch is None or ch.rate_hz is None or key.sysid != self.sysid or ch.message != key.message or ch.last_t is None:
            start = min(n, 200)
            used = sum(bool(self.on_sample(key, t[k], gyro[k], accel[k])) for k in range(start))
            if start == n:
                return used
            ch = self.channels.get(key.instance)
            if ch is None or ch.rate_hz is None or ch.message != key.message or key.sysid != self.sysid:
                return used + sum(bool(self.on_sample(key, t[k], gyro[k], accel[k])) for k in range(start, n))
        else:
            used = 0
        tt = t[start:]
        dt = np.diff(np.concatenate(([ch.last_t], tt)))
        if not (np.all(dt > 0.0) and np.all(dt <= self.cfg.gap_s)):
            return used + sum(bool(self.on_sample(key, t[k], gyro[k], accel[k])) for k in range(start, n))
        rows = np.column_stack([tt, gyro[start:], accel[start:]])
        ch.dts.extend(dt[-ch.dts.maxlen:].tolist())
        ch.counts["samples"] += tt.size
        ch.last_t = float(tt[-1])
        if ch.block:
            ch.block_arrays.insert(0, np.asarray(ch.block, dtype=float))
            ch.block = []
        i = 0
        m = tt.size
        stride = max(1, int(0.05 * (ch.rate_hz or 100.0)))
        while i < m:
            if ch.block_t0 is None:
                ch.block_t0 = float(tt[i])
            j = int(np.searchsorted(tt, ch.block_t0 + self.cfg.block_s - 0.5 * self._period(ch), side="left"))
            if j >= m:
                ch.block_arrays.append(rows[i:])
                for k in range(i, m, stride):
                    self.reporter.tick(float(tt[k]))
                break
            ch.block_arrays.append(rows[i:j + 1])
            for k in range(i, j + 1, stride):
                self.reporter.tick(float(tt[k]))
            self._close_block(ch)
            if ch.next_check_t is not None and tt[j] >= ch.next_check_t:
                self._check(ch, float(tt[j]))
            self.reporter.tick(float(tt[j]))
            i = j + 1
        return used + m

    @staticmethod
    def _period(ch: Channel) -> float:
        return 1.0 / ch.rate_hz if ch.rate_hz else (float(np.median(ch.dts)) if ch.dts else 0.0)

    def _break(self, ch: Channel) -> None:
        """Time discontinuity: drop the partial block and the look-ahead, settle again."""
        ch.block, ch.block_t0, ch.pending, ch.still_run_s = [], None, None, 0.0
        ch.block_arrays = []
        ch.pending_stats = None
        ch.next_check_t = None
        ch.recent.clear()

    # ------------------------------------------------------------------ blocks
    def _close_block(self, ch: Channel) -> None:
        parts = ch.block_arrays + ([np.asarray(ch.block, dtype=float)] if ch.block else [])
        data = parts[0] if len(parts) == 1 else np.concatenate(parts)
        ch.block, ch.block_arrays, ch.block_t0 = [], [], None
        st = block_stats(data[:, 1:4], ch.faults.dd_scale_ref())
        still = (not self.armed) and self._still(ch, data, st)
        ch.last_stats = st
        ch.recent.append((data[:, 0].copy(), data[:, 1:4].copy()))
        self._report(ch.faults.on_block(st, data[:, 0], still), float(data[-1, 0]))
        self._pairs(ch)
        if len(ch.dts) >= 8:
            rate = 1.0 / period_of(ch.dts, ch.time_res)
            if ch.rate_hz is None:
                ch.rate_hz = rate
                if self.baseline_fixed and self._has_baseline(ch):
                    check_baseline(self.baseline, ch, self.cfg.baseline_force, self.log)
                ch.make_estimators(learning=not self._has_baseline(ch))
                self.log(f"IMU{ch.imu}: {rate:.1f} Hz")
            elif abs(rate / ch.rate_hz - 1.0) > 0.2:
                ch.counts["rate_changes"] += 1
                self.log(f"IMU{ch.imu}: rate changed {ch.rate_hz:.1f} -> {rate:.1f} Hz: estimators restart")
                ch.rate_hz = rate
                ch.make_estimators(learning=not self._has_baseline(ch))
                ch.pending, ch.pending_stats, ch.still_run_s = None, None, 0.0
                return
        if ch.rate_hz is None:
            return
        duration = data.shape[0] / ch.rate_hz
        ch.counts["blocks_still" if still else "blocks_moving"] += 1
        if not still:
            ch.pending, ch.pending_stats, ch.still_run_s = None, None, 0.0
            return
        if ch.pending is not None:
            self._report(ch.faults.on_quiet(ch.pending_stats, self._bias_extra_var(ch)), float(ch.pending[-1, 0]))
            self._feed(ch, ch.pending)
        settled = ch.still_run_s >= self.cfg.settle_s
        ch.pending = data if settled else None
        ch.pending_stats = st if settled else None
        ch.still_run_s += duration

    def _still(self, ch: Channel, data: np.ndarray, st=None) -> bool:
        """Motion gate from the accelerometer and from the agreement of IMUs and axes, never from one gyro
        axis' own noise level (a gyro whose noise jumps while the accel and the other IMUs stay quiet is
        faulty, not moving):

        * accel: |accel| std above ``accel_std``, the mean accel vector ``accel_shift`` away from the
          still reference (a new attitude), or an accel axis' std above ``accel_std_factor`` x its still
          reference and above ``accel_std_min`` (handling, vibration);
        * rotation: the block mean rate above ``gyro_mean`` and significant against the block's own noise
          (5 sigma), on the IMU agreeing most with "no rotation" when others exist (per axis the smaller
          |mean| of two, the median of three): one frozen or biased gyro cannot declare motion; with one
          IMU only the rotation about gravity counts (a rotation about a horizontal axis tilts the vehicle
          and shows in the accel shift test; a gyro drifting or frozen at a rate alone is not motion);
        * vibration: with other IMUs, their gyros vibrating too (an axis above ``gyro_std_factor`` x its
          still noise on this and on another IMU); alone, two axes of this gyro above it and the accel
          axis std above 1.5x its reference.
        """
        cfg = self.cfg
        g, a = data[:, 1:4], data[:, 4:7]
        if st is None:
            st = block_stats(g, ch.faults.dd_scale_ref())
        a_mean = a.mean(axis=0)
        a_std = a.std(axis=0)
        if np.linalg.norm(a, axis=1).std() > cfg.accel_std:
            return False
        if ch.ref_accel is not None and np.linalg.norm(a_mean - ch.ref_accel) > cfg.accel_shift:
            # moved to a new attitude; it becomes the reference once still for settle_s
            ch.ref_accel = a_mean if ch.still_run_s == 0.0 and ch.pending is None else ch.ref_accel
            return False
        accel_up = 1.0
        if ch.ref_accel_std is not None:
            ratio = a_std / np.maximum(ch.ref_accel_std, 1e-9)
            if np.any((ratio > cfg.accel_std_factor) & (a_std > cfg.accel_std_min)):
                return False
            accel_up = float(ratio.max())
        # rotation, by consensus of the IMUs
        means = [self._rotation(st)]
        others = [o for o in self.channels.values() if o is not ch and o.last_stats is not None
                  and o.last_t is not None and ch.last_t is not None and abs(o.last_t - ch.last_t) < 2 * cfg.block_s]
        means += [self._rotation(o.last_stats) for o in others]
        rot = np.array(means)
        if len(means) == 1:
            w = rot[0]
        elif len(means) == 2:  # the IMU claiming less rotation, per axis
            w = np.where(np.abs(rot[0]) <= np.abs(rot[1]), rot[0], rot[1])
        else:
            w = np.median(rot, axis=0)
        # A rotation about a horizontal axis tilts the vehicle: the accelerometer sees it (the shift test
        # above) within the block. Unseen by the accel, only a rotation about gravity (yaw) is physical;
        # a lone gyro drifting or frozen at a rate is not motion.
        g_dir = a_mean / max(float(np.linalg.norm(a_mean)), 1e-9)
        yaw = abs(float(np.dot(w, g_dir)))
        if yaw > cfg.gyro_mean or (len(means) > 1 and np.any(np.abs(w) > cfg.gyro_mean)):
            return False
        # vibration, by agreement of IMUs / axes
        k2 = cfg.gyro_std_factor ** 2
        mine = self._noise_ratio(ch, st)
        if mine is not None:
            if others:
                theirs = [self._noise_ratio(o, o.last_stats) for o in others]
                if np.any(mine > k2) and any(r is not None and np.any(r > k2) for r in theirs):
                    return False
            elif np.count_nonzero(mine > k2) >= 2 and accel_up > 1.5:
                return False
        w = 0.05
        ch.ref_accel = a_mean if ch.ref_accel is None else (1 - w) * ch.ref_accel + w * a_mean
        ch.ref_accel_std = a_std if ch.ref_accel_std is None else (1 - w) * ch.ref_accel_std + w * a_std
        return True

    @staticmethod
    def _rotation(st) -> np.ndarray:
        """Block means that are significant rotation (5 sigma of the block's white noise), else 0."""
        sig = np.sqrt(np.nan_to_num(st.v2, nan=0.0) / max(st.n, 1))
        return np.where(np.abs(st.mean) > 5.0 * sig, st.mean, 0.0)

    @staticmethod
    def _noise_ratio(ch: Channel, st) -> np.ndarray | None:
        refs = [af.ref for af in ch.faults.axes.values()]
        if st is None or not all(r.ready and r.sigma2 > 0 for r in refs):
            return None
        return np.nan_to_num(st.v2, nan=0.0) / np.array([r.sigma2 for r in refs])

    def _bias_extra_var(self, ch: Channel) -> dict[str, float]:
        """Allan-predicted wander of a block mean around the bias reference: 0.44 B^2 + K^2 T / 3."""
        out = {}
        from companion.health.bias import REF_TAU_BLOCKS

        for ax in ("gx", "gy", "gz"):
            b = self.baseline.get(ch.imu, ax) if self.baseline is not None else None
            if not b:
                continue
            v = 0.0
            if "B" in b and math.isfinite(b["B"][0]):
                v += 0.44 * b["B"][0] ** 2
            if "K" in b and math.isfinite(b["K"][0]):
                v += b["K"][0] ** 2 * REF_TAU_BLOCKS * self.cfg.block_s / 3.0
            out[ax] = v
        return out

    # ------------------------------------------------------------------ IMU disagreement
    def _pairs(self, ch: Channel) -> None:
        """Compare this IMU with every other over the time both have covered since the pair's last check."""
        for other in list(self.channels.values()):
            if other is ch or not other.recent or not ch.recent:
                continue
            i, j = sorted((ch.imu, other.imu))
            ci, cj = self.channels[i], self.channels[j]
            key = (i, j)
            pair = self.pairs.get(key)
            if pair is None:
                pair = self.pairs[key] = PairDisagreement(i, j, self.cfg.faults)
            ti = np.concatenate([b[0] for b in ci.recent])
            tj = np.concatenate([b[0] for b in cj.recent])
            t_end = min(ti[-1], tj[-1])
            t_done = self.pair_done.get(key, -math.inf)
            if t_end < t_done - self.cfg.reset_s:  # reboot: time starts again
                t_done = -math.inf
            mask = (ti > t_done) & (ti <= t_end) & (ti >= tj[0])
            if np.count_nonzero(mask) < 10:
                continue
            t = ti[mask]
            k = np.clip(np.searchsorted(tj, t), 1, tj.size - 1)
            period = float(np.median(np.diff(tj))) if tj.size > 1 else 0.0
            near = np.minimum(np.abs(tj[k] - t), np.abs(tj[k - 1] - t))
            ok = near <= 1.5 * period
            if np.count_nonzero(ok) < 10:
                self.pair_done[key] = t_end
                continue
            gi = np.concatenate([b[1] for b in ci.recent])[mask][ok]
            gj_all = np.concatenate([b[1] for b in cj.recent])
            gj = np.column_stack([np.interp(t[ok], tj, gj_all[:, a]) for a in range(3)])
            self.pair_done[key] = t_end
            nv = [ci.faults.noise_ref(ax) for ax in ("gx", "gy", "gz")] + [cj.faults.noise_ref(ax) for ax in ("gx", "gy", "gz")]
            ready = all(v is not None for v in nv)
            noise_var = (max(nv[:3]) + max(nv[3:])) if ready else None
            obs = Observation(i, y=gi, other=gj, other_imu=j, noise_var=noise_var,
                              noise_other=max(nv[3:]) if ready else None)
            if pair.update(obs):
                self._name_disagreement(float(t[-1]))

    def _name_disagreement(self, t: float) -> None:
        """From pair states to named IMUs: with three or more the odd one out (its pairs disagree, the
        others agree); with two both are suspects unless only one of them has another fault."""
        imus = sorted(self.channels)
        for a, ax in enumerate(("gx", "gy", "gz")):
            bad = {k for k, p in self.pairs.items() if p.axis_state(a) == FAULT}
            named: dict[int, list[int]] = {}
            if len(imus) == 2 and bad:
                i, j = imus
                other_faults = {k: [f for f in self.channels[k].faults.active() if f[0] != "disagree"] for k in (i, j)}
                if other_faults[i] and not other_faults[j]:
                    named = {i: [j]}
                elif other_faults[j] and not other_faults[i]:
                    named = {j: [i]}
                else:
                    named = {i: [j], j: [i]}
            elif len(imus) >= 3 and bad:
                partners = {k: sorted(p[0] if p[1] == k else p[1] for p in bad if k in p) for k in imus}
                most = max(len(v) for v in partners.values())
                named = {k: v for k, v in partners.items() if len(v) >= 2 and len(v) == most}
            for k in imus:
                was = (k, ax) in self.disagree
                now = k in named
                if was == now:
                    continue
                pair = self.pairs.get(tuple(sorted((k, named[k][0])))) if now else None
                value = pair.value[a] if pair is not None else math.nan
                detail = "/".join(f"IMU{o}" for o in named[k]) if now else ""
                if now:
                    self.disagree[(k, ax)] = detail
                else:
                    self.disagree.pop((k, ax), None)
                self.channels[k].faults.set_external("disagree", ax, FAULT if now else OK)
                self._report([FaultEvent(k, ax, "disagree", FAULT if now else OK, value, detail,
                                         critical=self.armed and now)], t)

    # ------------------------------------------------------------------ fault reports
    def _report(self, events: list, t: float) -> None:
        for ev in events:
            text = ev.text()
            self.transitions.append((t, text))
            self.log(text)
            if ev.state == FAULT:
                sev = MAV_SEVERITY_CRITICAL if ev.critical else MAV_SEVERITY_WARNING
            else:
                sev = MAV_SEVERITY_NOTICE
            self.reporter.statustext(text, sev)
            ch = self.channels.get(ev.imu)
            if ch is not None:
                self.reporter.set_fault(ch.imu, ch.faults.code(), ch.faults.mask())
                self.reporter.set_health(ch.imu, self.health(ch))
            if ev.kind != "disagree" and len(self.channels) == 2 and self.disagree:
                self._name_disagreement(t)  # another fault may tell which of the two disagrees

    def _feed(self, ch: Channel, data: np.ndarray) -> None:
        """Queue a still block for the estimators (updated in batches of about ``check_s``: same result,
        the estimators' block updates are split-invariant, far fewer calls)."""
        ch.counts["blocks_fed"] += 1
        ch.feed_buf.append(data)
        duration = data.shape[0] / ch.rate_hz
        ch.fed_s += duration
        ch.feed_buf_s += duration
        if ch.next_check_t is None:
            ch.next_check_t = float(data[-1, 0]) + self.cfg.check_s
        if ch.learn:
            ch.learned_s += duration
            if ch.learned_s >= self.cfg.baseline_s:
                self._learn_done(ch)
                return
        if ch.feed_buf_s >= self.cfg.check_s:
            self._flush_feed(ch)

    def _flush_feed(self, ch: Channel) -> None:
        if not ch.feed_buf:
            return
        data = np.concatenate(ch.feed_buf) if len(ch.feed_buf) > 1 else ch.feed_buf[0]
        ch.feed_buf, ch.feed_buf_s = [], 0.0
        cols = {ax: 1 + i for i, ax in enumerate(GYRO_AXES + ACCEL_AXES)}
        for ax in ch.axes:
            y = np.ascontiguousarray(data[:, cols[ax]])
            ch.fast[ax].update(y)
            ch.slow[ax].update(y)
            if ch.learn:
                ch.learn[ax].update(y)

    def _has_baseline(self, ch: Channel) -> bool:
        return self.baseline is not None and self.baseline.has_imu(ch.imu)

    def _learn_done(self, ch: Channel) -> None:
        self._flush_feed(ch)
        if self.baseline is None:
            self.baseline = Baseline("learned")
        for ax, est in ch.learn.items():
            self.baseline.set_axis(ch.imu, ax, _health_params(est.terms(full=True) if est.kind == "octave" else est.terms()))
        self.baseline.meta[ch.imu] = stream_meta(ch)
        ch.learn = {}
        b = self.baseline.get(ch.imu, "gx") or {}
        n = b.get("N", (math.nan, math.nan))[0]
        self.log(f"IMU{ch.imu}: baseline learned from {ch.learned_s:.0f} s of still data (gx N {n:.3g} rad/s/sqrt(Hz))")
        self.reporter.statustext(f"IMU{ch.imu} gyro baseline learned", MAV_SEVERITY_NOTICE)

    # ------------------------------------------------------------------ checks and reports
    # --- online report (issue 13): one code path with `analyze --online` (companion.estimators.report) ---
    def report_terms(self, ch: Channel, ax: str, full: bool = False) -> list[dict]:
        """The reported terms of one axis (SI; resolved values and 95 % bounds, ``"bound": True``): Q and N
        from the fast estimator, B, K, R, Gauss-Markov and sinusoid from the slow one."""
        def terms(est):
            return est.terms(full=full) if est.kind == "octave" else est.terms()

        fast = [t for t in terms(ch.fast[ax]) if t["effect"] in ("quantization", "white_noise")]
        slow = [t for t in terms(ch.slow[ax]) if t["effect"] not in ("quantization", "white_noise")]
        return fast + slow

    def current_params(self, ch: Channel, ax: str, terms=None) -> dict[str, tuple[float, float]]:
        """``{param: (value, std)}`` of the resolved parameters (a bound is not compared with a baseline)."""
        return _health_params(self.report_terms(ch, ax) if terms is None else terms)

    def _check(self, ch: Channel, t: float) -> None:
        ch.next_check_t = t + self.cfg.check_s
        self._flush_feed(ch)
        if ch.fed_s < self.cfg.min_report_s:
            self.reporter.set_health(ch.imu, self.health(ch) if ch.faults.active() else LEARNING)
            self.reporter.set_fault(ch.imu, ch.faults.code(), ch.faults.mask())
            return
        effects_params = None
        for ax in ch.axes:
            terms = self.report_terms(ch, ax)
            cur = self.current_params(ch, ax, terms)
            ch.current[ax] = cur
            if effects_params is None:
                effects_params = set(cur)
            self.reporter.set_online_terms(ch.imu, ax, terms)
            base = self.baseline.get(ch.imu, ax) if self.baseline is not None else None
            if base is None or ch.learn:
                continue
            bad = units_mismatch(base, cur) if self.baseline_fixed and not self.cfg.baseline_force else None
            if bad:
                from companion.errors import CompanionError

                raise CompanionError(f"baseline {self.baseline.source} does not match IMU{ch.imu} {ax}: {bad}; "
                                     "use a baseline of this stream or --baseline-force")
            for tr in ch.detector.check(ax, cur, base):
                text = tr.text()
                self.transitions.append((t, text))
                self.log(text)
                self.reporter.statustext(text, MAV_SEVERITY_WARNING if tr.state == DEGRADING else MAV_SEVERITY_NOTICE)
                if ax in ("gx", "gy", "gz"):
                    high = any(d.state == DEGRADING for (a, _), d in ch.detector.detectors.items() if a == ax)
                    ch.faults.set_external("allan", ax, FAULT if high else OK)
        self.reporter.set_health(ch.imu, self.health(ch))
        self.reporter.set_fault(ch.imu, ch.faults.code(), ch.faults.mask())

    def health(self, ch: Channel) -> int:
        """0 healthy, 1 degrading (any fault, even while the Allan baseline is still being learned), 2 learning."""
        if ch.faults.active():
            return DEGRADING
        if ch.learn or not self._has_baseline(ch):
            return LEARNING
        return ch.detector.state

    def send_health_now(self, state: int | None = None) -> None:
        """Send every IMU's health at once (e.g. STALE when the link is silent: no message time advances)."""
        for imu, ch in sorted(self.channels.items()):
            s = self.health(ch) if state is None else state
            self.reporter.send_now(health_name(imu), float(s), ch.last_t or 0.0)

    def summary(self) -> list[dict]:
        out = []
        for imu, ch in sorted(self.channels.items()):
            row = {"imu": imu, "message": ch.message, "rate_hz": ch.rate_hz, "still_s": ch.fed_s,
                   "health": STATE_NAMES[self.health(ch)], "counts": dict(ch.counts), "axes": {},
                   "faults": self.fault_texts(ch)}
            if ch.fast and ch.fed_s > 0:
                self._flush_feed(ch)
                for ax in ch.axes:
                    terms = self.report_terms(ch, ax, full=True)
                    row["axes"][ax] = {"current": self.current_params(ch, ax, terms), "terms": terms,
                                       "baseline": self.baseline.get(imu, ax) if self.baseline else None}
            out.append(row)
        return out

    def fault_texts(self, ch: Channel) -> list[str]:
        """The active faults of an IMU in plain words, most severe first (what the STATUSTEXTs said)."""
        out = []
        for kind, ax in ch.faults.active():
            if kind == "disagree":
                ev = FaultEvent(ch.imu, ax, kind, FAULT, detail=self.disagree.get((ch.imu, ax), "another IMU"))
            elif kind == "allan":
                worst = [(d.ratio, p) for (a, p), d in ch.detector.detectors.items() if a == ax and d.state == DEGRADING]
                r, p = max(worst) if worst else (math.nan, "N")
                ev = FaultEvent(ch.imu, ax, kind, FAULT, detail=f"degrading: {p} {r:.1f}x baseline")
            elif kind == "rate":
                ev = FaultEvent(ch.imu, "", kind, FAULT, ch.faults.timing.value, ch.faults.timing.detail)
            else:
                af = ch.faults.axes[ax]
                v = {"stuck": math.nan, "noise": af.noise.value, "bias_jump": af.bias.value,
                     "bias_drift": af.bias.drift_value, "spikes": af.spikes.value,
                     "saturation": af.saturation.value, "resolution": af.resolution.value}[kind]
                ev = FaultEvent(ch.imu, ax, kind, FAULT, v)
            out.append(ev.text())
        return out

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        chans = {}
        for imu, ch in self.channels.items():
            if ch.rate_hz is None:
                continue
            self._flush_feed(ch)
            chans[str(imu)] = {
                "message": ch.message, "rate_hz": ch.rate_hz, "fed_s": ch.fed_s, "learned_s": ch.learned_s,
                "fast": {a: e.state_dict() for a, e in ch.fast.items()},
                "slow": {a: e.state_dict() for a, e in ch.slow.items()},
                "learn": {a: e.state_dict() for a, e in ch.learn.items()},
                "detector": ch.detector.state_dict(),
                "faults": ch.faults.state_dict(),
            }
        pairs = {f"{i}-{j}": p.state_dict() for (i, j), p in self.pairs.items()}
        return {"format": STATE_FORMAT, "version": 1, "sysid": self.sysid,
                "baseline": self.baseline.to_dict() if self.baseline is not None else None, "channels": chans,
                "pairs": pairs, "disagree": [[k, a, d] for (k, a), d in self.disagree.items()]}

    def load_state_dict(self, d: Mapping) -> None:
        """Restore a saved state; raises ValueError (caller warns and starts fresh) if it is not ours."""
        if not isinstance(d, Mapping) or d.get("format") != STATE_FORMAT or d.get("version") != 1:
            raise ValueError("not a companion run state")
        if self.sysid is not None and d.get("sysid") not in (None, self.sysid):
            raise ValueError(f"state is for system id {d.get('sysid')}, not {self.sysid}")
        channels = {}
        for key, c in (d.get("channels") or {}).items():
            ch = Channel(int(key), str(c["message"]), self.cfg)
            ch.rate_hz = float(c["rate_hz"])
            ch.fast = {a: estimator_from_state(s) for a, s in c["fast"].items()}
            ch.slow = {a: estimator_from_state(s) for a, s in c["slow"].items()}
            ch.learn = {a: estimator_from_state(s) for a, s in c["learn"].items()}
            if set(ch.fast) != set(ch.axes) or set(ch.slow) != set(ch.axes) or (ch.learn and set(ch.learn) != set(ch.axes)):
                raise ValueError("state holds other axes than configured")
            ch.fed_s, ch.learned_s = float(c["fed_s"]), float(c["learned_s"])
            ch.detector.load_state_dict(c["detector"])
            if c.get("faults") is not None:
                ch.faults.load_state_dict(c["faults"])
            channels[ch.imu] = ch
        pairs = {}
        for key, pd in (d.get("pairs") or {}).items():
            i, j = (int(v) for v in key.split("-"))
            pairs[(i, j)] = PairDisagreement(i, j, self.cfg.faults)
            pairs[(i, j)].load_state_dict(pd)
        self.pairs = pairs
        self.disagree = {(int(k), str(a)): str(dt) for k, a, dt in d.get("disagree") or []}
        baseline = None
        if d.get("baseline") is not None:
            baseline = Baseline.from_dict(d["baseline"])
        if not self.baseline_fixed:
            self.baseline = baseline
        for ch in channels.values():
            if self._has_baseline(ch):
                ch.learn = {}
            elif not ch.learn:  # no baseline for this IMU and nothing being learned: learn afresh
                ch.learn = {a: make_estimator(rate_hz=ch.rate_hz, forgetting_s=None, **{
                    k: v for k, v in self.cfg.estimator.items() if k != "forgetting_s"}) for a in ch.axes}
                ch.learned_s = 0.0
        self.channels = channels
        if d.get("sysid") is not None and self.sysid is None:
            self.sysid = int(d["sysid"])
