"""One IMU of the live pipeline (PX4's DataValidator to the group's DataValidatorGroup).

A :class:`Channel` is one IMU stream of one vehicle: its samples cut into blocks, each block judged still or
moving and run through the fault detectors, still blocks fed to the online Allan estimators, the baseline
learned from them, and the Allan check against that baseline. It composes small parts, each with its own
state:

* :class:`~companion.service.blocks.BlockCutter` (``cutter``): timestamps, rate, blocks;
* :class:`~companion.service.motion_gate.MotionGate` (``gate``) and :class:`~companion.service.settling.StillSettler`
  (``settler``): still or moving, and the look-ahead before a still block is fed;
* :class:`~companion.health.monitor.ImuFaults` (``faults``): the per-block fault detectors;
* :class:`~companion.service.estimator_bank.EstimatorBank` (``bank``): the estimators at the current rate,
  the baseline being learned, the still data queued for them;
* :class:`~companion.service.rate_tracker.RateTracker` (``rates``): blocks off the rate, switches, the
  estimators and fault references kept for other rates;
* :class:`~companion.service.allan_check.AllanCheck` (``allan``): the degradation test.

The interface, in the order a block goes through it: rows through :attr:`Channel.cutter`; each closed
block through :meth:`stats`, :meth:`is_still` (with the other IMUs' latest blocks) and :meth:`on_block`
(the per-block fault detectors); the look-ahead through :meth:`settle`; a settled still block through
:meth:`on_quiet` (the detectors that need rest) and :meth:`feed` (the estimators; True when the baseline is
learned, then :meth:`learned_terms`); every ``check_s`` :meth:`check`. A rate change is
:meth:`switch_rate`, a time discontinuity :meth:`on_break`. Outputs: FaultEvents, the check's
transitions, the reported terms (:meth:`report_terms`), :meth:`health` and the state (:meth:`state_dict`).

A still block that does not follow the last one fed (motion, a handling, a flight or a time gap between
them) starts a new segment of the estimators (no Allan cluster straddles the junction, as in the offline
analysis' pooled still segments): the bias moves while the vehicle is not still (warm-up, temperature,
Gauss-Markov wander), and a step at a junction read as part of one record raises every level by about
step^2 tau / record, the shape of a rate random walk (K).
"""

from __future__ import annotations

from collections import deque
from typing import Mapping

import numpy as np

from companion.analysis.filters import sampling
from companion.estimators import make_estimator
from companion.health.baseline import check_params
from companion.health.degradation import DEGRADING, LEARNING
from companion.health.block_stats import CARRY, BlockStats, block_stats
from companion.health.faults import FaultEvent
from companion.health.monitor import ImuFaults
from companion.samples import ACCEL_AXES, GYRO_AXES
from companion.service.allan_check import AllanCheck, CheckResult, StreamFacts
from companion.service.blocks import BlockCutter
from companion.service.pipeline_config import PipelineConfig
from companion.service.estimator_bank import EstimatorBank
from companion.service.motion_gate import MotionGate, Peer, noise_ratio
from companion.service.rate_tracker import RateProfile, RateTracker
from companion.service.settling import StillSettler
from companion.sources.messages import IMU_LAYOUTS
from companion.sources.timestamps import stamp_resolution

# the MAVLink messages whose gyro is an integer (int16, mrad/s by default), from their layouts
INT16_MESSAGES = tuple(name for name, lay in IMU_LAYOUTS.items() if lay.dtype["xgyro"].kind == "i")
TEMP_COLUMN = 7  # the IMU temperature (degC, nan where the source has none)
#: the closed blocks kept for the IMU disagreement test: the last three, and older ones within RECENT_S of the
#: newest. A pair is tested at the slower stream's instants once MIN_ALIGNED of them are new
#: (service.imu_group): a stream logged at 2 Hz (a PX4 log's vehicle_imu, a telemetry tlog) has 6 samples in
#: three 1-s blocks, too few to compare it with its twin
RECENT_MIN_BLOCKS = 3
RECENT_S = 12.0
#: faults that corrupt the still data while they last and leave the gyro as it was when they clear: the
#: estimators are kept as they stood at the onset and put back at the clear, so a burst of noise does not
#: hold "degrading: N" for the fast estimator's memory after the gyro is quiet again. Not a stuck or dead
#: reading (a sub-LSB gyro at rest cycles 'stuck'/'cleared', and its Allan terms must follow it), nor a
#: bias step (the gyro is not as it was).
TRANSIENT_FAULTS = ("noise", "spikes")
#: new samples a stream brings between two Allan checks at least (Channel.check_period): 50 at a 5 Hz
#: stream in the default 10 s, so only slower streams wait longer
CHECK_MIN_SAMPLES = 50


