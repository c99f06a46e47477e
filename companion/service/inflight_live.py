"""Each IMU's own gyro noise while armed (on the ground and in flight), online, from the redundant IMUs.

At rest the Allan estimators see the gyro alone; armed, the body's rotation swamps it. Two IMUs on one
body see the same rotation, so per pair (:class:`PairTrack`):

1. the samples are compared at the slower stream's instants (the faster one interpolated there);
2. a running relative calibration (:class:`companion.estimators.pair_calibration.PairCalibration`: bias,
   3x3 scale/misalignment, time offset; recursive least squares with a ``calib_memory_s`` memory) removes
   the rotation; what is left is the two IMUs' own noise (common-mode vibration cancels, what each IMU
   picks up of it on its own does not: that is part of the figure, "the IMU's own noise in flight");
3. the calibrated difference feeds octave Allan accumulators (:mod:`companion.estimators.octave_bank`),
   one per condition and axis with a ``memory_s`` memory (the test's), one over this flight (since arming;
   the figures reported), and while learning one without forgetting (the baseline);
4. every ``check_s`` its white level N^2 = AVAR(tau) tau is read at the first octave at or above a shortest
   cluster time, the rounding of int16 messages removed (:func:`companion.redundancy.hat.quantization_avar`),
   1-sigma from its EDF (the overlap of the staggered phases counted). The test's accumulators: above the
   low-pass roll-off (:func:`companion.redundancy.fit_points.tau_min_for`). This flight's figures: the
   offline method's cluster time and filter shape (:meth:`PairTrack._first`), so `run` and `analyze` agree.

Three IMUs: each IMU's N from the three-cornered hat with the offline method's variance
(:func:`companion.redundancy.hat.hat_share`; a share below two of its sigmas is a 95 % upper bound). Two
IMUs: the pair figure, an upper bound of each IMU's. One IMU: nothing (its noise cannot be separated from
motion). Conditions: ``ground`` (armed, the body not turning) and ``flight`` (armed and turning), from the
HEARTBEAT armed bit and the gyro's half-second means; each has its own estimators, baseline and test.

The baseline (per condition: the hat figures and each pair's figure) is learned from the first
``baseline_s`` of that condition's data and kept in the state file; then every check tests each pair's figure
against its baseline both ways (:class:`InflightTest`: a z test whose threshold is set by its false-alarm
rate per IMU-hour, :mod:`companion.service.inflight_alarm`) and names the IMU whose pairs changed while the others' did not (:meth:`InflightNoise._test`). The online calibration differs
from the offline one (:mod:`companion.redundancy.calibration`, a batch fit with instrumental variables and
cross-filtering) in being recursive, scipy-free and fitted on 0.1-s means; the Allan points, the hat and the
cluster time are the offline method's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.redundancy.fit_points import tau_min_for
from companion.redundancy.redundant import EQUALIZED_TAU0, SHAPE_MIN
from companion.redundancy.shape import MAX_FILTER_FRACTION
from companion.redundancy.hat import hat_share, quantization_avar
from companion.estimators.octave_bank import OctaveBankEstimator
from companion.estimators.pair_calibration import PairCalibration
from companion.health.degradation import DEGRADING, HEALTHY
from companion.health.faults import AXES
from companion.health.hold import debounce
from companion.service.inflight_alarm import allan_shape, overlap_edf_gain, z_threshold
from companion.service.imu_group import _period
from companion.service.inflight_align import _held_faulty, aligned
from companion.service.inflight_settle import SettledFlight

CONDITIONS = ("ground", "flight")
PHASES = 4  # staggered phases of the octave accumulators
#: the overlap of a level's min(PHASES, m) phases: its EDF over the bank's (the count of one phase's differences)
EDF_GAIN = {p: overlap_edf_gain(p) for p in range(1, PHASES + 1)}


@dataclass
class InflightTest:
    """The degradation test in flight (:mod:`companion.service.inflight_alarm`): per pair, axis and direction,
    Z = ln(now / baseline) / sigma_L above ``z`` for ``hold_on`` checks in a row, ``z`` solved so that all the
    tests of a vehicle give ``per_imu_hour`` false alarms per IMU and flight hour; back after ``hold_off``
    checks with |Z| below ``z_back``. The pair without the named IMU must stay within ``z_stable`` of its
    baseline (the other two agree as before)."""

    per_imu_hour: float = 1e-3
    #: relative scatter of a pair's figure the Allan statistics do not hold (the frame's vibration level
    #: wandering with throttle and manoeuvres, in the pair's difference through the IMUs' different pick-up),
    #: added to sigma_L: healthy 250 Hz flights of the px4 preset move pair figures by 6-13 % over minutes
    #: while their sampling sigma is 2-3 %. The stated false-alarm rate is that of the statistics alone: with
    #: this term the rate of a stationary flight is lower
    model_sigma: float = 0.05
    hold_on: int = 4
    hold_off: int = 6
    z_back: float = 2.0
    z_stable: float = 2.0

    def z(self, imus: int, check_s: float, memory_s: float, baseline_s: float) -> float:
        return z_threshold(self.per_imu_hour, imus, self.hold_on, check_s, memory_s, baseline_s)


@dataclass
class ZDetector:
    """Hysteresis of one test (one pair, axis and direction)."""

    state: int = HEALTHY
    count: int = 0

    def check(self, zval: float, z_on: float, test: InflightTest) -> None:
        self.state, self.count, _ = debounce(self.state, self.count, zval > z_on, test.hold_on, test.hold_off,
                                             good=zval < test.z_back)


VERSION = 1
Z95 = 1.96


@dataclass
class InflightConfig:
    calib_memory_s: float = 60.0  # memory of the relative calibration
    memory_s: float = 30.0  # memory of the current figure
    baseline_s: float = 240.0  # armed data per condition learned as the baseline
    check_s: float = 5.0
    min_edf: float = 20.0
    turning: float = 0.03  # rad/s: a half-second mean body rate above this is flight, not ground
    ground_hold_s: float = 10.0  # not turning for this long before flight becomes ground again
    settle_s: float = 15.0  # the test leaves out each flight stretch's first and last (inflight_settle.py)
    test: InflightTest = field(default_factory=InflightTest)


class PairTrack:
    """One pair: its calibration and, per condition and axis, the Allan accumulators of the difference."""

    def __init__(self, cfg: InflightConfig):
        self.cfg = cfg
        self.cal = PairCalibration(cfg.calib_memory_s)
        self.t_done = -math.inf
        self.rate_hz: float | None = None
        self.filter_hz: float | None = None  # the lower of the two IMUs' known gyro low-pass cut-offs
        self.filters: tuple = ()  # both IMUs' cut-offs (None: unknown)
        self.all_filters: tuple = ()  # every IMU's of the vehicle (analyze's cascade)
        self.lsb: tuple = ()  # the two IMUs' sample rounding (rad/s; int16 messages)
        self.cur: dict[str, list[OctaveBankEstimator]] = {}
        self.learn: dict[str, list[OctaveBankEstimator] | None] = {}
        self.whole: dict[str, list[OctaveBankEstimator]] = {}  # this flight (since arming), no forgetting
        self.seconds = {c: 0.0 for c in CONDITIONS}
        self.whole_s = {c: 0.0 for c in CONDITIONS}  # behind the whole-flight figures
        self.last_cond: str | None = None
        self.settled = SettledFlight(cfg.settle_s)  # the test's flight data: take-offs and landings left out
        self.suspended = False  # one of its IMUs is held dead, stuck or saturated (InflightNoise.on_block)

    def suspend(self) -> None:
        """Stop the pair while one of its IMUs is held faulty: its accumulators start afresh when it resumes
        (they hold the second or two of the fault before it was named: a frozen axis' difference is the
        twin's whole motion, hundreds of times its noise), the learned baseline (InflightNoise) is kept."""
        if not self.suspended:
            self.suspended = True
            self.cur, self.learn, self.whole = {}, {}, {}
            self.whole_s = {c: 0.0 for c in CONDITIONS}
            self.last_cond = None
            self.settled.end()

    def _banks(self, cond: str, learning: bool):
        mk = dict(rate_hz=self.rate_hz, effects=("white_noise",), phases=PHASES, max_tau_s=8.0, fit="diag")
        if cond not in self.cur:
            self.cur[cond] = [OctaveBankEstimator(forgetting_s=self.cfg.memory_s, **mk) for _ in AXES]
            self.learn[cond] = [OctaveBankEstimator(**mk) for _ in AXES] if learning else None
        if cond not in self.whole:  # a whole flight reaches the slow telemetry streams' cluster times
            self.whole[cond] = [OctaveBankEstimator(**dict(mk, max_tau_s=64.0)) for _ in AXES]
        return self.cur[cond], self.learn[cond], self.whole[cond]

    def feed(self, t: np.ndarray, gi: np.ndarray, gj: np.ndarray, cond: str | None, learning: bool) -> None:
        if self.rate_hz is None:
            self.rate_hz = 1.0 / _period(t)
        gap = self.cal.t_last is not None and float(t[0]) - self.cal.t_last > 5.0 / self.rate_hz
        if gap:
            self.cal.restart()
        e = self.cal.update(t, gi, gj)
        if e is None or cond is None:
            self.last_cond = None
            self.settled.end()
            return
        cur, learn, whole = self._banks(cond, learning)
        junction = gap or self.last_cond != cond
        self.last_cond = cond
        for a in range(3):
            if junction:
                whole[a].new_segment()
            whole[a].update(e[:, a])
        self.whole_s[cond] += t.shape[0] / self.rate_hz
        for eb, start in self.settled.route(t, e, cond, junction):  # the test's: take-offs, landings left out
            for est, y in [(b[a], eb[:, a]) for b in (cur, learn) if b is not None for a in range(3)]:
                if start:
                    est.new_segment()
                est.update(y)
            self.seconds[cond] += eb.shape[0] / self.rate_hz

    def level(self, cond: str, a: int, which: str = "cur") -> tuple[float, float, float]:
        """(N^2, 1-sigma, EDF) of axis ``a``'s difference over ``which`` accumulators (``cur``: the last
        ``memory_s``; ``learn``: the learning data; ``whole``: this flight): the Allan variance at the first
        octave at or above :func:`tau_min_for` with ``min_edf``, times tau, without the rounding of the two
        IMUs' samples."""
        banks = getattr(self, which).get(cond)
        if not banks or self.rate_hz is None:
            return math.nan, math.nan, 0.0
        tau, avar, edf = banks[a].avar()
        m = np.maximum(np.rint(tau * self.rate_hz), 1.0)
        edf = edf * np.where(m >= PHASES, EDF_GAIN[PHASES], [EDF_GAIN[int(min(x, PHASES))] for x in m])
        first, shape = self._first(which, m)
        ok = np.flatnonzero((tau >= first * (1 - 1e-9)) & (edf >= self.cfg.min_edf) & np.isfinite(avar))
        if ok.size == 0:
            return math.nan, math.nan, 0.0
        k = int(ok[0])
        q = sum(float(quantization_avar(lsb, tau[k], self.rate_hz)) for lsb in self.lsb)
        v = float(max(avar[k] - q, 0.0) * tau[k] / shape[k])
        return v, v * math.sqrt(2.0 / float(edf[k])), float(edf[k])

    def _first(self, which: str, m: np.ndarray) -> tuple[float, np.ndarray]:
        """(shortest cluster time read, the filters' Allan shape per level to divide out). The test's
        accumulators: above the low-pass roll-off (:func:`tau_min_for`), no shape. This flight's figures:
        analyze's choice (:func:`companion.redundancy.redundant._equalized`): with every IMU's cut-off known
        and below 0.45 of the rate, from ``EQUALIZED_TAU0`` samples or where the cascade of all the IMUs'
        filters keeps ``SHAPE_MIN`` of the white level, the pair's own filters' shape divided out."""
        one = np.ones(m.shape[0])
        fcs = self.all_filters
        if which != "whole" or not fcs or not all(f and 0 < f < MAX_FILTER_FRACTION * self.rate_hz for f in fcs):
            return tau_min_for(self.rate_hz, self.filter_hz), one
        grid = np.arange(1, 257)
        casc = allan_shape(fcs, self.rate_hz, grid)
        m0 = int(grid[np.argmax(casc >= SHAPE_MIN)]) if np.any(casc >= SHAPE_MIN) else 256
        own = 0.5 * (allan_shape(self.filters[:1], self.rate_hz, m) + allan_shape(self.filters[1:], self.rate_hz, m))
        return max(EQUALIZED_TAU0, m0) / self.rate_hz, own

    def learned_s(self, cond: str) -> float:
        banks = self.learn.get(cond)
        return 0.0 if not banks else banks[0].n_samples / self.rate_hz


@dataclass
class Verdict:
    """A change of the in-flight test for IMU ``who``."""

    who: int
    cond: str
    axis: str
    state: int
    ratio: float

    def imus(self) -> tuple[int, ...]:
        return (self.who,)

    def text(self) -> str:
        """STATUSTEXT, e.g. ``IMU2 gyro X flight noise changed: pair 2.1x`` (<= 50 characters): the largest
        change of its pairs' figures."""
        word = "changed" if self.state == DEGRADING else "back"
        return f"IMU{self.who} gyro {self.axis[1].upper()} {self.cond} noise {word}: pair {self.ratio:.2g}x"[:50]


def _n(v: float, s: float) -> tuple[float, float]:
    """(N, 1-sigma) from (N^2, 1-sigma), as the octave bank propagates it."""
    n = math.sqrt(max(v, 0.0))
    return n, math.sqrt(max(v, 0.0) + s) - n


class InflightNoise:
    """The IMUs' own noise while armed (module docstring); the pipeline calls :meth:`on_block` after every
    closed block and reads :attr:`figures`, :meth:`degrading` and :meth:`state_dict`."""

    def __init__(self, cfg: InflightConfig | None = None, block_s: float = 1.0):
        self.cfg = cfg or InflightConfig()
        self.block_s = float(block_s)
        self.pairs: dict[tuple[int, int], PairTrack] = {}
        self.cond: str | None = None
        self._still_since: float | None = None
        self.next_check: float | None = None
        # per condition: {who: {axis: (N, 1-sigma, bound)}}; who an IMU, or a pair (i, j) of two IMUs
        self.figures: dict[str, dict] = {c: {} for c in CONDITIONS}  # this flight (since arming)
        self._armed = False
        self.baseline: dict[str, dict] = {c: {} for c in CONDITIONS}
        self.detectors: dict[tuple, ZDetector] = {}  # (cond, pair, axis, "up" | "down")
        self.named: set = set()  # (cond, imu, axis) the test names
        #: cond -> {(pair, axis): Z of the latest check (InflightTest)}
        self.last_z: dict[str, dict] = {}
        self.seen: dict = {}  # (cond, pair) -> its test data's seconds at the last check

    # ------------------------------------------------------------------ condition
    def _condition(self, channels, armed: bool, t: float) -> str | None:
        """ground or flight while armed (None disarmed: the at-rest machinery's time), from the least
        vibrating IMU's half-second mean rates in its latest block."""
        if not armed:
            self.cond, self._still_since = None, None
            return None
        turn = []
        for ch in channels.values():
            if not ch.recent or ch.recent[-1][0][-1] < t - 2.0 * self.block_s:
                continue
            tb, gb = ch.recent[-1]
            k = max(1, int(round(0.5 * tb.shape[0] / max(tb[-1] - tb[0], 1e-9))))
            m = gb[: (gb.shape[0] // k) * k].reshape(-1, k, 3).mean(axis=1) if gb.shape[0] >= k else gb
            turn.append(float(np.max(np.linalg.norm(m, axis=1))))
        if not turn:
            return self.cond
        if min(turn) > self.cfg.turning:
            self.cond, self._still_since = "flight", None
        elif self.cond != "flight":
            self.cond = "ground"
        else:
            self._still_since = t if self._still_since is None else self._still_since
            if t - self._still_since >= self.cfg.ground_hold_s:
                self.cond = "ground"
        return self.cond

    # ------------------------------------------------------------------ data
    def on_block(self, imu: int, channels, armed: bool, t: float) -> list[Verdict]:
        """After a block of IMU ``imu``: its pairs' new common samples through calibration and accumulators;
        the figures and the test when a check is due. Returns the test's changes."""
        if len(channels) < 2:
            return []
        if armed and not self._armed:  # a new flight: its own figures
            for p in self.pairs.values():
                p.whole, p.whole_s = {}, {c: 0.0 for c in CONDITIONS}
        self._armed = bool(armed)
        cond = self._condition(channels, armed, t)
        ch = channels[imu]
        faulty = {i for i, c in channels.items() if _held_faulty(c)}
        for other in channels.values():
            if other is ch or not other.recent or not ch.recent:
                continue
            key = tuple(sorted((imu, other.imu)))
            pair = self.pairs.get(key)
            if pair is None:
                pair = self.pairs[key] = PairTrack(self.cfg)
            if min(channels[key[0]].recent[-1][0][-1], channels[key[1]].recent[-1][0][-1]) < pair.t_done - 5.0:
                pair.t_done = -math.inf  # a reboot: time starts again
            fc = [c.filters.get("gyro") for c in (channels[key[0]], channels[key[1]])]
            pair.filter_hz = min((f for f in fc if f), default=None)
            pair.filters = tuple(fc)
            pair.all_filters = tuple(c.filters.get("gyro") for c in channels.values())
            pair.lsb = tuple(c.gyro_lsb for c in (channels[key[0]], channels[key[1]]) if c.gyro_lsb)
            if key[0] in faulty or key[1] in faulty:  # resumes through feed's gap: a fresh calibration
                pair.suspend()
                pair.t_done = max(pair.t_done, min(float(channels[i].recent[-1][0][-1]) for i in key))
                continue
            pair.suspended = False
            got = aligned(channels[key[0]], channels[key[1]], pair.t_done)
            if got is None:
                continue
            pair.t_done = float(got[0][-1])
            pair.feed(*got, cond, learning=cond is not None and not self.baseline[cond])
        if self.next_check is None or t < self.next_check - 10 * self.cfg.check_s:
            self.next_check = t + self.cfg.check_s
        if t < self.next_check:
            return []
        self.next_check = t + self.cfg.check_s
        return self.check()

    # ------------------------------------------------------------------ figures and test
    def _figures(self, cond: str, which: str = "cur") -> dict:
        """{who: {axis: (N, 1-sigma, bound)}} of one condition from the current (or learning) accumulators:
        three IMUs per IMU (the hat), two IMUs the pair (i, j) (its figure bounds each IMU)."""
        levels = {k: [p.level(cond, a, which) for a in range(3)] for k, p in self.pairs.items()}
        imus = sorted({i for k in levels for i in k})
        out: dict = {}
        if len(imus) == 3 and len(levels) == 3:
            for a, ax in enumerate(AXES):
                edf = min(v[a][2] for v in levels.values())
                if not edf > 0:
                    continue
                for i in imus:
                    j, k = (x for x in imus if x != i)
                    lv = [levels[tuple(sorted(p))][a][0] for p in ((i, j), (i, k), (j, k))]
                    v, _, s = (float(x) for x in hat_share(*lv, edf))
                    bound = not v >= 2.0 * s
                    n, sn = _n(max(v, 0.0) + Z95 * s if bound else v, s)
                    out.setdefault(i, {})[ax] = (n, sn, bound)
        elif len(imus) == 2 and len(levels) == 1:
            (k, v), = levels.items()
            for a, ax in enumerate(AXES):
                if math.isfinite(v[a][0]):
                    n, s = _n(*v[a][:2])
                    out.setdefault(k, {})[ax] = (n, s, False)
        return out

    def _pair_levels(self, cond: str, which: str = "cur") -> dict:
        """{(i, j): {axis: (N, 1-sigma)}} of the pairs' differences."""
        out = {}
        for k, p in self.pairs.items():
            axes = {ax: _n(*p.level(cond, a, which)[:2]) for a, ax in enumerate(AXES)}
            out[k] = {ax: v for ax, v in axes.items() if math.isfinite(v[0]) and v[0] > 0}
        return out

    def check(self) -> list[Verdict]:
        """Figures, baseline learning and the test of every condition; the changes of the named IMUs."""
        out: list[Verdict] = []
        for cond in CONDITIONS:
            self.figures[cond] = self._figures(cond, "whole")
            if not self.baseline[cond]:
                if self.pairs and all(p.learned_s(cond) >= self.cfg.baseline_s for p in self.pairs.values()):
                    pairs = self._pair_levels(cond, "learn")
                    if any(pairs.values()):  # else (a slow stream: no level resolved yet) learning goes on
                        self.baseline[cond] = {"imus": self._figures(cond, "learn"), "pairs": pairs}
                        for p in self.pairs.values():
                            p.learn[cond] = None
                continue
            out += self._test(cond)
        return out

    def z_on(self) -> float:
        """The test's threshold on Z for this vehicle's number of IMUs (:class:`InflightTest`)."""
        imus = len({i for k in self.pairs for i in k})
        c = self.cfg
        return c.test.z(max(imus, 2), c.check_s, c.memory_s, c.baseline_s)

    def _test(self, cond: str) -> list[Verdict]:
        """Per pair and axis, has the difference's N changed from its baseline (up or down: Z of
        :class:`InflightTest` both ways, with its hysteresis)? Three IMUs: an IMU is named when a pair it is
        in has changed while the pair without it stays within ``z_stable`` of its baseline (the other two
        agree as before), and no other IMU fits this; a change of every pair is the vibration of the whole
        frame, not one IMU. Both ways, because what an IMU picks up of the frame's vibration is shared with the
        others: when one IMU's pick-up grows towards another's, their difference shrinks. Two IMUs: a changed
        pair names both as suspects."""
        test, out = self.cfg.test, []
        z_on = self.z_on()
        base = self.baseline[cond]["pairs"]
        now = self._pair_levels(cond)
        changed: dict[str, set] = {ax: set() for ax in AXES}
        ratios: dict = {}
        zs: dict = {}
        for k in [k for k, p in self.pairs.items() if p.suspended]:  # afresh when it resumes
            for ax in AXES:
                self.detectors.pop((cond, k, ax, "up"), None)
                self.detectors.pop((cond, k, ax, "down"), None)
        for k, axes in now.items():
            if self.pairs[k].suspended:
                continue
            for ax, (x, sx) in axes.items():
                if ax not in base.get(k, {}):
                    continue
                b, sb = base[k][ax]
                if not (x > 0 and b > 0 and sx > 0 and sb > 0):
                    continue
                sig = math.sqrt((sx / x) ** 2 + (sb / b) ** 2 + test.model_sigma ** 2)
                zv = math.log(x / b) / sig
                up = self.detectors.setdefault((cond, k, ax, "up"), ZDetector())
                down = self.detectors.setdefault((cond, k, ax, "down"), ZDetector())
                if self.pairs[k].seconds[cond] > self.seen.get((cond, k), -1.0):  # new data: another look
                    up.check(zv, z_on, test)
                    down.check(-zv, z_on, test)
                ratios[(k, ax)], zs[(k, ax)] = x / b, zv
                if DEGRADING in (up.state, down.state):
                    changed[ax].add(k)
        self.last_z[cond] = zs
        self.seen.update({(cond, k): p.seconds[cond] for k, p in self.pairs.items()})
        imus = sorted({i for k in self.pairs for i in k})
        for ax in AXES:
            named = set()
            if len(imus) == 2 and changed[ax]:
                named = set(imus)
            elif len(imus) >= 3 and changed[ax] and len(changed[ax]) < len(self.pairs):
                for i in imus:
                    others = [k for k in self.pairs if i not in k]
                    if (changed[ax] & {k for k in self.pairs if i in k}) and all(
                            abs(zs.get((k, ax), math.inf)) < test.z_stable for k in others):
                        named.add(i)
                if len(named) > 1:  # the changed pair's two IMUs both fit: which one is not known yet
                    named = set()
            for i in imus:
                key = (cond, i, ax)
                if (key in self.named) == (i in named):
                    continue
                r = max((ratios.get((k, ax), 1.0) for k in self.pairs if i in k), key=lambda v: abs(math.log(v)))
                if i in named:
                    self.named.add(key)
                else:
                    self.named.discard(key)
                out.append(Verdict(i, cond, ax, DEGRADING if i in named else HEALTHY, r))
        return out

    def degrading(self, imu: int) -> bool:
        """The in-flight (or ground) test names this IMU on some axis."""
        return any(i == imu for _, i, _ in self.named)

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        """The learned baselines (the accumulators start afresh: the next flight is another record)."""
        def enc(who):
            return "-".join(str(i) for i in who) if isinstance(who, tuple) else str(who)

        return {"version": VERSION, "baseline": {
            c: {part: {enc(w): {ax: list(v) for ax, v in axes.items()} for w, axes in b[part].items()}
                for part in ("imus", "pairs")} for c, b in self.baseline.items() if b}}

    def load_state_dict(self, d) -> None:
        """Restore :meth:`state_dict`; ValueError when it is not of this version."""
        if not isinstance(d, dict) or d.get("version") != VERSION:
            raise ValueError("in-flight state of another version")

        def dec(k: str):
            parts = tuple(int(x) for x in k.split("-"))
            return parts if len(parts) > 1 else parts[0]

        base: dict = {c: {} for c in CONDITIONS}
        for c, b in (d.get("baseline") or {}).items():
            if c in CONDITIONS:
                base[c] = {part: {dec(w): {ax: tuple(v) for ax, v in axes.items()} for w, axes in b[part].items()}
                           for part in ("imus", "pairs")}
        self.baseline = base
