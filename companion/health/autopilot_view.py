"""The autopilot's own view of its IMUs, and the cross-check against ours. Pure numpy.

An autopilot watches its sensors too: ArduPilot logs per-IMU error counts and health flags (DataFlash ``IMU``:
``EG``/``ErrG``, ``EA``/``ErrA``, ``GH``/``GyHlt``, ``AH``/``AcHlt``), accelerometer clipping counts and vibration
levels (``VIBE``) and subsystem errors (``ERR``); PX4 logs ``vehicle_imu_status`` (error counts, clipping, vibration
metrics) and ``sensors_status_imu`` (the voter's health flags and inconsistency); both send ``SYS_STATUS`` sensor
health bits and ``VIBRATION`` on the link. The readers (:mod:`companion.sources.autopilot_health`) turn each into
one :class:`AutopilotImu` per IMU instance; this module says what it means and compares it with our report.

An IMU is *flagged by the autopilot* when any health flag says unhealthy, or an error or clip counter rises during
the log. A counter that is already above zero at the first record counted before logging began: it is shown, not
flagged (ArduPilot counts start-up errors of a sensor that then worked). Counters restart at a reboot: the rise is
the sum of the increases, a drop starting a new count from its value.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: ArduPilot ``ERR`` subsystems that concern the IMUs or the estimator fed by them (AP_Logger LogErrorSubsystem)
ERR_SUBSYSTEMS = {1: "MAIN", 12: "CRASH_CHECK", 16: "EKFCHECK", 24: "EKF_PRIMARY", 26: "FAILSAFE_SENSORS",
                  29: "FAILSAFE_VIBE"}
#: what an ``ECode`` means per subsystem (0 is "resolved" for all of them)
_ERR_CODES = {("MAIN", 1): "INS delay (the main loop waited for IMU samples)", ("EKFCHECK", 2): "bad variance",
              ("CRASH_CHECK", 1): "crash", ("CRASH_CHECK", 2): "loss of control",
              ("FAILSAFE_VIBE", 1): "vibration compensation on", ("FAILSAFE_SENSORS", 1): "sensors failsafe"}


@dataclass
class CountRise:
    """A cumulative counter the autopilot logs (errors or clipping): its first and last values and its rise."""

    field: str  # where it was read, e.g. "IMU.EG", "VIBE.Clip", "vehicle_imu_status.gyro_error_count"
    first: float
    last: float
    rise: float  # the sum of the increases (a drop is a restart: the new value counts as an increase from 0)
    first_rise_s: float | None  # message time of the first increase

    def to_dict(self) -> dict:
        return {"field": self.field, "first": self.first, "last": self.last, "rise": self.rise,
                "first_rise_s": self.first_rise_s}


@dataclass
class Unhealthy:
    """The intervals in which a health flag of the autopilot said unhealthy."""

    field: str  # e.g. "IMU.GH", "SYS_STATUS", "sensors_status_imu.gyro_healthy"
    sensor: str  # "gyro" or "accel"
    intervals: list[tuple[float, float]]  # message time (s), start of the first bad record to the next good one
    #: the boot session (1, 2, ...) of each interval: a log across reboots starts its clock again at each
    boots: list[int] = field(default_factory=list)

    def seconds(self) -> float:
        return float(sum(b - a for a, b in self.intervals))

    def text(self) -> str:
        boots = self.boots if len(self.boots) == len(self.intervals) else [1] * len(self.intervals)
        spans = ", ".join(f"{a:.1f}-{b:.1f} s" + (f" (boot {k})" if max(boots) > 1 else "")
                          for (a, b), k in zip(self.intervals[:3], boots[:3]))
        more = f" and {len(self.intervals) - 3} more" if len(self.intervals) > 3 else ""
        return f"{self.sensor} unhealthy ({self.field}) {spans}{more}"

    def to_dict(self) -> dict:
        return {"field": self.field, "sensor": self.sensor, "intervals": [list(iv) for iv in self.intervals],
                "boots": list(self.boots), "seconds": self.seconds()}


@dataclass
class AutopilotImu:
    """What the autopilot says about one IMU instance (None where the log does not carry it)."""

    instance: int
    fields: list[str] = field(default_factory=list)  # every autopilot field read for it
    gyro_errors: CountRise | None = None
    accel_errors: CountRise | None = None
    clip: CountRise | None = None  # accelerometer clipping
    gyro_clip: CountRise | None = None  # gyro clipping (PX4 vehicle_imu_status.gyro_clipping, where logged)
    unhealthy: list[Unhealthy] = field(default_factory=list)
    vibration_max: list[float] | None = None  # m/s/s, x y z (ArduPilot VIBE, VIBRATION)
    gyro_vibration_max: float | None = None  # PX4 gyro_vibration_metric, rad/s
    accel_vibration_max: float | None = None  # PX4 accel_vibration_metric, m/s/s
    gyro_inconsistency_max: float | None = None  # PX4 sensors_status_imu, rad/s against the others' mean
    temperature: list[float] | None = None  # [min, max] deg C where the health record carries it
    sysid: int | None = None  # the system on a link or tlog; None in an onboard log

    def reasons(self) -> list[str]:
        """The autopilot's reasons to distrust this IMU (empty: it saw nothing wrong)."""
        out = [u.text() for u in self.unhealthy if u.intervals]
        for what, c in (("gyro error count", self.gyro_errors), ("accel error count", self.accel_errors),
                        ("clip count", self.clip), ("gyro clip count", self.gyro_clip)):
            if c is not None and c.rise > 0:
                out.append(f"{what} rose by {c.rise:.0f} ({c.field}, first at {c.first_rise_s:.1f} s)")
        return out

    def flagged(self) -> bool:
        return bool(self.reasons())

    def to_dict(self) -> dict:
        d = {"instance": self.instance, "fields": list(self.fields), "flagged": self.flagged(),
             "reasons": self.reasons(), "unhealthy": [u.to_dict() for u in self.unhealthy]}
        for k in ("gyro_errors", "accel_errors", "clip", "gyro_clip"):
            c = getattr(self, k)
            d[k] = c.to_dict() if c is not None else None
        for k in ("vibration_max", "gyro_vibration_max", "accel_vibration_max", "gyro_inconsistency_max",
                  "temperature", "sysid"):
            d[k] = getattr(self, k)
        return d

    def summary(self) -> str:
        """One line for a table: the reasons, or what was read and found in order."""
        if self.flagged():
            return "; ".join(self.reasons())
        parts = []
        for what, c in (("gyro errors", self.gyro_errors), ("accel errors", self.accel_errors), ("clips", self.clip),
                        ("gyro clips", self.gyro_clip)):
            if c is not None:
                parts.append(f"{what} {c.last:.0f}" + (" (from the start)" if c.first > 0 else ""))
        if self.unhealthy:
            parts.append("healthy throughout (" + ", ".join(dict.fromkeys(u.field for u in self.unhealthy)) + ")")
        if self.vibration_max is not None:
            parts.append("vibration max " + "/".join(f"{v:.1f}" for v in self.vibration_max) + " m/s/s")
        if self.gyro_vibration_max is not None:
            parts.append(f"gyro vibration metric max {self.gyro_vibration_max:.3g} rad/s")
        if self.gyro_inconsistency_max is not None:
            parts.append(f"gyro inconsistency max {self.gyro_inconsistency_max:.3g} rad/s")
        return "nothing wrong: " + ", ".join(parts) if parts else "nothing read"


