"""Rigid-body motion of a multirotor for the vehicle simulator (numpy only): rest, flights, handling by hand.

A vehicle rests still at a small tilt between events (gravity only). A :class:`Flight` is armed on the
ground with idling motors (vibration), takes off (vertical acceleration), manoeuvres (roll, pitch and
yaw as sums of sinusoids whose rates reach about ``max_rate``), lands, idles and disarms; in the air the
specific force is the thrust along body -z (a multirotor without drag) plus vibration. A
:class:`Handling` is the disarmed vehicle picked up and turned by hand (attitude swings of up to
``max_tilt_deg`` so gravity moves between the accelerometer axes, rates about ``max_rate``, hand tremor)
and put down in another attitude (a new heading and a small tilt). Body rates are the ZYX Euler angles'
derivatives mapped to the body (``body_rates``), so rates and gravity are consistent (tests integrate
the rates and compare). Frames: NED world, FRD body; a level vehicle at rest feels (0, 0, -g).
Times in s since the simulation start. Errors raise :class:`companion.errors.CompanionError` (one line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.errors import CompanionError

G0 = 9.80665


def _err(msg: str) -> CompanionError:
    return CompanionError(msg)


def _finite(name: str, v, lo=None, hi=None, lo_open=False) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise _err(f"{name} must be a number, got {v!r}") from None
    if not math.isfinite(x):
        raise _err(f"{name} must be finite, got {v!r}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise _err(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {x:g}")
    if hi is not None and x > hi:
        raise _err(f"{name} must be <= {hi:g}, got {x:g}")
    return x


@dataclass(frozen=True)
class Flight:
    """An armed period (s since start): armed on the ground, take-off, manoeuvres, landing, disarm.

    ``max_rate`` rad/s: about the peak body rate of the manoeuvres per axis; ``gyro_vibration`` (rad/s)
    and ``accel_vibration`` (m/s^2): std of the frame's vibration in the air (30 % of it while idling on
    the ground), half in a few lines (motor/propeller harmonics as sampled), half broadband.
    """

    arm_at: float
    disarm_at: float
    max_rate: float = 1.5
    gyro_vibration: float = 0.02
    accel_vibration: float = 2.0

    def __post_init__(self):
        a = _finite("arm time", self.arm_at, lo=0.0)
        d = _finite("disarm time", self.disarm_at)
        if not d >= a + 4.0:
            raise _err(f"disarm time ({d:g} s) must be at least 4 s after the arm time ({a:g} s)")
        _finite("flight max_rate (rad/s)", self.max_rate, lo=0.0, hi=20.0)
        _finite("gyro vibration (rad/s)", self.gyro_vibration, lo=0.0)
        _finite("accel vibration (m/s^2)", self.accel_vibration, lo=0.0)

    @property
    def start(self) -> float:
        return self.arm_at

    @property
    def end(self) -> float:
        return self.disarm_at


@dataclass(frozen=True)
class Handling:
    """The disarmed vehicle picked up at ``at`` (s since start) and turned by hand for ``duration`` s:
    attitude swings of up to ``max_tilt_deg`` with body rates of about ``max_rate`` rad/s, hand tremor,
    then put down in another attitude (new heading, small tilt)."""

    at: float
    duration: float = 20.0
    max_rate: float = 1.5
    max_tilt_deg: float = 80.0

    def __post_init__(self):
        _finite("handling time", self.at, lo=0.0)
        _finite("handling duration (s)", self.duration, lo=1.0)
        _finite("handling max_rate (rad/s)", self.max_rate, lo=0.0, hi=20.0)
        _finite("handling max_tilt_deg", self.max_tilt_deg, lo=0.0, hi=180.0)

    @property
    def start(self) -> float:
        return self.at

    @property
    def end(self) -> float:
        return self.at + self.duration


@dataclass(frozen=True)
class Schedule:
    """Flights and handlings (s since start); they must not overlap (handling happens while disarmed)."""

    flights: tuple = ()
    handlings: tuple = ()

    def __post_init__(self):
        fl = tuple(sorted(self.flights, key=lambda f: f.arm_at))
        hd = tuple(sorted(self.handlings, key=lambda h: h.at))
        for f in fl:
            if not isinstance(f, Flight):
                raise _err(f"schedule flights must be Flight objects, got {f!r}")
        for h in hd:
            if not isinstance(h, Handling):
                raise _err(f"schedule handlings must be Handling objects, got {h!r}")
        object.__setattr__(self, "flights", fl)
        object.__setattr__(self, "handlings", hd)
        ev = self.events()
        for a, b in zip(ev, ev[1:]):
            if b.start < a.end:
                raise _err(f"{_name(b)} overlaps {_name(a)}: flights and handlings must not overlap "
                           "(a vehicle is handled only while disarmed)")

    def events(self) -> list:
        return sorted(list(self.flights) + list(self.handlings), key=lambda e: e.start)

    @classmethod
    def random(cls, duration_s: float, seed=0, flights_per_hour: float = 2.0, handlings_per_hour: float = 2.0,
               flight_s=(60.0, 900.0), handling_s=(5.0, 30.0), first_s: float = 120.0, rest_s: float = 60.0,
               **flight_kw) -> "Schedule":
        """Random non-overlapping flights and handlings over ``duration_s`` (benchmarks, soak tests).

        Events start after ``first_s`` and are separated by at least ``rest_s`` of rest plus an
        exponential gap (event starts at ``flights_per_hour + handlings_per_hour`` per hour of rest; each
        is a flight with probability flights/(flights + handlings)); durations are uniform in ``flight_s``
        / ``handling_s`` (the last one cut short to end by ``duration_s``);
        ``flight_kw`` go to every :class:`Flight` (max_rate, vibration).
        """
        rng = np.random.default_rng(seed)
        rate = (flights_per_hour + handlings_per_hour) / 3600.0
        flights, handlings = [], []
        t = float(first_s)
        if rate <= 0:
            return cls()
        while True:
            t += rng.exponential(1.0 / rate)
            fly = rng.random() < flights_per_hour / (flights_per_hour + handlings_per_hour)
            lo, hi = flight_s if fly else handling_s
            d = min(rng.uniform(lo, hi), duration_s - t)  # the last event is cut short to fit
            if d < lo:
                break
            if fly:
                flights.append(Flight(t, t + d, **flight_kw))
            else:
                handlings.append(Handling(t, d))
            t += d + rest_s
        return cls(tuple(flights), tuple(handlings))


def _name(e) -> str:
    if isinstance(e, Flight):
        return f"the flight {e.arm_at:g}-{e.disarm_at:g} s"
    return f"the handling {e.at:g}-{e.end:g} s"


def rotation_nb(att: np.ndarray) -> np.ndarray:
    """Body-to-NED rotation matrices (n, 3, 3) of ZYX Euler angles ``att`` (n, 3) = (roll, pitch, yaw)."""
    att = np.atleast_2d(att)
    cr, sr = np.cos(att[:, 0]), np.sin(att[:, 0])
    cp, sp = np.cos(att[:, 1]), np.sin(att[:, 1])
    cy, sy = np.cos(att[:, 2]), np.sin(att[:, 2])
    R = np.empty((att.shape[0], 3, 3))
    R[:, 0, 0] = cp * cy
    R[:, 0, 1] = sr * sp * cy - cr * sy
    R[:, 0, 2] = cr * sp * cy + sr * sy
    R[:, 1, 0] = cp * sy
    R[:, 1, 1] = sr * sp * sy + cr * cy
    R[:, 1, 2] = cr * sp * sy - sr * cy
    R[:, 2, 0] = -sp
    R[:, 2, 1] = sr * cp
    R[:, 2, 2] = cr * cp
    return R


def body_rates(att: np.ndarray, datt: np.ndarray) -> np.ndarray:
    """Body rates (p, q, r) from ZYX Euler angles and their time derivatives (both (n, 3))."""
    r, p = att[:, 0], att[:, 1]
    dr, dp, dy = datt[:, 0], datt[:, 1], datt[:, 2]
    return np.stack([dr - dy * np.sin(p),
                     dp * np.cos(r) + dy * np.cos(p) * np.sin(r),
                     -dp * np.sin(r) + dy * np.cos(p) * np.cos(r)], axis=1)


def specific_force_at_rest(att: np.ndarray, a_ned=None) -> np.ndarray:
    """Specific force in the body frame, f_b = R_bn (a_n - g_n), g_n = (0, 0, g)."""
    R = rotation_nb(att)
    a = np.zeros((R.shape[0], 3)) if a_ned is None else np.asarray(a_ned, dtype=float)
    v = a - np.array([0.0, 0.0, G0])
    return np.einsum("nji,nj->ni", R, v)  # R^T v


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def _window(t, a, b, ramp):
    """1 inside [a + ramp, b - ramp], smooth ramps to 0 at a and b."""
    if b <= a:
        return np.zeros_like(t)
    r = max(min(ramp, (b - a) / 2.0), 1e-9)
    return _smoothstep((t - a) / r) * _smoothstep((b - t) / r)


class _Event:
    """Motion of one flight or handling; times in s since start (``s``). Randomness drawn at construction."""

    H = 1e-4  # s, central-difference step for the Euler-angle derivatives (error ~1e-7 rad/s)

    def __init__(self, ev, rest0: np.ndarray, rest1: np.ndarray, rng: np.random.Generator, rate_hz: float):
        self.ev, self.rest0, self.rest1 = ev, rest0, rest1
        self.start, self.end = ev.start, ev.end
        T = self.end - self.start
        if isinstance(ev, Flight):
            self.idle = min(3.0, 0.1 * T)
            self.lift = min(5.0, 0.15 * T)
            self.air = (self.start + self.idle, self.end - self.idle)
            self.man = (self.air[0] + self.lift, self.air[1] - self.lift)
            self.man_ramp = min(3.0, max(self.man[1] - self.man[0], 0.0) / 4.0)
            self.climb = rng.uniform(1.0, 2.5)  # m/s^2 peak vertical acceleration at take-off/landing
            f_rp, f_y, k = (0.3, 1.0), (0.05, 0.3), 3
            self.osc = [self._osc(rng, f_rp, ev.max_rate, k, None), self._osc(rng, f_rp, ev.max_rate, k, None),
                        self._osc(rng, f_y, ev.max_rate, k, None)]
            self.tremor = None
            nyq = 0.5 * rate_hz
            self.vib = []
            for std in (ev.gyro_vibration, ev.accel_vibration):
                lines = [(rng.uniform(0.3, 0.9) * nyq, rng.uniform(0, 2 * np.pi, 3), rng.uniform(0.5, 1.0, 3))
                         for _ in range(2)]
                self.vib.append((std, lines))
        else:
            self.air = (self.start, self.end)
            self.man = (self.start, self.end)
            self.man_ramp = min(2.0, T / 4.0)
            tilt = math.radians(ev.max_tilt_deg) / 2.0
            f = (0.1, 0.4)
            self.osc = [self._osc(rng, f, ev.max_rate, 2, tilt), self._osc(rng, f, ev.max_rate, 2, tilt),
                        self._osc(rng, f, ev.max_rate, 2, None)]
            # hand tremor: small fast angle wobble (~0.1 rad/s) and acceleration (~0.2 m/s^2)
            self.tremor = ([(rng.uniform(2.0, 6.0), rng.uniform(0, 2 * np.pi), 0.1 / (2 * np.pi * 4.0)) for _ in range(3)],
                           [(rng.uniform(1.0, 4.0), rng.uniform(0, 2 * np.pi), 0.2) for _ in range(3)])
            self.lift_h = rng.uniform(0.3, 1.0)  # m, how high it is lifted
            self.vib = None

    @staticmethod
    def _osc(rng, fr, max_rate, k, cap):
        f = rng.uniform(*fr, k)
        rate = max_rate / k * rng.uniform(0.6, 1.0, k)
        amp = rate / (2 * np.pi * f)
        if cap is not None:
            amp = np.minimum(amp, cap / k * 2.0)
        return f, amp, rng.uniform(0, 2 * np.pi, k)

    def angles(self, s: np.ndarray) -> np.ndarray:
        a0, a1 = self.air
        base = self.rest0 + (self.rest1 - self.rest0) * _smoothstep((s - a0) / max(a1 - a0, 1e-9))[:, None]
        w = _window(s, self.man[0], self.man[1], self.man_ramp)
        out = base.copy()
        for j, (f, amp, ph) in enumerate(self.osc):
            out[:, j] += w * np.sum(amp * np.sin(2 * np.pi * f * (s[:, None] - self.start) + ph), axis=1)
        if self.tremor is not None:
            for j, (f, ph, amp) in enumerate(self.tremor[0]):
                out[:, j] += w * amp * np.sin(2 * np.pi * f * s + ph)
        return out

    def motion(self, s: np.ndarray):
        """(body rate (n, 3), specific force (n, 3), vibration envelope (n,)) at times ``s``."""
        att = self.angles(s)
        datt = (self.angles(s + self.H) - self.angles(s - self.H)) / (2 * self.H)
        w = body_rates(att, datt)
        if isinstance(self.ev, Flight):
            f = specific_force_at_rest(att)  # on the ground: gravity only
            air = (s >= self.air[0]) & (s < self.air[1])
            if air.any():
                sa = s[air]
                up = np.zeros(sa.shape)
                dur = self.lift
                m = sa < self.air[0] + dur
                up[m] = self.climb * np.sin(2 * np.pi * (sa[m] - self.air[0]) / dur)
                m = sa >= self.air[1] - dur
                up[m] = -self.climb * np.sin(2 * np.pi * (sa[m] - (self.air[1] - dur)) / dur)
                c = np.cos(att[air, 0]) * np.cos(att[air, 1])
                f[air] = 0.0
                f[air, 2] = -(G0 + up) / np.maximum(c, 0.2)  # thrust along body -z
            env = np.where((s >= self.start) & (s < self.end), 0.3, 0.0) + 0.7 * _window(s, self.air[0], self.air[1], 1.0)
        else:
            T = self.end - self.start
            u = np.clip((s - self.start) / T, 0.0, 1.0)
            a_n = np.zeros((s.shape[0], 3))
            a_n[:, 2] = -self.lift_h * (2 * np.pi / T) ** 2 / 2 * np.cos(2 * np.pi * u)  # h = H sin^2(pi u), NED down
            wt = _window(s, self.start, self.end, self.man_ramp)
            for j, (fq, ph, amp) in enumerate(self.tremor[1]):
                a_n[:, j] += wt * amp * np.sin(2 * np.pi * fq * s + ph)
            f = specific_force_at_rest(att, a_n)
            env = np.zeros(s.shape)
        return w, f, env




class BodyMotion:
    """The body's true rate and specific force over a :class:`Schedule`; random parameters drawn at construction
    from ``rng`` (rest attitudes, manoeuvres, tremor, vibration lines), so samples are a function of time."""

    def __init__(self, schedule: "Schedule", rng: np.random.Generator, rate_hz: float, rest_tilt_deg: float = 2.0):
        tilt = math.radians(_finite("rest tilt (deg)", rest_tilt_deg, lo=0.0, hi=45.0))
        rest = [np.array([rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt), rng.uniform(-np.pi, np.pi)])]
        self.events = []
        for ev in schedule.events():
            nxt = np.array([rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt), rest[-1][2] + rng.uniform(-np.pi, np.pi)])
            self.events.append(_Event(ev, rest[-1], nxt, rng, rate_hz))
            rest.append(nxt)
        self.rest = rest  # Euler angles (roll, pitch, yaw) at rest before event k and after the last one
        self.rest_f = [specific_force_at_rest(r[None, :])[0] for r in rest]
        self.ev_end = np.array([e.end for e in self.events])

    def sample(self, s: np.ndarray, rng: np.random.Generator):
        """(body rate (n, 3) rad/s, specific force (n, 3) m/s^2) at times ``s``, vibration (drawn from ``rng``) included."""
        w, f, env = self._body(s)
        return w + self._vibration(s, env, 0, rng), f + self._vibration(s, env, 1, rng)

    def sample_parts(self, s: np.ndarray, rng: np.random.Generator):
        """(body rate without vibration, specific force with vibration, vibration envelope (n,): 0 disarmed,
        0.3 armed on the ground, 1 in the air) at times ``s``: for a simulator that makes the gyro
        vibration itself (:mod:`companion.sim.realism`)."""
        w, f, env = self._body(s)
        return w, f + self._vibration(s, env, 1, rng), env

    def _body(self, s: np.ndarray):
        n = s.shape[0]
        w = np.zeros((n, 3))
        f = np.empty((n, 3))
        env = np.zeros(n)
        # rest segments: the attitude after the last event that ended
        seg = np.searchsorted(self.ev_end, s, side="right")
        for k in np.unique(seg):
            f[seg == k] = self.rest_f[int(k)]
        for e in self.events:
            m = (s >= e.start) & (s < e.end)
            if m.any():
                w[m], f[m], env[m] = e.motion(s[m])
        return w, f, env

    def _vibration(self, s, env, which, rng):
        out = np.zeros((s.shape[0], 3))
        on = env > 0
        if not on.any():
            return out
        for e in self.events:
            if e.vib is None:
                continue
            m = on & (s >= e.start) & (s < e.end)
            if not m.any():
                continue
            std, lines = e.vib[which]
            sm = s[m]
            v = rng.normal(0.0, std / math.sqrt(2.0), (sm.shape[0], 3))
            rms = np.sqrt(sum(a**2 for _, _, a in lines) / 2.0)  # per axis, of the sum of the lines
            for fq, ph, amp in lines:
                v += (std / math.sqrt(2.0)) * (amp / rms) * np.sin(2 * np.pi * fq * sm[:, None] + ph)
            out[m] = v * env[m][:, None]
        return out
