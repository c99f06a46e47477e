"""Each IMU's vibration pick-up against its twins' in flight (numpy only).

Two or three IMUs on one body see the same rotation and the same frame vibration; each picks up that
vibration through its own mount (damper, board, screws). The IMU differences used for the in-flight noise
(companion/service/inflight_live.py) cancel the common part and keep only (g_i - g_j) v: when one IMU's
pick-up g_i grows from below its twin's towards it (a loosened mount on an IMU that was damped) the
difference shrinks while that IMU's own vibration grew. This module measures the pick-up directly:

    P_i = mean power of IMU i's gyro in the band [f_lo, f_hi] of a window        (1)
    L_ij = 0.5 ln(P_i / P_j)                                                      (2)

the band above the vehicle's true motion (:data:`F_LO` Hz) and below the log's Nyquist (``HI_FRACTION``
of the rate), where a multirotor's gyro holds rotor vibration and the sensor's noise. With one time span
for both IMUs, the frame's vibration level (throttle, manoeuvres) cancels in the ratio; what is left is the
IMUs' pick-up ratio and whatever true motion reaches the band (common to both, it pulls L towards 0).
:func:`band_power` is one window's (1); :class:`PickupTrack` accumulates one IMU's per-window powers
into time bins shared by the IMUs, so that ratios compare the same instants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.health.hold import debounce

F_LO = 8.0  # Hz: above a vehicle's controlled motion (attitude loops close at a few Hz)
HI_FRACTION = 0.45  # of the rate: below the Nyquist frequency, clear of its edge
MIN_SAMPLES = 16  # a window shorter than this gives no power


def band(rate_hz: float) -> tuple[float, float] | None:
    """(f_lo, f_hi) of (1) at ``rate_hz``; None when the band is empty (a log slower than about 36 Hz)."""
    hi = HI_FRACTION * float(rate_hz)
    lo = F_LO
    return (lo, hi) if hi > 1.5 * lo else None


def band_power(g: np.ndarray, rate_hz: float, f_lo: float, f_hi: float) -> np.ndarray:
    """Mean power per axis (rad/s)^2 in [f_lo, f_hi] of the evenly sampled gyro ``g`` (n, 3) at ``rate_hz``:
    a straight line removed, a Hann window (its power gain divided out), the periodogram's bins in the
    band summed (one-sided: Parseval, the band's share of the variance)."""
    g = np.asarray(g, dtype=float)
    n = g.shape[0]
    if n < MIN_SAMPLES:
        return np.full(3, math.nan)
    x = np.arange(n) - 0.5 * (n - 1)
    g0 = g - g.mean(axis=0)
    g = g0 - np.outer(x, (x @ g0) / float(x @ x))
    w = np.hanning(n)
    spec = np.abs(np.fft.rfft(g * w[:, None], axis=0)) ** 2
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    sel = (f >= f_lo) & (f <= f_hi)
    return 2.0 * spec[sel].sum(axis=0) / (n * float(w @ w))


# ---------------------------------------------------------------------------------------------- the test
#
# Per pair (i, j) and axis, the windows' L (2) are learned over the first ``baseline_s`` of flight: their
# mean L_b, their spread s (one window's standard deviation) and count n. Then a running mean with memory
# ``memory_s`` (weights exp(-age / memory_s), normalised: it holds from the first window of a flight) is
# tested against L_b:
#
#     Z = (L_now - L_b) / sqrt(s^2 (sum w^2 / (sum w)^2 + 1 / n) + model_sigma^2)                   (3)
#
# s is the vehicle's own spread, measured: what the frame's vibration spectrum moving under the two mounts
# does to the ratio from one window to the next (real 50 Hz logs: 0.14-0.45 per 5-s window; the simulator's
# vehicles: 0.005-0.04). ``model_sigma`` is what one flight's windows cannot show: the offset of the ratio
# between flights of one healthy vehicle (real same-day flights, benchmarks/bench_pickup.py: rms difference
# of flight medians 0.10) and its slow wander. The threshold on Z (``z_on``) is set by the caller from the
# test's false-alarm rate per IMU-hour (service/inflight_alarm.py), as the in-flight noise test's.


@dataclass
class PickupConfig:
    window_s: float = 5.0
    memory_s: float = 60.0
    baseline_s: float = 240.0  # flight seconds of windows learned as the baseline
    #: between-flight offset and slow wander of a healthy vehicle's L (module notes above (3))
    model_sigma: float = 0.10
    hold_on: int = 4  # checks (windows) in a row above z_on
    hold_off: int = 6
    z_back: float = 2.0
    z_stable: float = 2.0  # with 3 IMUs the pair without the named IMU stays within this


@dataclass
class PairStats:
    """Running sums of one pair's window L per axis (baseline: plain; current: exponentially weighted)."""

    w: np.ndarray = field(default_factory=lambda: np.zeros(3))
    w2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    s1: np.ndarray = field(default_factory=lambda: np.zeros(3))
    s2: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def add(self, L: np.ndarray, decay: float = 1.0) -> None:
        ok = np.isfinite(L)
        x = np.where(ok, L, 0.0)
        self.w = self.w * decay + ok
        self.w2 = self.w2 * decay * decay + ok
        self.s1 = self.s1 * decay + x
        self.s2 = self.s2 * decay + x * x

    def mean(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.s1 / self.w


@dataclass
class PickupVerdict:
    """A change of IMU ``who``'s pick-up on ``axis``: ``ratio`` its gyro's band RMS over its twins' against
    the baseline's (the geometric mean over its pairs)."""

    who: int
    axis: str
    state: int  # 1 changed, 0 back
    ratio: float
    twins: tuple

    def imus(self) -> tuple[int, ...]:
        return (self.who,)

    def text(self) -> str:
        """STATUSTEXT (<= 50 characters), e.g. ``IMU0 gyro Z vibration pick-up 2.0x vs twins``."""
        vs = "twins" if len(self.twins) > 1 else f"IMU{self.twins[0]}"
        if self.state:
            return f"IMU{self.who} gyro {self.axis[1].upper()} vibration pick-up {self.ratio:.2g}x vs {vs}"[:50]
        return f"IMU{self.who} gyro {self.axis[1].upper()} vibration pick-up back"[:50]


AXES = ("gx", "gy", "gz")
VERSION = 1


def _oriented(zs: dict, i: int, j: int, ax: int) -> float:
    """Z of pair (i, j) seen from IMU i (L is of the lower-numbered IMU over the other)."""
    z = zs.get((min(i, j), max(i, j)), np.full(3, math.nan))[ax]
    return float(z if i < j else -z)


class PickupWatch:
    """The pick-up test of (3): :meth:`add_window` with each flight window's band powers per IMU; a baseline
    learned over ``baseline_s`` of flight windows, then per window the test and its verdicts."""

    def __init__(self, cfg: PickupConfig | None = None):
        self.cfg = cfg or PickupConfig()
        self.base: dict[tuple[int, int], dict] = {}  # {pair: {"mean", "sd", "n"}: (3,) each}
        self.learn: dict[tuple[int, int], PairStats] = {}
        self.learned_s = 0.0
        self.cur: dict[tuple[int, int], PairStats] = {}
        self.det: dict[tuple, tuple[int, int]] = {}  # (who, axis) -> (state, count); who an IMU or a pair
        self.named: dict[tuple[int, int], float] = {}  # (imu, axis index) -> ratio

    def new_flight(self) -> None:
        """A new flight (arming): the running means start afresh, the baseline stays."""
        self.cur = {}

    def drop_imu(self, imu: int) -> None:
        """IMU ``imu`` is held dead, stuck or saturated: its pairs' running means (and learning sums) start
        afresh, since they hold the windows of the fault before it was named (a frozen gyro's band power is
        0, a ratio of 1e7 that would stay in the mean for minutes)."""
        self.cur = {k: v for k, v in self.cur.items() if imu not in k}
        self.learn = {k: v for k, v in self.learn.items() if imu not in k}

    def add_window(self, powers: dict[int, np.ndarray], z_on: float) -> list[PickupVerdict]:
        """One flight window's band powers {imu: (3,)} (:func:`band_power`, one time span for all)."""
        imus = sorted(powers)
        L = {}
        for a, i in enumerate(imus):
            for j in imus[a + 1:]:
                with np.errstate(invalid="ignore", divide="ignore"):
                    L[(i, j)] = 0.5 * np.log(np.asarray(powers[i], float) / np.asarray(powers[j], float))
                L[(i, j)][~np.isfinite(L[(i, j)])] = math.nan
        if not self.base:
            for k, v in L.items():
                self.learn.setdefault(k, PairStats()).add(v)
            self.learned_s += self.cfg.window_s
            if self.learned_s >= self.cfg.baseline_s:
                self._learned()
            return []
        decay = math.exp(-self.cfg.window_s / self.cfg.memory_s)
        zs, delta = {}, {}
        for k, v in L.items():
            b = self.base.get(k)
            if b is None:
                continue
            cur = self.cur.setdefault(k, PairStats())
            cur.add(v, decay)
            with np.errstate(invalid="ignore", divide="ignore"):
                var = b["sd"] ** 2 * (cur.w2 / cur.w ** 2 + 1.0 / b["n"]) + self.cfg.model_sigma ** 2
                delta[k] = cur.mean() - b["mean"]
                zs[k] = delta[k] / np.sqrt(var)
        return self._test(imus, zs, delta, z_on)

    def _learned(self) -> None:
        """The baseline from the learning sums: per pair and axis the mean, one window's sd, the count (an
        axis with fewer than 10 windows: none)."""
        for k, st in self.learn.items():
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = st.mean()
                sd = np.sqrt(np.maximum(st.s2 / st.w - mean ** 2, 0.0) * st.w / np.maximum(st.w - 1.0, 1.0))
            ok = st.w >= 10
            self.base[k] = {"mean": np.where(ok, mean, math.nan), "sd": np.where(ok, sd, math.nan), "n": st.w.copy()}
        self.learn = {}

    def _test(self, imus: list[int], zs: dict, delta: dict, z_on: float) -> list[PickupVerdict]:
        """Per axis: three IMUs, IMU i changed when its Z against both twins passes ``z_on`` the same way and
        the twins' own pair stays within ``z_stable``; two IMUs, a changed pair names both (one of them
        changed: which one the ratio cannot tell). ``hold_on`` windows in a row to name, ``hold_off`` below
        ``z_back`` to clear."""
        c, out = self.cfg, []
        for a, ax in enumerate(AXES):
            for i in imus:
                tw = tuple(j for j in imus if j != i)
                zi = [_oriented(zs, i, j, a) for j in tw]
                if len(imus) == 3:
                    zt = abs(_oriented(zs, tw[0], tw[1], a))
                    bad = (min(zi) > z_on or max(zi) < -z_on) and zt < c.z_stable
                elif len(imus) == 2:
                    bad = abs(zi[0]) > z_on
                else:
                    continue
                good = all(abs(z) < c.z_back for z in zi)
                st, n = self.det.get((i, a), (0, 0))
                st2, n, _ = debounce(st, n, bad, c.hold_on, c.hold_off, good=good)
                self.det[(i, a)] = (st2, n)
                if st2 == st:
                    continue
                d = [_oriented(delta, i, j, a) for j in tw]
                d = [x for x in d if math.isfinite(x)]
                ratio = math.exp(sum(d) / len(d)) if d else math.nan
                if st2:
                    self.named[(i, a)] = ratio
                else:
                    self.named.pop((i, a), None)
                out.append(PickupVerdict(i, ax, int(bool(st2)), ratio, tw))
        return out

    def degrading(self, imu: int) -> bool:
        return any(i == imu for i, _ in self.named)

    def state_dict(self) -> dict:
        def enc(v):  # JSON without NaN: an axis without a baseline is null
            return [float(x) if math.isfinite(x) else None for x in v]

        return {"version": VERSION, "pairs": {f"{i}-{j}": {key: enc(v) for key, v in b.items()}
                                              for (i, j), b in self.base.items()}}

    def load_state_dict(self, d) -> None:
        """Restore :meth:`state_dict`; ValueError when it is not of this version."""
        if not isinstance(d, dict) or d.get("version") != VERSION:
            raise ValueError("pick-up state of another version")
        base = {}
        for k, b in (d.get("pairs") or {}).items():
            i, j = (int(x) for x in k.split("-"))
            base[(i, j)] = {key: np.array([math.nan if x is None else float(x) for x in b[key]],
                                                     dtype=float) for key in ("mean", "sd", "n")}
        self.base = base