@dataclass
class AutopilotEvent:
    """An ``ERR`` record of a subsystem that concerns the IMUs (vehicle-wide, not per IMU)."""

    t_s: float
    subsystem: str
    code: int

    def text(self) -> str:
        what = "resolved" if self.code == 0 else _ERR_CODES.get((self.subsystem, self.code), f"code {self.code}")
        if self.subsystem == "EKF_PRIMARY":
            what = f"primary estimator lane now {self.code}"
        return f"{self.t_s:.1f} s ERR {self.subsystem}: {what}"


@dataclass
class AutopilotView:
    """Everything the autopilot said about its IMUs in one source."""

    format: str  # "dataflash", "ulog", "tlog", "live"
    imus: list[AutopilotImu] = field(default_factory=list)
    events: list[AutopilotEvent] = field(default_factory=list)
    fields: list[str] = field(default_factory=list)  # every message/field name found, for the counts
    error: str | None = None  # why the health records could not be read (a damaged log), shown as a note
    #: PX4's pre-flight gyro inconsistency (sensor_preflight, older PX4): the largest distance between gyros, rad/s
    gyro_inconsistency_max: float | None = None

    def imu(self, instance: int, sysid: int | None = None) -> AutopilotImu | None:
        return next((r for r in self.imus if r.instance == instance
                     and (sysid is None or r.sysid is None or r.sysid == sysid)), None)

    def to_dict(self) -> dict:
        return {"format": self.format, "fields": list(self.fields), "error": self.error,
                "gyro_inconsistency_max": self.gyro_inconsistency_max,
                "imus": [r.to_dict() for r in self.imus],
                "events": [{"t_s": e.t_s, "subsystem": e.subsystem, "code": e.code, "text": e.text()}
                           for e in self.events]}


