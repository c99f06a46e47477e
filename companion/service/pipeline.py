"""From MAVLink messages to estimates, health and reports, in message time only.

Per IMU (``StreamKey.instance``; the first IMU message type seen for an instance is used, other types
carrying the same IMU are ignored) and per gyro axis (accel axes optional):

1. Samples are cut into blocks of ``block_s`` seconds of message time. Each block is *still* when
   the vehicle is disarmed (its autopilot's HEARTBEAT ``base_mode`` bit 128 clear; no HEARTBEAT at all
   counts as disarmed) AND the motion detector agrees: |block mean of each gyro axis| <= ``gyro_mean``,
   the block mean of the accel vector within ``accel_shift`` of the still reference, the block std of
   |accel| <= ``accel_std`` and each gyro axis' block std <= ``gyro_std_factor`` x its still reference.
   A block is fed only if the next block is still too (one block of look-ahead, so the start of a
   handling never leaks in) and the vehicle has been still for ``settle_s`` before it.
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
from companion.mavlink.reporter import MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING, Reporter
from companion.samples import ACCEL_AXES, GYRO_AXES

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
    reset_s: float = 1.0
    gap_s: float = 0.5
    estimator: dict = field(default_factory=dict)  # passed to make_estimator (e.g. effects, phases, max_tau_s)
    health: DetectorConfig = field(default_factory=DetectorConfig)

    @classmethod
    def from_mapping(cls, cfg: Mapping | None) -> "PipelineConfig":
        out = cls()
        names = {f.name for f in fields(cls)}
        for k, v in dict(cfg or {}).items():
            if k not in names:
                raise ValueError(f"run: unknown key {k!r}")
            if k == "health":
                out.health = DetectorConfig.from_mapping(v)
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
        self.gyro_lsb = None if message in ("HIGHRES_IMU", "CSV") else 1e-3  # set from the scale table in on_sample
        self.axes = GYRO_AXES + (ACCEL_AXES if cfg.accel else ())
        self.last_t: float | None = None
        self.dts: deque = deque(maxlen=64)
        self.rate_hz: float | None = None
        self.block: list = []
        self.block_t0: float | None = None
        self.pending = None  # still block waiting for the look-ahead
        self.still_run_s = 0.0
        self.ref_accel = None
        self.ref_gyro_std = None
        self.fast: dict = {}
        self.slow: dict = {}
        self.learn: dict = {}
        self.learned_s = 0.0
        self.fed_s = 0.0
        self.feed_buf: list = []
        self.feed_buf_s = 0.0
        self.next_check_t: float | None = None
        self.detector = HealthDetector(imu, cfg.health)
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
        ch.block.append((t, *gyro, *accel))
        if t - ch.block_t0 >= self.cfg.block_s - 0.5 * self._period(ch):
            self._close_block(ch)
        if ch.next_check_t is not None and t >= ch.next_check_t:
            self._check(ch, t)
        self.reporter.tick(t)
        return True

    @staticmethod
    def _period(ch: Channel) -> float:
        return 1.0 / ch.rate_hz if ch.rate_hz else (float(np.median(ch.dts)) if ch.dts else 0.0)

    def _break(self, ch: Channel) -> None:
        """Time discontinuity: drop the partial block and the look-ahead, settle again."""
        ch.block, ch.block_t0, ch.pending, ch.still_run_s = [], None, None, 0.0
        ch.next_check_t = None

    # ------------------------------------------------------------------ blocks
    def _close_block(self, ch: Channel) -> None:
        data = np.asarray(ch.block, dtype=float)
        ch.block, ch.block_t0 = [], None
        if len(ch.dts) >= 8:
            rate = 1.0 / float(np.median(ch.dts))
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
                ch.pending, ch.still_run_s = None, 0.0
                return
        if ch.rate_hz is None:
            return
        duration = data.shape[0] / ch.rate_hz
        still = (not self.armed) and self._still(ch, data)
        ch.counts["blocks_still" if still else "blocks_moving"] += 1
        if not still:
            ch.pending, ch.still_run_s = None, 0.0
            return
        if ch.pending is not None:
            self._feed(ch, ch.pending)
        ch.pending = data if ch.still_run_s >= self.cfg.settle_s else None
        ch.still_run_s += duration

    def _still(self, ch: Channel, data: np.ndarray) -> bool:
        g, a = data[:, 1:4], data[:, 4:7]
        cfg = self.cfg
        if np.any(np.abs(g.mean(axis=0)) > cfg.gyro_mean):
            return False
        g_std = g.std(axis=0)
        a_mean = a.mean(axis=0)
        if np.linalg.norm(a, axis=1).std() > cfg.accel_std:
            return False
        if ch.ref_accel is not None and np.linalg.norm(a_mean - ch.ref_accel) > cfg.accel_shift:
            # moved to a new attitude; it becomes the reference once still for settle_s
            ch.ref_accel = a_mean if ch.still_run_s == 0.0 and ch.pending is None else ch.ref_accel
            return False
        if ch.ref_gyro_std is not None and np.any(g_std > cfg.gyro_std_factor * np.maximum(ch.ref_gyro_std, 1e-6)):
            return False
        w = 0.05
        ch.ref_accel = a_mean if ch.ref_accel is None else (1 - w) * ch.ref_accel + w * a_mean
        ch.ref_gyro_std = g_std if ch.ref_gyro_std is None else (1 - w) * ch.ref_gyro_std + w * g_std
        return True

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
            self.reporter.set_health(ch.imu, LEARNING)
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
        self.reporter.set_health(ch.imu, self.health(ch))

    def health(self, ch: Channel) -> int:
        if ch.learn or not self._has_baseline(ch):
            return LEARNING
        return ch.detector.state

    def send_health_now(self, state: int | None = None) -> None:
        """Send every IMU's health at once (e.g. STALE when the link is silent: no message time advances)."""
        for imu, ch in sorted(self.channels.items()):
            s = self.health(ch) if state is None else state
            self.reporter.set_health(imu, s)
            self.reporter.sink.send_named_value_float(
                int(round((ch.last_t or 0.0) * 1000)) & 0xFFFFFFFF, f"IMU{imu}G_HLTH", float(s))

    def summary(self) -> list[dict]:
        out = []
        for imu, ch in sorted(self.channels.items()):
            row = {"imu": imu, "message": ch.message, "rate_hz": ch.rate_hz, "still_s": ch.fed_s,
                   "health": STATE_NAMES[self.health(ch)], "counts": dict(ch.counts), "axes": {}}
            if ch.fast and ch.fed_s > 0:
                self._flush_feed(ch)
                for ax in ch.axes:
                    terms = self.report_terms(ch, ax, full=True)
                    row["axes"][ax] = {"current": self.current_params(ch, ax, terms), "terms": terms,
                                       "baseline": self.baseline.get(imu, ax) if self.baseline else None}
            out.append(row)
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
            }
        return {"format": STATE_FORMAT, "version": 1, "sysid": self.sysid,
                "baseline": self.baseline.to_dict() if self.baseline is not None else None, "channels": chans}

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
            channels[ch.imu] = ch
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