class Channel:
    """One IMU stream: blocks, motion, fault detectors, estimators, baseline learning and the Allan check."""

    def __init__(self, imu: int, message: str, cfg: PipelineConfig, gyro_lsb: float | None | str = "default"):
        self.imu, self.message, self.cfg = imu, message, cfg
        self.time_res = stamp_resolution(message)  # 1 ms for time_boot_ms: 400 Hz comes as 2 and 3 ms steps
        # the LSB of the gyro (stored with a learned baseline): only the int16 MAVLink messages are rounded
        # (1 mrad/s unless the scales say otherwise); HIGHRES_IMU, a CSV, DataFlash IMU and ULog
        # sensor_combined carry floats (as `analyze` reads them: a baseline from its report then matches)
        self.gyro_lsb = (1e-3 if message in INT16_MESSAGES else None) if gyro_lsb == "default" else gyro_lsb
        self.axes = GYRO_AXES + (ACCEL_AXES if cfg.accel else ())
        self.cutter = BlockCutter(cfg.block_s, cfg.reset_s, cfg.gap_s, self.time_res)
        self.gate = MotionGate(cfg)
        self.settler = StillSettler(cfg.settle_s)
        self.faults = self._new_faults()
        self.bank = EstimatorBank()
        self.rates = RateTracker()
        self.allan = AllanCheck(imu, cfg)
        self.learned_levels: dict = {}  # per axis the Allan levels the baseline was learned from
        self.next_check_t: float | None = None
        self._fed_end_t: float | None = None  # time of the last sample queued for the estimators
        self._junction = False  # the next queued block starts a new segment whatever its time (other estimators)
        self.last_stats: BlockStats | None = None  # of the last closed block (motion consensus between IMUs)
        self.recent: deque = deque()  # (t, gyro) of the last closed blocks (IMU disagreement; RECENT_S)
        self._tail: np.ndarray | None = None  # (t, gyro) of the last block's last samples (the spike search)
        self._blocks = {"blocks_still": 0, "blocks_moving": 0, "blocks_fed": 0}
        # {"gyro": Hz, "accel": Hz}: the autopilot's low-pass cut-offs of these data (from the log's parameters
        # or PARAM_VALUE), modelled in the estimators' white-noise term unless the estimator config names one
        self.filters: dict[str, float] = {}
        self.gyro_moved = False  # any gyro axis read other than exactly 0 this run (the all-zero note)
        self.restored_s = 0.0  # still data taken back out after transient faults (the summary's count)

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

    @property
    def fast(self) -> dict:
        return self.bank.fast

    @property
    def slow(self) -> dict:
        return self.bank.slow

    @property
    def learn(self) -> dict:
        return self.bank.learn

    @property
    def fed_s(self) -> float:
        return self.bank.fed_s

    @property
    def learned_s(self) -> float:
        return self.bank.learned_s

    @property
    def _before_fault(self) -> dict | None:
        return self.bank.held

    @property
    def current(self) -> dict:
        return self.allan.current

    @property
    def rate_switches(self) -> int:
        return self.rates.switches

    def peer(self) -> Peer | None:
        """What another IMU's motion gate needs of this one's latest block."""
        if self.last_stats is None:
            return None
        return Peer(self.last_stats, noise_ratio(self.last_stats, self.faults.still_sigma2()))

    def kept_rates(self) -> tuple[int, float]:
        """(how many other rates, their still seconds) whose estimators are kept aside for when the stream
        returns to them (:meth:`switch_rate`): the still data of this IMU that are not in this rate's figures."""
        return self.rates.kept_summary()

    def see(self, gyro: np.ndarray) -> None:
        """Every arriving gyro row (n, 3): notes a non-zero value."""
        if not self.gyro_moved and gyro.size:
            self.gyro_moved = bool(np.any(gyro != 0.0))

    # ------------------------------------------------------------------ parts made afresh
    def _new_faults(self) -> ImuFaults:
        # the step of an integer message (RAW_IMU, SCALED_IMU*); DataFlash, ULog, CSV and HIGHRES_IMU are floats
        coded = self.gyro_lsb if self.message in INT16_MESSAGES else None
        return ImuFaults(self.imu, self.cfg.gyro_limit, max(1, int(round(self.cfg.fault_ref_s / self.cfg.block_s))),
                         stamp_res=self.time_res, limits=self.cfg.faults, coded_lsb=coded)

    def _est_cfg(self, axis: str) -> dict:
        """The estimator settings of one axis: the configuration, plus the log's filter of that axis's data
        and how the samples were taken from it (a filter named in the configuration wins)."""
        est = {k: v for k, v in self.cfg.estimator.items() if k != "forgetting_s"}
        if est.get("filter_hz") is None:
            est["filter_hz"] = self.filters.get("gyro" if axis in GYRO_AXES else "accel")
        est.setdefault("sampling", sampling(self.message))
        return est

    def _make_estimator(self, axis: str, forgetting_s: float | None):
        return make_estimator(rate_hz=self.rate_hz, forgetting_s=forgetting_s, **self._est_cfg(axis))

    def make_estimators(self, learning: bool) -> None:
        """Fresh estimators at the current rate (``learning``: also the baseline's); nothing fed."""
        self.bank = EstimatorBank.create(self.axes, self._make_estimator, self.cfg.forgetting_fast_s,
                                         self.cfg.forgetting_slow_s, learning)

    def relearn(self) -> None:
        """Learn the baseline afresh (estimators without forgetting from now on)."""
        self.bank.relearn(self.axes, self._make_estimator)

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
        for bank in [self.bank] + self.rates.kept_banks():
            bank.set_filters(new)
        return True

    def forget_rest(self, learning: bool) -> bool:
        """The motion gate found that what it took for rest was vibration (MotionGate.mislearned): the still
        data queued and fed so far are dropped (fresh estimators, the baseline learned afresh when
        ``learning``) and so are the fault detectors' still references (learned from the same blocks), unless
        a fault is active (its alarm stays). True when the fault references were learned afresh."""
        self.make_estimators(learning=learning)
        self._fed_end_t, self._junction, self.next_check_t = None, True, None
        self.allan.current = {}
        self.settler.restart()
        if self.faults.active():
            return False
        self.faults = self._new_faults()
        return True

    # ------------------------------------------------------------------ rate changes
    def switch_rate(self, new_rate: float, t_block: np.ndarray, keep_window: bool = False) -> bool:
        """The stream now comes at ``new_rate`` (another client's stream request, a log-rate change): not a
        sensor fault. What depends on the rate (the estimators, the fault references and detectors, the timing
        reference) is kept aside for the old rate; the state kept for the new rate comes back when there is one
        (a rate that returns), else it is learned afresh, without alarms. True when a kept state came back."""
        self.flush()
        # a drift the cutter re-took (``keep_window``) has switched the cutter already, its window at the new
        # rate; else the window is that of the blocks held back at the new rate
        old = self.cutter.prev_rate_hz if keep_window else self.rate_hz
        if old is not None:
            self.rates.keep(old, RateProfile(self.bank, self.faults))
        back = self.rates.take(new_rate)
        if not keep_window:
            self.cutter.switch(new_rate, self.rates.off_dts or np.diff(np.asarray(t_block, dtype=float)).tolist())
        self.settler.drop_lookahead()
        self._tail = None
        self.rates.switched()
        if back is not None:
            self.bank, self.faults = back.bank, back.faults
            self.bank.clear_queue()
            self._junction = True  # their last samples are of another time
            return True
        self.make_estimators(learning=bool(self.bank.learn))
        self.faults = self._new_faults()
        return False

    # ------------------------------------------------------------------ blocks
    def on_break(self) -> None:
        """Time discontinuity: the partial block, the look-ahead and the recent blocks are dropped."""
        self.cutter.drop()
        self.settler.restart()
        self.next_check_t = None
        self.recent.clear()
        self._tail = None

    def stats(self, data: np.ndarray) -> BlockStats:
        """The statistics of a closed block (health.block_stats.block_stats), with its mean temperature."""
        # the previous block's last samples, when this block follows them (one sample period apart): the spike
        # search sees a spike on either side of the junction
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
        return self.gate.still(data, st, mine, peers, settling=self.settler.settling)

    def on_block(self, data: np.ndarray, st: BlockStats, still: bool) -> list[FaultEvent]:
        """Every closed block: remember it (motion consensus, disagreement) and run the per-block detectors."""
        self.last_stats = st
        self.recent.append((data[:, 0].copy(), data[:, 1:4].copy()))
        while len(self.recent) > RECENT_MIN_BLOCKS and self.recent[0][0][-1] < data[-1, 0] - RECENT_S:
            self.recent.popleft()
        return self._transient(self.faults.on_block(st, data[:, 0], still, data[:, 1:4], data[:, 4:7]))

    def settle(self, data: np.ndarray, st: BlockStats, still: bool) -> tuple[np.ndarray | None, BlockStats | None]:
        """The look-ahead, for every block once the rate is known (StillSettler.settle)."""
        self._blocks["blocks_still" if still else "blocks_moving"] += 1
        return self.settler.settle(data, st, still, self.rate_hz)

    def on_quiet(self, st: BlockStats, extra_var: Mapping[str, float], data: np.ndarray | None = None) -> list[FaultEvent]:
        """A settled still block through the detectors that need rest (noise, bias, resolution)."""
        if data is None:
            return self._transient(self.faults.on_quiet(st, extra_var))
        return self._transient(self.faults.on_quiet(st, extra_var, data[:, 1:4], data[:, 0]))

    def _transient(self, events: list[FaultEvent]) -> list[FaultEvent]:
        """After the fault detectors: at the onset of a transient fault (TRANSIENT_FAULTS, on any axis: the
        estimators run per IMU) the estimators' state is kept, without the still blocks queued since the last
        hand-over (the burst's first blocks, before the detector was sure, are among them); when the last
        such fault clears it is put back and what was fed meanwhile is dropped. Between the two the
        estimators are fed as usual, so the Allan terms show the fault while it lasts. Returns ``events``."""
        if not events or not self.bank.fast:
            return events
        active = any(k in TRANSIENT_FAULTS for k, _ in self.faults.active())
        if active and self.bank.held is None:
            self.bank.held = self.bank.snapshot()
        elif not active and self.bank.held is not None:
            self.restored_s += self.bank.put_back(self.bank.held)
            self.bank.held = None
            self._fed_end_t, self._junction = None, True  # what comes next does not follow what they saw last
            self.allan.current = {}
        return events

    # ------------------------------------------------------------------ estimators
    def feed(self, data: np.ndarray) -> bool:
        """Queue a still block for the estimators; True when the baseline learning is complete (the caller
        takes :meth:`learned_terms`)."""
        self._blocks["blocks_fed"] += 1
        # a block between this one and the last fed one was not fed (moving, settling, a gap): the junction is
        # then about a block long, where consecutive fed blocks are one sample period apart (two where a sample
        # was lost); the threshold lies between, and above one period at 2 Hz, where the jitter of half a block
        # alone would make every other pair of blocks a junction
        t0 = float(data[0, 0])
        joined = 0.5 * self.cfg.block_s + 1.5 / self.rate_hz
        junction = self._junction or (self._fed_end_t is not None and t0 - self._fed_end_t > joined)
        self._junction = False
        self._fed_end_t = float(data[-1, 0])
        self.bank.queue_block(data, data.shape[0] / self.rate_hz, junction)
        if self.next_check_t is None:
            self.next_check_t = float(data[-1, 0]) + self.check_period()
        # not from the data of a transient fault: they will be dropped when it clears
        if self.bank.learn and self.bank.learned_s >= self.cfg.baseline_s and self.bank.held is None:
            self.flush()
            return True
        if self.bank.queue_s >= self.cfg.check_s:
            self.flush()
        return False

    def flush(self) -> None:
        """Hand the queued still blocks to the estimators."""
        self.bank.flush()

    def learned_terms(self) -> dict[str, dict[str, tuple[float, float]]]:
        """The learned baseline per axis ``{param: (value, std)}``; learning stops."""
        terms, self.learned_levels = self.bank.take_baseline()
        return terms

    # ------------------------------------------------------------------ checks and reports
    def report_terms(self, ax: str, full: bool = False) -> list[dict]:
        """The reported terms of one axis (SI; resolved values and 95 % bounds, ``"bound": True``): Q and N
        from the fast estimator, B, K, R, Gauss-Markov and sinusoid from the slow one."""
        return self.bank.report_terms(ax, full)

    def current_params(self, ax: str, terms=None) -> dict[str, tuple[float, float]]:
        """``{param: (value, s)}`` of the parameters the window resolves (a bound, or a term whose 95 % interval
        reaches 0, is not compared with a baseline); s / value is the one-sigma of ln(value) from the interval's
        lower end (health.baseline.check_params)."""
        return check_params(self.report_terms(ax) if terms is None else terms, side="current")

    def check_period(self) -> float:
        """Message time between Allan checks: ``check_s``, longer where the stream is slow, so that each check
        has CHECK_MIN_SAMPLES new samples (at 1 Hz a check every 10 s would judge the same data again and
        again, and the hysteresis would count near-identical checks as separate evidence)."""
        return max(self.cfg.check_s, CHECK_MIN_SAMPLES / self.rate_hz) if self.rate_hz else self.cfg.check_s

    def check_due(self, t: float) -> bool:
        return self.next_check_t is not None and t >= self.next_check_t

    def check(self, t: float, baseline, strict: bool) -> CheckResult:
        """The Allan check at message time ``t`` (AllanCheck.run): the reported terms per axis (empty before
        ``min_report_s`` of still data), the health transitions, and an error line when the loaded baseline
        is in other units or of another sensor (``strict``: a loaded, not forced baseline)."""
        self.next_check_t = t + self.check_period()
        self.flush()
        if self.fed_s < self.cfg.min_report_s:
            return CheckResult({}, [])
        facts = StreamFacts(self.imu, self.rate_hz, self.gyro_lsb)
        return self.allan.run(self.bank, self.axes, facts, self.faults, baseline, strict)

    def health(self, has_baseline: bool) -> int:
        """0 healthy, 1 degrading (any fault, even while the Allan baseline is still being learned), 2 learning."""
        if self.faults.active():
            return DEGRADING
        if self.bank.learn or not has_baseline:
            return LEARNING
        return self.allan.detector.state

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        b = self.bank.state_dict()
        return {"message": self.message, "rate_hz": self.rate_hz, "fed_s": b["fed_s"], "learned_s": b["learned_s"],
                "fast": b["fast"], "slow": b["slow"], "learn": b["learn"],
                "detector": self.allan.detector.state_dict(), "faults": self.faults.state_dict(),
                "before_fault": b["before_fault"], "restored_s": self.restored_s}

    @classmethod
    def from_state(cls, imu: int, c: Mapping, cfg: PipelineConfig) -> "Channel":
        """A channel restored from :meth:`state_dict`; ValueError when it does not fit the configuration."""
        ch = cls(imu, str(c["message"]), cfg)
        ch.cutter.rate_hz = float(c["rate_hz"])
        ch.bank = EstimatorBank.from_state(c, ch.axes)
        ch._junction = True  # the next still data do not follow what the estimators saw before the restart
        ch.restored_s = float(c.get("restored_s", 0.0))
        ch.allan.detector.load_state_dict(c["detector"])
        if c.get("faults") is not None:
            ch.faults.load_state_dict(c["faults"])
            ch.faults.restart()
        return ch