def view_lines(view: AutopilotView | None) -> list[str]:
    """What ``inspect`` prints: one line per IMU the autopilot reports on, one per ERR event (at most 10)."""
    if view is None:
        return []
    out = [f"autopilot: IMU{r.instance}{f' (sys{r.sysid})' if r.sysid is not None else ''}: {r.summary()}"
           for r in view.imus]
    if view.gyro_inconsistency_max is not None:
        out.append(f"autopilot: {inconsistency_text(view.gyro_inconsistency_max)}")
    out += [f"autopilot: {line}" for line in event_lines(view.events)]
    if view.error:
        out.append(f"autopilot: health records not read: {view.error}")
    return out


def event_lines(events: list[AutopilotEvent], limit: int = 10) -> list[str]:
    """The ERR events as printed: a run of one repeated text once with its count (an autopilot logs the same
    ERR again and again; records without a time of their own all get one time), at most ``limit`` lines, then
    how many more."""
    runs: list[list] = []
    for e in events:
        text = e.text()
        if runs and runs[-1][0] == text:
            runs[-1][1] += 1
        else:
            runs.append([text, 1])
    out = [text if n == 1 else f"{text} ({n} times)" for text, n in runs[:limit]]
    if len(runs) > limit:
        out.append(f"{sum(n for _, n in runs[limit:])} more ERR events")
    return out


def inconsistency_text(x: float) -> str:
    return f"pre-flight gyro inconsistency between IMUs max {x:.3g} rad/s (sensor_preflight)"


