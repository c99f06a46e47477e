"""NAMED_VALUE_FLOAT reports and STATUSTEXT health transitions, scheduled in message time.

Names (MAVLink NAMED_VALUE_FLOAT ``name`` is char[10]; MAVProxy's ``graph`` only accepts [A-Z0-9_]+):

==================  ==========================================  =========================
name                value                                        unit
==================  ==========================================  =========================
``IMU{i}G{a}_N``    angle random walk N of gyro axis a (X Y Z)   deg/sqrt(h)
``IMU{i}G{a}_B``    bias instability B                           deg/h
``IMU{i}G{a}_K``    rate random walk K                           deg/h^1.5
``IMU{i}G{a}_Q``    quantisation Q (when estimated)              arcsec
``IMU{i}G{a}_R``    rate ramp R (when estimated)                 deg/h^2
``IMU{i}A{a}_N``    accel velocity random walk (optional)        m/s/sqrt(h)
``IMU{i}A{a}_B``    accel bias instability (optional)            mg
``IMU{i}A{a}_K``    accel random walk (optional)                 m/s/h^1.5
``IMU{i}G_HLTH``    0 healthy, 1 degrading, 2 learning, 3 stale  -
``IMU{i}G_FLT``     fault kind code (0 none; table below)        -
``IMU{i}G_FLM``     bitmask of all active faults (bit k: code k) -
==================  ==========================================  =========================

``IMU{i}G_FLT`` (companion.health.faults.KIND_CODE; the most severe active fault of the IMU's gyros):
0 none, 1 stuck, 2 noise, 3 bias jump, 4 bias drift, 5 spikes, 6 saturation, 7 rate drop / irregular
timing, 8 disagreement with another IMU, 9 Allan term (N, B, K) above its baseline, 10 resolution loss,
11 an axis reading exactly 0 (dead, or on int16 messages at rest: below the 1 mrad/s resolution).
``IMU{i}G_FLM`` has bit k set for every active code k (e.g. 6.0 = stuck and noise together), so faults
present at the same time are all reported while ``IMU{i}G_FLT`` keeps the most severe.

Uncertainty and bounds (:meth:`Reporter.set_online_terms`, what ``companion run`` sends): each value
``IMU{i}G{a}_{P}`` (P = Q, N, B, K, R) has a companion ``IMU{i}G{a}_{P}S`` = its 1-sigma in the same unit
(e.g. ``IMU0GX_NS``). When the data do not resolve the term, ``_{P}`` carries its one-sided 95 % upper
bound and ``_{P}S`` is sent as -1: **a negative sigma marks a bound** (sigmas are never negative). A
Gauss-Markov term (only when resolved): ``_GM`` sigma (deg/h), ``_GMS`` its 1-sigma, ``_GMT`` correlation
time (s); a sinusoid: ``_SA`` amplitude (deg/h), ``_SAS`` its 1-sigma, ``_SF`` frequency (Hz). Names of
terms no longer reported stop being sent.

Datasheet units come from :mod:`companion.units` (the only place they are defined). Cadence: every name
once per ``period_s`` of *message* time (the IMU timestamps), the M names of a period spread evenly at
offsets j * period_s / M so the link sees one small message at a time, never a burst. A jump of message
time (replay, reboot) never produces a flood: at most one period's worth is sent per call.
"""

from __future__ import annotations

import math
import re
from typing import Mapping, Protocol

import numpy as np

from companion import units

NAME_RE = re.compile(r"^[A-Z0-9_]{1,10}$")  # a NAMED_VALUE_FLOAT name: char[10], upper case as ArduPilot's
# MAV_SEVERITY values of STATUSTEXT (MAVLink common.xml)
MAV_SEVERITY_CRITICAL = 2
MAV_SEVERITY_WARNING = 4
MAV_SEVERITY_NOTICE = 5
MAV_SEVERITY_INFO = 6


