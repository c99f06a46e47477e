"""One IMU of the live pipeline (PX4's DataValidator to the group's DataValidatorGroup): its block cutter,
motion gate, fault detectors, estimators, baseline learning and Allan health check.

Inputs: rows through :attr:`Channel.cutter`, closed blocks through :meth:`Channel.on_block` (still or not,
decided with the other IMUs by the pipeline), still settled blocks through :meth:`Channel.feed`;
outputs: FaultEvents, health transitions (:meth:`Channel.check`), the reported terms and the state.

Estimators per axis (companion.estimators.make_estimator): a *fast* one (exponential memory
``forgetting_fast_s``) for Q and N, a *slow* one (``forgetting_slow_s``) for B, K and R, and while
learning a third one without forgetting whose terms become the baseline after ``baseline_s`` seconds of
still data. Still blocks are queued and handed over in batches of about ``check_s`` (the estimators'
block updates are split-invariant: the same result, far fewer calls). A still block that does not follow the
last one fed (motion, a handling, a flight or a time gap between them) starts a new segment of the estimators
(no Allan cluster straddles the junction, as in the offline analysis' pooled still segments): the bias moves
while the vehicle is not still (warm-up, temperature, Gauss-Markov wander), and a step at a junction read as
part of one record raises every level by about step^2 tau / record, the shape of a rate random walk (K).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Mapping

import numpy as np

from companion.estimators import from_state_dict as estimator_from_state, make_estimator
from companion.health.baseline import check_params, risen_params, rounding_ceiling, supported_params
from companion.health.detector import DEGRADING, LEARNING, HealthDetector, Transition
from companion.health.faults import CARRY, FAULT, MIN_NOISE_SAMPLES, OK, BlockStats, FaultEvent, block_stats
from companion.health.monitor import ImuFaults
from companion.samples import ACCEL_AXES, GYRO_AXES
from companion.service.baseline_match import units_mismatch
from companion.service.blocks import RATE_CHANGE, BlockCutter
from companion.service.config import PipelineConfig
from companion.service.motion import MotionGate, Peer, noise_ratio
from companion.analysis.filters import sampling
from companion.sources.messages import IMU_LAYOUTS
from companion.sources.timing import stamp_resolution

# the MAVLink messages whose gyro is an integer (int16, mrad/s by default), from their layouts
INT16_MESSAGES = tuple(name for name, lay in IMU_LAYOUTS.items() if lay.dtype["xgyro"].kind == "i")
COLUMNS = {ax: 1 + i for i, ax in enumerate(GYRO_AXES + ACCEL_AXES)}  # column of each axis in a row
TEMP_COLUMN = 7  # the IMU temperature (degC, nan where the source has none)
#: the closed blocks kept for the IMU disagreement test: the last three, and older ones within RECENT_S of the
#: newest. A pair is tested at the slower stream's instants once MIN_ALIGNED of them are new
#: (service.imu_group); a stream logged at 2 Hz (a PX4 log's vehicle_imu, a telemetry tlog) has 6 samples in
#: three 1-s blocks, and with three blocks only it was never compared with its twin
RECENT_MIN_BLOCKS = 3
RECENT_S = 12.0
#: faults that corrupt the still data while they last and leave the gyro as it was when they clear: the
#: estimators are kept as they stood at the onset and put back at the clear. Fed to the 600-s memory, a
#: 60-s burst of 3x noise held "degrading: N" for ten minutes after the gyro was quiet again. Not a stuck or
#: dead reading (a sub-LSB gyro at rest cycles 'stuck'/'cleared', and its Allan terms must follow it), nor a
#: bias step (the gyro is not as it was).
TRANSIENT_FAULTS = ("noise", "spikes")
#: other rates whose estimators and references are kept for when the stream returns to them (memory: each
#: holds three estimator banks per axis)
KEPT_RATES = 4


class Channel:
    def __init__(self, imu: int, message: str, cfg: PipelineConfig, gyro_lsb: float | None | str = "default"):
        self.imu, self.message, self.cfg = imu, message, cfg
        self.time_res = stamp_resolution(message)  # 1 ms for time_boot_ms: 400 Hz comes as 2 and 3 ms steps
        # the LSB of the gyro (stored with a learned baseline); by default 1 mrad/s unless a float message
        # only the int16 MAVLink messages are rounded (mrad/s unless the scales say otherwise): HIGHRES_IMU, a
        # CSV, DataFlash IMU and ULog sensor_combined carry floats (as `analyze` reads them: a baseline from
        # its report then matches the stream)
        self.gyro_lsb = (1e-3 if message in INT16_MESSAGES else None) if gyro_lsb == "default" else gyro_lsb
        self.axes = GYRO_AXES + (ACCEL_AXES if cfg.accel else ())
        self.cutter = BlockCutter(cfg.block_s, cfg.reset_s, cfg.gap_s, self.time_res)
        self.gate = MotionGate(cfg)
        self.detector = HealthDetector(imu, cfg.health)
        self.faults = self._new_faults()
        self.fast: dict = {}
        self.slow: dict = {}
        self.learn: dict = {}
        self.learned_levels: dict = {}
        self.learned_s = 0.0
        self.fed_s = 0.0
        self._queue: list = []
        self._queue_s = 0.0
        self._junctions: set[int] = set()  # queue indices whose block does not follow the one before (new segment)
        self._fed_end_t: float | None = None  # time of the last sample queued for the estimators
        self._junction = False  # the next queued block starts a new segment whatever its time (other estimators)
        self.next_check_t: float | None = None
        self.pending: np.ndarray | None = None  # still block waiting for the look-ahead
        self.pending_stats: BlockStats | None = None
        self.still_run_s = 0.0
        self.last_stats: BlockStats | None = None  # of the last closed block (motion consensus between IMUs)
        self.recent: deque = deque()  # (t, gyro) of the last closed blocks (IMU disagreement; RECENT_S)
        self._tail: np.ndarray | None = None  # (t, gyro) of the last block's last samples (the spike search)
        self._blocks = {"blocks_still": 0, "blocks_moving": 0, "blocks_fed": 0}
        self.current: dict[str, dict[str, tuple[float, float]]] = {}
        self.off_rate: list[float] = []  # block rates of the consecutive blocks off the stream's rate
        self._profiles: list[tuple[float, dict]] = []  # (rate, rate-dependent state) of rates seen before
        self.rate_switches = 0
        # {"gyro": Hz, "accel": Hz}: the autopilot's low-pass cut-offs of these data (from the log's parameters
        # or PARAM_VALUE), modelled in the estimators' white-noise term unless the estimator config names one
        self.filters: dict[str, float] = {}
        self.gyro_moved = False  # any gyro axis read other than exactly 0 this run (the all-zero note)
        # the estimators as they stood at the onset of a transient fault (TRANSIENT_FAULTS), put back when it clears
        self._before_fault: dict | None = None
        self.restored_s = 0.0  # still data dropped that way (the summary's count)

    def see(self, gyro: np.ndarray) -> None:
        """Every arriving gyro row (n, 3): notes a non-zero value."""
        if not self.gyro_moved and gyro.size:
            self.gyro_moved = bool(np.any(gyro != 0.0))

    def all_zero(self) -> str | None:
        """A note when every gyro sample of the run read exactly 0 but no fault says so (a record too short for
        the dead test: a 2-s public rover log of 77 zeros was silent where analyze said 'gyro dead'); else None."""
        n = self.cutter.counts["samples"]
        if self.gyro_moved or n == 0 or self.faults.active():
            return None
        dur = f" ({n / self.rate_hz:.1f} s)" if self.rate_hz else ""
        why = ("dead, or a gyro quieter than the message's 1 mrad/s at rest" if self.message in INT16_MESSAGES
               else "dead, absent or not started (a live gyro's float never reads exactly 0)")
        return (f"IMU{self.imu}: gyro X, Y, Z read exactly 0 in all {n} samples{dur}: {why}; too few for the dead "
                "test to name it")

    def transient_note(self) -> str | None:
        """What the Allan estimates leave out for transient faults (the summary's note), or None."""
        if self.restored_s <= 0:
            return None
        return (f"IMU{self.imu}: {self.restored_s:.0f} s of still data fed during noise or spike faults were taken "
                "back out of the Allan estimates when the faults cleared")

    # ------------------------------------------------------------------ read-only views
    @property
    def rate_hz(self) -> float | None:
        return self.cutter.rate_hz

    @property
    def last_t(self) -> float | None:
        return self.cutter.last_t

    @property
    def counts(self) -> dict:
        """Samples dropped and kept, blocks by kind (a copy)."""
        return {**self.cutter.counts, **self._blocks}

    def peer(self) -> Peer | None:
        """What another IMU's motion gate needs of this one's latest block."""
        if self.last_stats is None:
            return None
        return Peer(self.last_stats, noise_ratio(self.last_stats, self.faults.still_sigma2()))

    def _new_faults(self) -> ImuFaults:
        # the step of an integer message (RAW_IMU, SCALED_IMU*); DataFlash, ULog, CSV and HIGHRES_IMU are floats
        coded = self.gyro_lsb if self.message in INT16_MESSAGES else None
        return ImuFaults(self.imu, self.cfg.gyro_limit, max(1, int(round(self.cfg.fault_ref_s / self.cfg.block_s))),
                         stamp_res=self.time_res, limits=self.cfg.faults, coded_lsb=coded)

    def too_slow(self) -> str | None:
        """What a stream too slow for the per-IMU fault tests is watched for, in words; None when it is not."""
        if not self.rate_hz:
            return None
        per_block = int(math.floor(self.cfg.block_s * self.rate_hz + 0.5)) + 1
        if per_block >= MIN_NOISE_SAMPLES:
            return None
        return (f"IMU{self.imu}: at {self.rate_hz:.1f} Hz a {self.cfg.block_s:g}-s block holds {per_block} samples, "
                f"fewer than the {MIN_NOISE_SAMPLES} the noise, bias, spikes and stuck-at-rest tests need: only a dead "
                "gyro, a gyro frozen in flight, a disagreement with another IMU and the Allan terms are watched "
                "(stream it at 4 Hz or more)")

    # ------------------------------------------------------------------ rate changes
    def kept_rates(self) -> tuple[int, float]:
        """(how many other rates, their still seconds) whose estimators are kept aside for when the stream
        returns to them (:meth:`switch_rate`): the still data of this IMU that are not in this rate's figures."""
        return len(self._profiles), float(sum(p["fed_s"] for _, p in self._profiles))

    def switch_rate(self, new_rate: float, t_block: np.ndarray) -> bool:
        """The stream now comes at ``new_rate`` (another client's stream request, a log-rate change): not a
        sensor fault. What depends on the rate (the estimators, the fault references and detectors, the timing
        reference) is kept aside for the old rate; the state kept for the new rate comes back when there is one
        (a rate that returns), else it is learned afresh, without alarms. True when a kept state came back."""
        self.flush()
        old = self.rate_hz
        if old is not None:
            # kept beside a rate within RATE_CHANGE of it, not in its place: the stream's rate can drift between
            # switches, and the one put aside then may hold seconds where the other holds minutes
            self._profiles.append((old, {"fast": self.fast, "slow": self.slow, "learn": self.learn,
                                         "learned_s": self.learned_s, "fed_s": self.fed_s, "faults": self.faults,
                                         "before_fault": self._before_fault}))
            if len(self._profiles) > KEPT_RATES:
                # the rate with the least still data goes: a stream that wanders over more rates than are kept
                # (a telemetry stream the autopilot slows while the radio is busy) dropped its oldest, often its
                # richest: a real tlog's IMU1 ended with 0 s of its 323 still blocks in any estimator
                self._profiles.pop(min(range(len(self._profiles)), key=lambda i: self._profiles[i][1]["fed_s"]))
        # of the kept rates the new one would be no change from (the test of block_off_rate: the new rate
        # within RATE_CHANGE of the kept one), the one with the most still data comes back. Measured as the
        # old rate over the new, 2.5 Hz counted as 'within 20 %' of 3.1 Hz, so the switch 2.5 -> 3.1 Hz
        # (+24 %) put the 2.5-Hz estimators aside and took them straight back
        kept = [(-p["fed_s"], abs(new_rate / r - 1.0), i) for i, (r, p) in enumerate(self._profiles)
                if abs(new_rate / r - 1.0) <= RATE_CHANGE]
        self.cutter.prev_rate_hz, self.cutter.rate_hz = old, float(new_rate)
        self.cutter.dts.clear()
        self.cutter.dts.extend(np.diff(np.asarray(t_block, dtype=float)).tolist())
        self.drop_lookahead()
        self._tail = None
        self.off_rate = []
        self.rate_switches += 1
        if kept:
            *_, i = min(kept)
            _, p = self._profiles.pop(i)
            self.fast, self.slow, self.learn = p["fast"], p["slow"], p["learn"]
            self.learned_s, self.fed_s, self.faults = p["learned_s"], p["fed_s"], p["faults"]
            self._before_fault = p.get("before_fault")
            self._queue, self._queue_s, self._junctions = [], 0.0, set()
            self._junction = True  # their last samples are of another time
            return True
        learning = bool(self.learn)
        self.make_estimators(learning=learning)
        self.faults = self._new_faults()
        return False

    # ------------------------------------------------------------------ estimators
    def _est_cfg(self, axis: str) -> dict:
        """The estimator settings of one axis: the configuration, plus the log's filter of that axis's data
        and how the samples were taken from it (a filter named in the configuration wins)."""
        est = {k: v for k, v in self.cfg.estimator.items() if k != "forgetting_s"}
        if est.get("filter_hz") is None:
            est["filter_hz"] = self.filters.get("gyro" if axis in GYRO_AXES else "accel")
        est.setdefault("sampling", sampling(self.message))
        return est

    def make_estimators(self, learning: bool) -> None:
        self.fast = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=self.cfg.forgetting_fast_s, **self._est_cfg(a))
                     for a in self.axes}
        self.slow = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=self.cfg.forgetting_slow_s, **self._est_cfg(a))
                     for a in self.axes}
        self.learn = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=None, **self._est_cfg(a))
                      for a in self.axes} if learning else {}
        self.learned_s = 0.0
        self.fed_s = 0.0
        self._queue, self._queue_s, self._junctions = [], 0.0, set()
        self._before_fault = None

    def set_filters(self, filters: dict) -> bool:
        """The autopilot's low-pass cut-offs ({"gyro": Hz, "accel": Hz}) became known or changed: the
        estimators that exist (and those kept for other rates) model them from their next report on (the
        filter shapes only the report's fit, not the accumulated levels). True when something changed."""
        new = {k: float(v) for k, v in (filters or {}).items() if k in ("gyro", "accel") and v}
        if new == self.filters:
            return False
        self.filters = new
        if self.cfg.estimator.get("filter_hz") is not None:
            return True
        banks = [self.fast, self.slow, self.learn] + [p[k] for _, p in self._profiles for k in ("fast", "slow", "learn")]
        for bank in banks:
            for a, est in bank.items():
                if hasattr(est, "filter_hz"):
                    est.filter_hz = new.get("gyro" if a in GYRO_AXES else "accel")
        return True

    def relearn(self) -> None:
        """Learn the baseline afresh (estimators without forgetting from now on)."""
        self.learn = {a: make_estimator(rate_hz=self.rate_hz, forgetting_s=None, **self._est_cfg(a)) for a in self.axes}
        self.learned_s = 0.0
        if self._before_fault is not None:
            self._before_fault["learn"] = None

    def stop_learning(self) -> None:
        self.learn = {}
        if self._before_fault is not None:
            self._before_fault["learn"] = None

    def forget_rest(self, learning: bool) -> bool:
        """The motion gate found that what it took for rest was vibration (MotionGate.mislearned): the still
        data queued and fed so far are dropped (fresh estimators, the baseline learned afresh when
        ``learning``) and so are the fault detectors' still references (learned from the same blocks), unless
        a fault is active (its alarm stays). True when the fault references were learned afresh."""
        self.make_estimators(learning=learning)
        self._fed_end_t, self._junction, self.next_check_t = None, True, None
        self.current = {}
        self.restart_settling()
        if self.faults.active():
            return False
        self.faults = self._new_faults()
        return True

    def restart_settling(self) -> None:
        """Motion or a time discontinuity: drop the look-ahead and settle again."""
        self.pending, self.pending_stats, self.still_run_s = None, None, 0.0

    def drop_lookahead(self) -> None:
        """A rate change: the look-ahead block belongs to the other rate and is dropped, but the vehicle has
        not moved, so the still time counts on. Settling again at each change would leave no still data at
        all under a router that sets stream rates every 15 s (MAVProxy's default: 4-6 s at 4 Hz, then 10 s
        of settling, in every 15 s)."""
        self.pending, self.pending_stats = None, None

    def on_break(self) -> None:
        """Time discontinuity: the partial block, the look-ahead and the recent blocks are dropped."""
        self.cutter.drop()
        self.restart_settling()
        self.next_check_t = None
        self.recent.clear()
        self._tail = None

    # ------------------------------------------------------------------ blocks
    def stats(self, data: np.ndarray) -> BlockStats:
        # the previous block's last samples, when this block follows them (one sample period apart): the spike
        # search sees a spike on either side of the junction (health/faults.py block_stats)
        prev = None
        if self._tail is not None and self.rate_hz:
            gap = float(data[0, 0]) - float(self._tail[-1, 0])
            if 0.0 < gap < 1.5 / self.rate_hz:
                prev = self._tail[:, 1:4]
        st = block_stats(data[:, 1:4], self.faults.dd_scale_ref(), prev=prev)
        self._tail = data[-CARRY:, :4].copy()
        if data.shape[1] > TEMP_COLUMN:
            temp = data[:, TEMP_COLUMN]
            ok = np.isfinite(temp)
            if ok.any():
                st.temperature = float(temp[ok].mean())
        return st

    def is_still(self, data: np.ndarray, st: BlockStats, peers: list[Peer]) -> bool:
        """The motion gate for one block with the other IMUs' latest blocks."""
        mine = noise_ratio(st, self.faults.still_sigma2())
        return self.gate.still(data, st, mine, peers, settling=self.still_run_s == 0.0 and self.pending is None)

    def on_block(self, data: np.ndarray, st: BlockStats, still: bool) -> list[FaultEvent]:
        """Every closed block: remember it (motion consensus, disagreement) and run the per-block detectors."""
        self.last_stats = st
        self.recent.append((data[:, 0].copy(), data[:, 1:4].copy()))
        while len(self.recent) > RECENT_MIN_BLOCKS and self.recent[0][0][-1] < data[-1, 0] - RECENT_S:
            self.recent.popleft()
        return self._transient(self.faults.on_block(st, data[:, 0], still, data[:, 1:4], data[:, 4:7]))

    def settle(self, data: np.ndarray, st: BlockStats, still: bool) -> tuple[np.ndarray | None, BlockStats | None]:
        """The look-ahead, for every block once the rate is known: returns the pending still block (and its
        statistics) to test and feed now that the block after it is still too, or (None, None); keeps this
        block pending once the vehicle has been still for ``settle_s``. A moving block drops the pending one."""
        self._blocks["blocks_still" if still else "blocks_moving"] += 1
        if not still:
            self.restart_settling()
            return None, None
        out = (self.pending, self.pending_stats)
        settled = self.still_run_s >= self.cfg.settle_s
        self.pending = data if settled else None
        self.pending_stats = st if settled else None
        self.still_run_s += data.shape[0] / self.rate_hz
        return out

    def on_quiet(self, st: BlockStats, extra_var: Mapping[str, float], data: np.ndarray | None = None) -> list[FaultEvent]:
        if data is None:
            return self._transient(self.faults.on_quiet(st, extra_var))
        return self._transient(self.faults.on_quiet(st, extra_var, data[:, 1:4], data[:, 0]))

    # ------------------------------------------------------------------ transient faults
    def _transient(self, events: list[FaultEvent]) -> list[FaultEvent]:
        """After the fault detectors: at the onset of a transient fault (TRANSIENT_FAULTS, on any axis: the
        estimators run per IMU) the estimators' state is kept, without the still blocks queued since the last
        hand-over (the burst's first blocks, before the detector was sure, are among them); when the last
        such fault clears it is put back and what was fed meanwhile is dropped. Between the two the
        estimators are fed as usual, so the Allan terms show the fault while it lasts. Returns ``events``."""
        if not events or not self.fast:
            return events
        active = any(k in TRANSIENT_FAULTS for k, _ in self.faults.active())
        if active and self._before_fault is None:
            self._before_fault = self._snapshot()
        elif not active and self._before_fault is not None:
            self._put_back(self._before_fault)
            self._before_fault = None
        return events

    def _snapshot(self) -> dict:
        learning = bool(self.learn)
        return {"fast": {a: e.state_dict() for a, e in self.fast.items()},
                "slow": {a: e.state_dict() for a, e in self.slow.items()},
                "learn": {a: e.state_dict() for a, e in self.learn.items()} if learning else None,
                "fed_s": self.fed_s - self._queue_s,
                "learned_s": max(0.0, self.learned_s - self._queue_s) if learning else self.learned_s}

    def _put_back(self, snap: Mapping) -> None:
        dropped = self.fed_s - float(snap["fed_s"])
        self.fast = {a: estimator_from_state(s) for a, s in snap["fast"].items()}
        self.slow = {a: estimator_from_state(s) for a, s in snap["slow"].items()}
        # a baseline learning that started afresh meanwhile (relearn) keeps its own estimators
        if self.learn and snap.get("learn") is not None:
            self.learn = {a: estimator_from_state(s) for a, s in snap["learn"].items()}
            self.learned_s = float(snap["learned_s"])
        self.fed_s = float(snap["fed_s"])
        self.restored_s += max(0.0, dropped)
        self._queue, self._queue_s, self._junctions = [], 0.0, set()
        self._fed_end_t, self._junction = None, True  # what comes next does not follow what they saw last
        self.current = {}

    def feed(self, data: np.ndarray) -> bool:
        """Queue a still block for the estimators; True when the baseline learning is complete (the caller
        takes :meth:`learned_terms`)."""
        self._blocks["blocks_fed"] += 1
        # a block between this one and the last fed one was not fed (moving, settling, a gap): the junction is
        # then about a block long, where consecutive fed blocks are one sample period apart (two where a sample
        # was lost); the threshold lies between. Half a block alone is one period at 2 Hz, where jitter made
        # every other pair of blocks a junction and the estimators lost every cluster time beyond a few seconds
        t0 = float(data[0, 0])
        joined = 0.5 * self.cfg.block_s + 1.5 / self.rate_hz
        if self._junction or (self._fed_end_t is not None and t0 - self._fed_end_t > joined):
            self._junctions.add(len(self._queue))
        self._junction = False
        self._fed_end_t = float(data[-1, 0])
        self._queue.append(data)
        duration = data.shape[0] / self.rate_hz
        self.fed_s += duration
        self._queue_s += duration
        if self.next_check_t is None:
            self.next_check_t = float(data[-1, 0]) + self.cfg.check_s
        if self.learn:
            self.learned_s += duration
            # not from the data of a transient fault: they will be dropped when it clears
            if self.learned_s >= self.cfg.baseline_s and self._before_fault is None:
                self.flush()
                return True
        if self._queue_s >= self.cfg.check_s:
            self.flush()
        return False

    def flush(self) -> None:
        """Hand the queued still blocks to the estimators."""
        if not self._queue:
            return
        cuts = sorted(self._junctions | {0, len(self._queue)})
        queue, junctions = self._queue, self._junctions
        self._queue, self._queue_s, self._junctions = [], 0.0, set()
        banks = [self.fast, self.slow] + ([self.learn] if self.learn else [])
        for a, b in zip(cuts[:-1], cuts[1:]):
            data = np.concatenate(queue[a:b]) if b - a > 1 else queue[a]
            for ax in self.axes:
                y = np.ascontiguousarray(data[:, COLUMNS[ax]])
                for bank in banks:
                    est = bank[ax]
                    if a in junctions and hasattr(est, "new_segment"):
                        est.new_segment()
                    est.update(y)

    def learned_terms(self) -> dict[str, dict[str, tuple[float, float]]]:
        """The learned baseline per axis ``{param: (value, std)}``; learning stops."""
        self.flush()
        out = {ax: check_params(est.terms(full=True) if est.kind == "octave" else est.terms(), side="baseline")
               for ax, est in self.learn.items()}
        # the Allan levels behind them: a later rise is compared only where the measured curve shows it
        self.learned_levels = {ax: est.avar() for ax, est in self.learn.items() if hasattr(est, "avar")}
        self.learn = {}
        return out

    # ------------------------------------------------------------------ checks and reports
    def report_terms(self, ax: str, full: bool = False) -> list[dict]:
        """The reported terms of one axis (SI; resolved values and 95 % bounds, ``"bound": True``): Q and N
        from the fast estimator, B, K, R, Gauss-Markov and sinusoid from the slow one."""
        def terms(est):
            return est.terms(full=full) if est.kind == "octave" else est.terms()

        fast = [t for t in terms(self.fast[ax]) if t["effect"] in ("quantization", "white_noise")]
        slow = [t for t in terms(self.slow[ax]) if t["effect"] not in ("quantization", "white_noise")]
        return fast + slow

    def current_params(self, ax: str, terms=None) -> dict[str, tuple[float, float]]:
        """``{param: (value, s)}`` of the parameters the window resolves (a bound, or a term whose 95 % interval
        reaches 0, is not compared with a baseline); s / value is the one-sigma of ln(value) from the interval's
        lower end (health.baseline.check_params)."""
        return check_params(self.report_terms(ax) if terms is None else terms, side="current")

    def _per_estimator(self, ax: str, params: dict[str, tuple[float, float]], test) -> dict[str, tuple[float, float]]:
        """``params`` filtered by ``test(sub, (tau, avar, edf))`` per estimator: Q and N with the fast
        estimator's Allan levels, B, K and R with the slow one's."""
        out = {}
        for bank, ps in ((self.fast, ("Q", "N")), (self.slow, ("B", "K", "R"))):
            sub = {p: params[p] for p in ps if p in params}
            est = bank.get(ax)
            if sub and est is not None and hasattr(est, "avar"):
                sub = test(sub, est.avar())
            out.update(sub)
        return out

    def supported(self, ax: str, params: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        """The current parameters the estimators' own Allan curves support (health.baseline.supported_params)."""
        return self._per_estimator(ax, params, lambda sub, lv: supported_params(sub, *lv, z=self.cfg.health.z))

    def risen(self, ax: str, params: dict[str, tuple[float, float]], base, base_levels) -> dict[str, tuple[float, float]]:
        """The current parameters whose rise over the baseline the measured Allan curves show
        (health.baseline.risen_params), each against the levels the baseline was learned from."""
        return self._per_estimator(ax, params,
                                   lambda sub, lv: risen_params(sub, base, lv, base_levels, z=self.cfg.health.z))

    def check_due(self, t: float) -> bool:
        return self.next_check_t is not None and t >= self.next_check_t

    def check(self, t: float, baseline, strict: bool) -> tuple[dict[str, list[dict]], list[Transition], str | None]:
        """The Allan check at message time ``t``: returns the reported terms per axis (empty before
        ``min_report_s`` of still data), the health transitions, and an error line when the loaded
        baseline is in other units or of another sensor (``strict``: a loaded, not forced baseline)."""
        self.next_check_t = t + self.cfg.check_s
        self.flush()
        if self.fed_s < self.cfg.min_report_s:
            return {}, [], None
        reported, transitions = {}, []
        for ax in self.axes:
            terms = self.report_terms(ax)
            cur = self.current_params(ax, terms)
            self.current[ax] = cur
            cur = self.supported(ax, cur)
            reported[ax] = terms
            base = baseline.get(self.imu, ax) if baseline is not None else None
            if base is None or self.learn:
                continue
            bad = units_mismatch(base, cur) if strict else None
            if bad:
                return reported, transitions, (f"baseline {baseline.source} does not match IMU{self.imu} {ax}: "
                                               f"{bad}; use a baseline of this stream or --baseline-force")
            shown = self.risen(ax, cur, base, baseline.get_levels(self.imu, ax))
            # a raised flag clears on them too: skipped, a value that stayed a little above a baseline learned
            # low held "degrading" for good after the rise had gone
            unshown = {p: v for p, v in cur.items() if p not in shown}
            if ax in GYRO_AXES:
                base = rounding_ceiling(base, self.rate_hz, self.gyro_lsb)
            for tr in self.detector.check(ax, shown, base, unshown):
                transitions.append(tr)
                if ax in GYRO_AXES:
                    high = any(d.state == DEGRADING for (a, _), d in self.detector.detectors.items() if a == ax)
                    self.faults.set_external("allan", ax, FAULT if high else OK)
        return reported, transitions, None

    def health(self, has_baseline: bool) -> int:
        """0 healthy, 1 degrading (any fault, even while the Allan baseline is still being learned), 2 learning."""
        if self.faults.active():
            return DEGRADING
        if self.learn or not has_baseline:
            return LEARNING
        return self.detector.state

    def allan_worst(self, ax: str) -> tuple[float, str]:
        """(ratio, param) of the largest degrading Allan term of an axis."""
        worst = [(d.ratio, p) for (a, p), d in self.detector.detectors.items() if a == ax and d.state == DEGRADING]
        return max(worst) if worst else (math.nan, "N")

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        self.flush()
        return {"message": self.message, "rate_hz": self.rate_hz, "fed_s": self.fed_s, "learned_s": self.learned_s,
                "fast": {a: e.state_dict() for a, e in self.fast.items()},
                "slow": {a: e.state_dict() for a, e in self.slow.items()},
                "learn": {a: e.state_dict() for a, e in self.learn.items()},
                "detector": self.detector.state_dict(), "faults": self.faults.state_dict(),
                "before_fault": self._before_fault, "restored_s": self.restored_s}

    @classmethod
    def from_state(cls, imu: int, c: Mapping, cfg: PipelineConfig) -> "Channel":
        """A channel restored from :meth:`state_dict`; ValueError when it does not fit the configuration."""
        ch = cls(imu, str(c["message"]), cfg)
        ch.cutter.rate_hz = float(c["rate_hz"])
        ch.fast = {a: estimator_from_state(s) for a, s in c["fast"].items()}
        ch.slow = {a: estimator_from_state(s) for a, s in c["slow"].items()}
        ch.learn = {a: estimator_from_state(s) for a, s in c["learn"].items()}
        if set(ch.fast) != set(ch.axes) or set(ch.slow) != set(ch.axes) or (ch.learn and set(ch.learn) != set(ch.axes)):
            raise ValueError("state holds other axes than configured")
        ch.fed_s, ch.learned_s = float(c["fed_s"]), float(c["learned_s"])
        ch._junction = True  # the next still data do not follow what the estimators saw before the restart
        snap = c.get("before_fault")
        if snap is not None:
            if set(snap["fast"]) != set(ch.axes) or set(snap["slow"]) != set(ch.axes):
                raise ValueError("state holds other axes than configured")
            ch._before_fault = dict(snap)
        ch.restored_s = float(c.get("restored_s", 0.0))
        ch.detector.load_state_dict(c["detector"])
        if c.get("faults") is not None:
            ch.faults.load_state_dict(c["faults"])
            ch.faults.restart()
        return ch