def count_rise(t: np.ndarray, v: np.ndarray, name: str) -> CountRise | None:
    """The rise of a cumulative counter ``v`` at times ``t`` (NaN values skipped; None when none is left)."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    ok = np.isfinite(v) & np.isfinite(t)
    t, v = t[ok], v[ok]
    if v.shape[0] == 0:
        return None
    d = np.diff(v)
    inc = np.where(d > 0, d, np.where(d < 0, v[1:], 0.0))  # a drop: the counter restarted (a reboot)
    rise = float(inc.sum())
    j = np.flatnonzero(inc > 0)
    return CountRise(name, float(v[0]), float(v[-1]), rise, float(t[j[0] + 1]) if j.shape[0] else None)


def _bad_runs(healthy: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [a, b) of the runs where ``healthy`` is False."""
    bad = ~np.asarray(healthy, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def bad_intervals(t: np.ndarray, healthy: np.ndarray) -> list[tuple[float, float]]:
    """The intervals where ``healthy`` is False: from the first bad record's time to the next good record's
    (or the last record's, when it stays bad to the end)."""
    t = np.asarray(t, dtype=float)
    return [(float(t[a]), float(t[b] if b < t.shape[0] else t[-1])) for a, b in _bad_runs(healthy)]


#: a step back in time by more than this is a reboot (as sources/sessions.py counts them)
RESET_S = 1.0


def unhealthy(t: np.ndarray, healthy: np.ndarray, name: str, sensor: str) -> Unhealthy:
    """The unhealthy intervals of a health flag, each with its boot session (times restart at a reboot)."""
    t = np.asarray(t, dtype=float)
    if t.shape[0] == 0:
        return Unhealthy(name, sensor, [], [])
    boot = np.concatenate([[1], 1 + np.cumsum(np.diff(t) < -RESET_S)])
    runs = _bad_runs(healthy)
    return Unhealthy(name, sensor, bad_intervals(t, healthy), [int(boot[a]) for a, _ in runs])


def finite_max(v) -> float | None:
    """The largest finite value (None when there is none: a damaged field decodes to NaN or inf)."""
    a = np.asarray(v, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.max()) if a.shape[0] else None


def vector_max(rows: np.ndarray) -> list[float] | None:
    """Per-column maximum of finite values (None when a column has none)."""
    a = np.asarray(rows, dtype=float)
    if a.ndim != 2 or a.shape[0] == 0:
        return None
    with np.errstate(invalid="ignore"):
        m = np.nanmax(np.where(np.isfinite(a), a, np.nan), axis=0) if np.isfinite(a).any() else None
    return None if m is None or not np.all(np.isfinite(m)) else [float(x) for x in m]


@dataclass
class CrossCheck:
    """One IMU seen by both: the autopilot's reasons, our findings, and whether they agree."""

    instance: int
    autopilot: list[str]  # the autopilot's reasons (empty: it saw nothing wrong)
    autopilot_summary: str  # the line shown when it saw nothing wrong
    ours: list[str]  # our findings that name this IMU (empty: nothing found)
    has_autopilot_data: bool

    @property
    def verdict(self) -> str:
        if not self.has_autopilot_data:
            return "no autopilot health data"
        if self.autopilot:
            return "both flag it" if self.ours else "autopilot only"
        return "ours only" if self.ours else "both healthy"

    def line(self) -> str:
        ap = "; ".join(self.autopilot) if self.autopilot else self.autopilot_summary
        ours = "; ".join(self.ours) if self.ours else "nothing found"
        return f"IMU{self.instance}: autopilot: {ap} | ours: {ours} ({self.verdict})"

    def to_dict(self) -> dict:
        return {"instance": self.instance, "autopilot_flagged": bool(self.autopilot), "autopilot": self.autopilot,
                "autopilot_summary": self.autopilot_summary, "ours": self.ours, "verdict": self.verdict,
                "line": self.line()}


def cross_check(view: AutopilotView | None, ours: dict[int, list[str]],
                instances: list[int] | None = None) -> list[CrossCheck]:
    """Per IMU instance (those of ``instances``, of the autopilot's records and of ``ours``): the autopilot's
    reasons beside ours. ``ours`` maps an instance to our findings about it (sentences; empty or absent:
    nothing found). Every IMU the autopilot flags is in the result with its reasons, whatever we found."""
    keys = set(instances or []) | set(ours)
    if view is not None:
        keys |= {r.instance for r in view.imus}
    out = []
    for i in sorted(keys):
        rec = view.imu(i) if view is not None else None
        out.append(CrossCheck(i, rec.reasons() if rec else [], rec.summary() if rec else "no health data",
                              list(ours.get(i, [])), rec is not None))
    return out