class Sink(Protocol):
    def send_named_value_float(self, time_boot_ms: int, name: str, value: float) -> None: ...
    def send_statustext(self, severity: int, text: str, time_boot_ms: int | None = None) -> None: ...


def value_name(imu: int, axis: str, param: str) -> str:
    """``IMU0GX_N`` for imu 0, axis ``gx``, param ``N``; ValueError if it does not fit 10 characters."""
    kind = "G" if axis.startswith("g") else "A"
    name = f"IMU{int(imu)}{kind}{axis[1].upper()}_{param}"
    if not NAME_RE.match(name):
        raise ValueError(f"NAMED_VALUE_FLOAT name {name!r} is not <= 10 characters of [A-Z0-9_]")
    return name


def health_name(imu: int) -> str:
    name = f"IMU{int(imu)}G_HLTH"
    if not NAME_RE.match(name):
        raise ValueError(f"NAMED_VALUE_FLOAT name {name!r} is not <= 10 characters of [A-Z0-9_]")
    return name


def fault_name(imu: int) -> str:
    name = f"IMU{int(imu)}G_FLT"
    if not NAME_RE.match(name):
        raise ValueError(f"NAMED_VALUE_FLOAT name {name!r} is not <= 10 characters of [A-Z0-9_]")
    return name


def fault_mask_name(imu: int) -> str:
    name = f"IMU{int(imu)}G_FLM"
    if not NAME_RE.match(name):
        raise ValueError(f"NAMED_VALUE_FLOAT name {name!r} is not <= 10 characters of [A-Z0-9_]")
    return name


def to_report_units(param: str, axis: str, value_si: float) -> float:
    """SI -> datasheet unit of the report table above (companion.units)."""
    return units.to_datasheet(param, value_si, axis)


