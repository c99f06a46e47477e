"""Degradation test: is a noise coefficient now clearly larger than its healthy baseline?

For one parameter p (N, B or K) of one gyro axis, with the current forgetting-window estimate
x +- s_x and the baseline b +- s_b (one sigma each), the log-ratio and its uncertainty follow from the
delta method (first-order propagation of independent errors):

    L = ln(x / b),    sigma_L = sqrt((s_x / x)^2 + (s_b / b)^2)                          (1)

The parameter is *high* when the lower z-sigma bound of the ratio exceeds the alarm ratio:

    L - z sigma_L > ln(ratio_on)                                                            (2)

i.e. we are z-sigma confident that it rose by more than ``ratio_on``. A baseline of zero or one that is
unresolved (b < 2 s_b) is replaced by its upper bound u = b + z s_b:

    ln(x / u) - z s_x / x > ln(ratio_on)                                                    (3)
 Hysteresis: the state goes to
DEGRADING after ``hold_on`` consecutive checks satisfying (2), and back to HEALTHY only after
``hold_off`` consecutive checks with L - z sigma_L < ln(ratio_off), ratio_off < ratio_on. A decrease
(an improvement) never raises a flag. A check with a non-finite or missing figure changes nothing.

Consecutive checks of a forgetting-window estimate are strongly correlated, so ``hold_on`` guards
against single outliers (a burst of bad data), not against the statistics: the false-alarm rate is set
by z and ratio_on, measured in benchmarks/bench_health.py (figures in docs/run.md).

numpy-free on purpose: plain floats, a few per second.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from companion.health.hold import debounce

HEALTHY = 0
DEGRADING = 1
LEARNING = 2
STALE = 3
STATE_NAMES = {HEALTHY: "healthy", DEGRADING: "degrading", LEARNING: "learning", STALE: "stale"}


@dataclass
class DetectorConfig:
    """Thresholds of the test (1)-(2); defaults chosen from benchmarks/bench_health.py (docs/run.md)."""

    z: float = 3.0
    ratio_on: float = 1.3
    ratio_off: float = 1.15
    hold_on: int = 3
    hold_off: int = 6
    params: tuple[str, ...] = ("N", "B", "K")

    @classmethod
    def from_mapping(cls, cfg: Mapping | None) -> "DetectorConfig":
        cfg = dict(cfg or {})
        out = cls()
        for k, v in cfg.items():
            if not hasattr(out, k):
                raise ValueError(f"run.health: unknown key {k!r} (allowed: z, ratio_on, ratio_off, hold_on, hold_off, params)")
            setattr(out, k, tuple(v) if k == "params" else type(getattr(out, k))(v))
        if not (out.ratio_on > out.ratio_off >= 1.0):
            raise ValueError("run.health: need ratio_on > ratio_off >= 1")
        if out.z < 0 or out.hold_on < 1 or out.hold_off < 1:
            raise ValueError("run.health: need z >= 0, hold_on >= 1, hold_off >= 1")
        return out


def log_ratio_bound(x: float, s_x: float, b: float, s_b: float, z: float) -> tuple[float, float]:
    """Return (ratio x/b, lower z-sigma bound of ln(x/b)) per eq. (1)-(2); (nan, nan) if undefined.

    A baseline that is zero or unresolved (b < 2 s_b: its interval reaches zero) is replaced by its upper
    bound u = b + z s_b, and the current value's lower bound is tested against it: ratio x / u, lower
    bound ln(x / u) - z s_x / x (eq. (3)). A term that was not seen in the baseline can thus still be
    flagged when it clearly appears (e.g. K after a bias jump), never from the uncertainty of a ratio to 0.
    """
    if not (x > 0 and math.isfinite(x)):
        return math.nan, math.nan
    if not (b > 0 and math.isfinite(b)) or (math.isfinite(s_b) and b < 2.0 * s_b):
        upper = (b if math.isfinite(b) and b > 0 else 0.0) + z * s_b
        if not (math.isfinite(upper) and upper > 0 and math.isfinite(s_x)):
            return math.nan, math.nan
        return x / upper, math.log(x / upper) - z * s_x / x
    if not (math.isfinite(s_x) and math.isfinite(s_b)):
        return x / b, -math.inf  # no usable uncertainty: never conclusive
    sigma_l = math.hypot(s_x / x, s_b / b)
    return x / b, math.log(x / b) - z * sigma_l


@dataclass
class ParamDetector:
    """Hysteresis state of one (imu, axis, param)."""

    state: int = HEALTHY
    count: int = 0
    ratio: float = math.nan

    def check(self, x: float, s_x: float, b: float, s_b: float, cfg: DetectorConfig) -> bool:
        """Update with one check; return True when the state changed."""
        ratio, lower = log_ratio_bound(x, s_x, b, s_b, cfg.z)
        if math.isnan(ratio):
            return False
        self.ratio = ratio
        self.state, self.count, changed = debounce(self.state, self.count, lower > math.log(cfg.ratio_on),
                                                   cfg.hold_on, cfg.hold_off, good=lower < math.log(cfg.ratio_off))
        return changed

    def unshown(self, x: float, b: float, cfg: DetectorConfig) -> bool:
        """A raised flag whose rise the measured Allan curves do not show at this check (the value ``x`` is
        above the baseline ``b`` by less than the curves can tell): one check towards clearing, as a value
        below ``ratio_off`` would be. Nothing while healthy. Returns True when the state changed."""
        if self.state != DEGRADING or not (x > 0 and b > 0 and math.isfinite(x) and math.isfinite(b)):
            return False
        self.ratio = x / b
        self.state, self.count, changed = debounce(self.state, self.count, False, cfg.hold_on, cfg.hold_off,
                                                   good=True)
        return changed


@dataclass
class Transition:
    imu: int
    axis: str
    param: str
    state: int
    ratio: float

    def text(self) -> str:
        """STATUSTEXT line (<= 50 characters), e.g. ``IMU0 gyro X degrading: N 2.1x baseline``."""
        name = self.axis[1].upper()
        kind = "gyro" if self.axis.startswith("g") else "accel"
        word = "degrading" if self.state == DEGRADING else "back to normal"
        return f"IMU{self.imu} {kind} {name} {word}: {self.param} {self.ratio:.1f}x baseline"[:50]


@dataclass
class HealthDetector:
    """All (axis, param) detectors of one IMU; the IMU's state is DEGRADING if any parameter is."""

    imu: int
    cfg: DetectorConfig = field(default_factory=DetectorConfig)
    detectors: dict[tuple[str, str], ParamDetector] = field(default_factory=dict)

    def check(self, axis: str, current: Mapping[str, tuple[float, float]],
              baseline: Mapping[str, tuple[float, float]],
              unshown: Mapping[str, tuple[float, float]] | None = None) -> list[Transition]:
        """Compare ``{param: (value, std)}`` of one axis with its baseline; return the transitions.
        ``unshown``: values above the baseline whose rise the Allan curves do not show (not compared; a raised
        flag counts them towards clearing, :meth:`ParamDetector.unshown`)."""
        out = []
        for p in self.cfg.params:
            if p not in baseline:
                continue
            if p not in current:
                det = self.detectors.get((axis, p))
                if det is not None and unshown and p in unshown and det.unshown(unshown[p][0], baseline[p][0], self.cfg):
                    out.append(Transition(self.imu, axis, p, det.state, det.ratio))
                continue
            det = self.detectors.setdefault((axis, p), ParamDetector())
            (x, s_x), (b, s_b) = current[p], baseline[p]
            if det.check(x, s_x, b, s_b, self.cfg):
                out.append(Transition(self.imu, axis, p, det.state, det.ratio))
        return out

    @property
    def state(self) -> int:
        return DEGRADING if any(d.state == DEGRADING for d in self.detectors.values()) else HEALTHY

    def worst(self) -> tuple[str, str, float] | None:
        """(axis, param, ratio) of the largest ratio among degrading parameters, or None."""
        bad = [(d.ratio, a, p) for (a, p), d in self.detectors.items() if d.state == DEGRADING]
        if not bad:
            return None
        r, a, p = max(bad)
        return a, p, r

    def state_dict(self) -> dict:
        return {f"{a}/{p}": {"state": d.state, "count": d.count, "ratio": None if math.isnan(d.ratio) else d.ratio}
                for (a, p), d in self.detectors.items()}

    def load_state_dict(self, data: Mapping) -> None:
        self.detectors = {}
        for k, d in data.items():
            a, p = k.split("/")
            r = d.get("ratio")
            self.detectors[(a, p)] = ParamDetector(int(d["state"]), int(d["count"]), math.nan if r is None else float(r))