class Reporter:
    """Holds the latest value of every name and sends them, spread over each period of message time."""

    def __init__(self, sink: Sink, period_s: float = 1.0):
        if not (period_s > 0):
            raise ValueError("run.report_period_s must be > 0")
        self.sink = sink
        self.period_s = float(period_s)
        self.values: dict[str, float] = {}
        self._names: list[str] | None = None  # sorted(values), kept until a name comes or goes
        self._slot = 0
        self._next_t: float | None = None
        self.sent = 0
        self.texts = 0

    def set_value(self, name: str, value: float) -> None:
        """Remember a value (already in report units) under ``name``; NaN removes it from the reports."""
        if not NAME_RE.match(name):
            raise ValueError(f"NAMED_VALUE_FLOAT name {name!r} is not <= 10 characters of [A-Z0-9_]")
        if value is None or not math.isfinite(value):
            if self.values.pop(name, None) is not None:
                self._names = None
        else:
            if name not in self.values:
                self._names = None
            self.values[name] = float(value)

    def set_terms(self, imu: int, axis: str, params_si: Mapping[str, float]) -> None:
        """Set ``IMU{i}{G|A}{a}_{P}`` from SI parameter values, converting to datasheet units."""
        for p, v in params_si.items():
            self.set_value(value_name(imu, axis, p), to_report_units(p, axis, v) if v is not None else math.nan)

    #: report names of the nonlinear terms: (effect, param) -> suffix
    NL_SUFFIX = {("gauss_markov", "sigma"): "GM", ("gauss_markov", "tau_c"): "GMT",
                 ("sinusoid", "amplitude"): "SA", ("sinusoid", "freq_hz"): "SF"}

    def set_online_terms(self, imu: int, axis: str, terms) -> None:
        """Set the values, their 1-sigma (``_{P}S``; -1 for a 95 % upper bound) and the nonlinear terms of
        one axis from an online report (companion.estimators.online_report; SI) -- see the module docstring."""
        new: dict[str, float] = {}
        for t in terms or ():
            e = t.get("effect")
            std = t.get("std") or {}
            for p, v in t.items():
                if p in ("effect", "std", "ci95", "bound") or not isinstance(v, (int, float)):
                    continue
                suffix = self.NL_SUFFIX.get((e, p), p if (e, p) not in self.NL_SUFFIX and len(p) == 1 else None)
                if suffix is None:
                    continue
                try:
                    name = value_name(imu, axis, suffix)
                    new[name] = to_report_units(p, axis, v)
                    if p in std:
                        sname = value_name(imu, axis, suffix + "S")
                        new[sname] = -1.0 if t.get("bound") else to_report_units(p, axis, std[p])
                except ValueError:  # IMU index >= 10 with a long suffix: does not fit 10 characters
                    continue
        prefix = value_name(imu, axis, "N")[:-1]
        for name in [k for k in self.values if k.startswith(prefix) and k not in new]:
            self.values.pop(name, None)
            self._names = None
        for name, v in new.items():
            self.set_value(name, v)

    def set_health(self, imu: int, state: int) -> None:
        self.set_value(health_name(imu), float(state))

    def set_fault(self, imu: int, code: int, mask: int | None = None) -> None:
        """``IMU{i}G_FLT``: the fault kind code of the IMU (0: none); ``IMU{i}G_FLM``: the bitmask of every
        active fault (bit k: code k), when given."""
        self.set_value(fault_name(imu), float(code))
        if mask is not None:
            self.set_value(fault_mask_name(imu), float(mask))

    def send_now(self, name: str, value: float, t_s: float) -> None:
        """Set ``name`` and send it at once, out of the cadence (e.g. STALE when no message time advances)."""
        self.set_value(name, value)
        self.sink.send_named_value_float(int(round(t_s * 1000.0)) & 0xFFFFFFFF, name, float(value))
        self.sent += 1

    def tick(self, t_s: float) -> int:
        """Send what is due at message time ``t_s``; return the number of messages sent."""
        if self._next_t is None or t_s < self._next_t - self.period_s:  # first call, or time went back
            self._next_t = t_s
        elif t_s < self._next_t:  # nothing due (most calls: one per sample)
            return 0
        if self._names is None:
            self._names = sorted(self.values)
        names = self._names
        if not names:
            return 0
        step = self.period_s / len(names)
        if t_s - self._next_t > self.period_s:  # a jump forward: resume from now, no burst
            self._next_t = t_s - self.period_s + step
        sent = 0
        while self._next_t <= t_s and sent < len(names):
            name = names[self._slot % len(names)]
            self._slot = (self._slot + 1) % len(names)
            self.sink.send_named_value_float(int(round(self._next_t * 1000.0)) & 0xFFFFFFFF, name, self.values[name])
            self._next_t += step
            sent += 1
        self.sent += sent
        return sent

    def tick_times(self, ts) -> int:
        """:meth:`tick` at every time of ``ts`` in order, skipping the calls that would do nothing (those
        within the current period, before the next send): the same messages, vectorised."""
        ts = np.asarray(ts, dtype=float)
        n = ts.shape[0]
        i = sent = 0
        while i < n:
            if self._next_t is None:
                sent += self.tick(float(ts[i]))
                i += 1
                continue
            lo = self._next_t - self.period_s
            hi = self._next_t if self.values else math.inf
            seg = ts[i:i + 256]
            hit = np.flatnonzero((seg >= hi) | (seg < lo))
            if hit.size == 0:
                i += seg.shape[0]
                continue
            i += int(hit[0])
            sent += self.tick(float(ts[i]))
            i += 1
        return sent

    def statustext(self, text: str, severity: int = MAV_SEVERITY_WARNING, t_s: float | None = None) -> None:
        """One STATUSTEXT (cut to 50 characters, the MAVLink 1 field size); ``t_s``: the message time of what
        it reports (a replay's tlog writes it there; a live link sends it now)."""
        ms = None if t_s is None else int(round(t_s * 1000.0)) & 0xFFFFFFFF
        self.sink.send_statustext(int(severity), text[:50], time_boot_ms=ms)
        self.texts += 1
