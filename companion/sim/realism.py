"""What real autopilot gyro data have beyond the noise model: the sensor's internal rate, the autopilot's
low-pass filter and decimation to the logged rate, rotor vibration that differs between IMUs and between
ground, idle and flight, per-IMU timing skew, temperature-driven bias, Gauss-Markov bias wander and the
sensor's LSB (numpy and scipy only).

How an IMU's logged gyro sample is made when :class:`Realism` is given to
:class:`companion.sim.vehicle.VehicleSimulator` (every quantity SI, per IMU i):

1. On the sensor's own clock (``sensor_rate_hz``, e.g. 1 kHz; sample k at k / fs since boot) the gyro
   sees: the slow part of the output (body rate through the IMU's mounting, biases, warm-up,
   temperature bias, the model's non-white terms; made at the logged rate and linearly interpolated),
   the model's ``white_noise`` drawn at the sensor rate (std N sqrt(fs), so its two-sided PSD stays N^2),
   times ``imu_noise_gain[i]``, and the frame's vibration times ``imu_vibration_gain[i]`` (per axis); with
   ``vibration_mounted`` the vibration also goes through the IMU's mounting (scale/misalignment), as the body
   rotation does (vibration is body rotation).
2. Rounded to the sensor LSB ``gyro_lsb`` rad/s (0: not), as the chip's int16 output would be.
3. Low-pass filtered as the autopilot does (ArduPilot INS_GYRO_FILTER, PX4 IMU_GYRO_CUTOFF): a
   Butterworth of order ``lpf_order`` at ``gyro_lpf_hz`` (bilinear, pre-warped: ArduPilot's
   LowPassFilter2p for order 2; ``imu_lpf_hz`` gives each IMU its own cut-off), run with :func:`scipy.signal.lfilter` with its state carried from block to
   block (no per-sample loop); 0 or None: no filter.
4. Decimated to the logged rate at the IMU's own sampling times ``t + skew_s[i] + jitter`` (jitter normal,
   std ``jitter_s``, clipped at 3 std): ``decimation="latest"`` takes the newest filtered sample (what
   ArduPilot logs; what the filter lets through above the log's Nyquist frequency aliases), ``"average"``
   the mean of the sensor samples since the previous logged one (PX4's integrated sensor_combined).

Vibration (body frame, shared by the IMUs, each through its own gain): lines at the rotor frequency and
its harmonics plus broadband white noise at the sensor rate. The phase is taken from the flight's
envelope: disarmed -> ``ground`` (:class:`Vibration`, usually nothing), armed on the ground -> ``idle``,
in the air -> ``flight``; between idle and flight the rotor frequency and amplitudes are interpolated
(the motors spool up). The rotor frequency wanders by ``wander`` (fraction) at 0.1-0.5 Hz.

Bias beyond the Allan model: a temperature per IMU ``T_i(t) = ambient_c + temp_offset_c[i] + rise_c[i] (1 - exp(-t /
temp_tau_s[i]))`` (t since boot) with a bias ``slope_ij (T_i - ambient_c)`` per axis (slope normal with std
``temp_slope`` rad/s/K; the drawn truth is ``VehicleSimulator.temp_slope``), and a first-order
Gauss-Markov bias (``bias_gm_sigma`` rad/s, ``bias_gm_tau_s``) per IMU axis. The temperature is logged
(``VehicleBlock.temperature``, degC) by the writers.

A preset (``copter``, ``plane``, ``rover``, ``px4``) is a YAML file in ``companion/sim/presets/`` with a noise
``model`` (:mod:`companion.sim.model` format), ``vehicle`` defaults (imus, rate_hz) and a ``realism``
section with the keys of :class:`Realism` (vibration phases as mappings of :class:`Vibration`'s keys).
:func:`load_preset` reads a name or a path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from companion.errors import CompanionError
from companion.sim import preset_names

DECIMATIONS = ("latest", "average")
PRESETS = preset_names()


def _err(msg: str) -> CompanionError:
    return CompanionError(msg)


def _num(name, v, lo=None, hi=None, lo_open=False) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise _err(f"{name} must be a number, got {v!r}") from None
    if not math.isfinite(x) or (lo is not None and (x < lo or (lo_open and x == lo))) or (hi is not None and x > hi):
        rng = f"{'>' if lo_open else '>='} {lo:g}" if lo is not None else ""
        rng += (" and " if rng else "") + (f"<= {hi:g}" if hi is not None else "")
        raise _err(f"{name} must be {rng}, got {v!r}")
    return x


@dataclass(frozen=True)
class Vibration:
    """Frame vibration of one phase: lines at ``rotor_hz`` x 1, 2, ... of amplitudes ``harmonics`` (rad/s,
    per body axis as ``axis_gain``), broadband white of std ``broadband`` rad/s at the sensor rate (per
    axis the same gain), the rotor frequency wandering by the fraction ``wander``."""

    rotor_hz: float = 0.0
    harmonics: tuple = ()
    broadband: float = 0.0
    axis_gain: tuple = (1.0, 1.0, 1.0)
    wander: float = 0.0

    def __post_init__(self):
        _num("vibration rotor_hz", self.rotor_hz, lo=0.0)
        object.__setattr__(self, "harmonics", tuple(_num("vibration harmonic amplitude (rad/s)", a, lo=0.0)
                                                    for a in self.harmonics))
        _num("vibration broadband (rad/s)", self.broadband, lo=0.0)
        g = tuple(_num("vibration axis_gain", a, lo=0.0) for a in self.axis_gain)
        if len(g) != 3:
            raise _err("vibration axis_gain needs 3 values (x, y, z)")
        object.__setattr__(self, "axis_gain", g)
        _num("vibration wander", self.wander, lo=0.0, hi=0.5)
        if self.harmonics and not self.rotor_hz > 0:
            raise _err("vibration harmonics need rotor_hz > 0")

    @classmethod
    def from_dict(cls, d, where="vibration") -> "Vibration":
        if d is None:
            return cls()
        if isinstance(d, Vibration):
            return d
        if not isinstance(d, dict):
            raise _err(f"{where} must be a mapping of rotor_hz, harmonics, broadband, axis_gain, wander")
        unknown = sorted(set(d) - {f.name for f in fields(cls)})
        if unknown:
            raise _err(f"{where}: unknown key {unknown[0]!r} (expected rotor_hz, harmonics, broadband, axis_gain, wander)")
        try:
            return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})
        except CompanionError as exc:
            raise _err(f"{where}: {exc}") from None


def _triple(name, v, n=3):
    v = tuple(v) if isinstance(v, (list, tuple)) else (v,) * n
    return tuple(_num(name, x, lo=0.0) for x in v)


@dataclass(frozen=True)
class Realism:
    """Options of the realistic gyro path (module docstring); defaults: a 1 kHz sensor, a 20 Hz 2nd-order
    low-pass, newest-sample decimation, no vibration, skew, temperature or extra bias."""

    sensor_rate_hz: float = 1000.0
    gyro_lpf_hz: float | None = 20.0
    lpf_order: int = 2
    decimation: str = "latest"
    gyro_lsb: float = 0.0
    imu_noise_gain: tuple = (1.0, 1.0, 1.0)
    imu_vibration_gain: tuple = ((1.0, 1.0, 1.0), (1.0, 1.0, 1.0), (1.0, 1.0, 1.0))
    ground: Vibration = field(default_factory=Vibration)
    idle: Vibration = field(default_factory=Vibration)
    flight: Vibration = field(default_factory=Vibration)
    skew_s: tuple = (0.0, 0.0, 0.0)
    jitter_s: float = 0.0
    stamp: str = "common"
    ambient_c: float = 25.0
    rise_c: tuple = (0.0, 0.0, 0.0)
    temp_tau_s: tuple = (300.0, 300.0, 300.0)
    temp_offset_c: tuple = (0.0, 0.0, 0.0)
    temp_slope: float = 0.0
    bias_gm_sigma: float = 0.0
    bias_gm_tau_s: float = 100.0
    imu_lpf_hz: tuple | None = None
    vibration_mounted: bool = False

    def __post_init__(self):
        fs = _num("sensor_rate_hz", self.sensor_rate_hz, lo=1.0, hi=32000.0)
        lp = self.gyro_lpf_hz
        if lp is not None and lp != 0:
            _num("gyro_lpf_hz", lp, lo=0.0, hi=0.45 * fs, lo_open=True)
        if self.imu_lpf_hz is not None:
            if not isinstance(self.imu_lpf_hz, (list, tuple)) or len(self.imu_lpf_hz) != 3:
                raise _err("imu_lpf_hz needs 3 cut-offs (one per IMU)")
            object.__setattr__(self, "imu_lpf_hz", tuple(_num("imu_lpf_hz", x, lo=0.0, hi=0.45 * fs, lo_open=True)
                                                         for x in self.imu_lpf_hz))
        if not isinstance(self.vibration_mounted, bool):
            raise _err("vibration_mounted must be true or false")
        if self.lpf_order not in (1, 2, 3, 4):
            raise _err(f"lpf_order must be 1-4, got {self.lpf_order!r}")
        if self.decimation not in DECIMATIONS:
            raise _err(f"decimation must be one of {', '.join(DECIMATIONS)}, got {self.decimation!r}")
        if self.stamp not in ("common", "own"):
            raise _err(f"stamp must be common (one time for every IMU) or own, got {self.stamp!r}")
        _num("gyro_lsb (rad/s)", self.gyro_lsb, lo=0.0)
        object.__setattr__(self, "imu_noise_gain", _triple("imu_noise_gain", self.imu_noise_gain))
        vg = self.imu_vibration_gain
        if not isinstance(vg, (list, tuple)) or len(vg) != 3:
            raise _err("imu_vibration_gain needs one entry (a number or 3 per-axis numbers) per IMU, 3 in all")
        object.__setattr__(self, "imu_vibration_gain", tuple(_triple("imu_vibration_gain", g) for g in vg))
        for ph in ("ground", "idle", "flight"):
            object.__setattr__(self, ph, Vibration.from_dict(getattr(self, ph), ph))
        sk = self.skew_s if isinstance(self.skew_s, (list, tuple)) else (self.skew_s,) * 3
        if len(sk) != 3:
            raise _err("skew_s needs 3 values (one per IMU)")
        object.__setattr__(self, "skew_s", tuple(_num("skew_s", x, lo=-0.5, hi=0.5) for x in sk))
        _num("jitter_s", self.jitter_s, lo=0.0, hi=0.1)
        _num("ambient_c", self.ambient_c, lo=-60.0, hi=120.0)
        rc = self.rise_c if isinstance(self.rise_c, (list, tuple)) else (self.rise_c,) * 3
        if len(rc) != 3:
            raise _err("rise_c needs 3 values (one per IMU) or one for all")
        object.__setattr__(self, "rise_c", tuple(_num("rise_c", x, lo=-50.0, hi=100.0) for x in rc))
        tt = self.temp_tau_s if isinstance(self.temp_tau_s, (list, tuple)) else (self.temp_tau_s,) * 3
        if len(tt) != 3:
            raise _err("temp_tau_s needs 3 values (one per IMU) or one for all")
        object.__setattr__(self, "temp_tau_s", tuple(_num("temp_tau_s", x, lo=0.0, lo_open=True) for x in tt))
        to = self.temp_offset_c if isinstance(self.temp_offset_c, (list, tuple)) else (self.temp_offset_c,) * 3
        object.__setattr__(self, "temp_offset_c", tuple(_num("temp_offset_c", x) for x in to))
        _num("temp_slope (rad/s/K)", self.temp_slope, lo=0.0)
        _num("bias_gm_sigma (rad/s)", self.bias_gm_sigma, lo=0.0)
        _num("bias_gm_tau_s", self.bias_gm_tau_s, lo=0.0, lo_open=True)

    @classmethod
    def from_dict(cls, d) -> "Realism":
        if d is None:
            return cls()
        if not isinstance(d, dict):
            raise _err("realism must be a mapping of Realism's keys")
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise _err(f"realism: unknown key {unknown[0]!r}")
        return cls(**{k: (tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list) else v)
                      for k, v in d.items()})

    # ------------------------------------------------------------------ the filter
    def filter_ba(self, imu: int | None = None):
        """(b, a) of the gyro low-pass at the sensor rate (IMU ``imu``'s own where ``imu_lpf_hz`` gives one),
        or None without a filter."""
        fc = self.imu_lpf_hz[imu] if (imu is not None and self.imu_lpf_hz) else self.gyro_lpf_hz
        if not fc:
            return None
        from scipy import signal  # here, not at the top: a simulator without a filter starts 1-2 s sooner

        return signal.butter(self.lpf_order, fc, fs=self.sensor_rate_hz)


# ---------------------------------------------------------------------------------------------- sensor stage
class SensorStage:
    """The sensor-rate path of all IMUs (filter state, rotor phase and the sensor clock carried across calls).

    ``run(t, slow, white_std, phase_env, rng_vib, rngs)`` makes the logged samples of a block: ``t`` (n,)
    nominal log times since boot, ``slow`` (imus, n, 3) the slow part at those times, ``white_std``
    (imus, 3) per-sample std of the white noise at the sensor rate, ``phase_env`` (n,) the flight envelope
    (0 disarmed, 0.3 armed on the ground, 1 in the air). Returns (gyro (imus, n, 3), sample times (imus,
    n)), and, for ``white_of`` = (imu, axis), that axis' filtered white noise alone (for a noise fault;
    ``(imu, axis, True)``: with the IMU's vibration pick-up, for a flight_noise fault)."""

    CHUNK = 1 << 18  # sensor samples per internal chunk (memory bound at any sensor rate)

    def __init__(self, realism: Realism, imus: int, t_first: float, rng_timing: np.random.Generator):
        self.r, self.imus = realism, imus
        self.fs = realism.sensor_rate_hz
        self.ba = realism.filter_ba()
        self.ba_imu = [realism.filter_ba(i) for i in range(imus)]
        self.mounts = None  # per-IMU 3x3 gyro mounting, applied to the vibration when realism.vibration_mounted
        self.zi = None  # (imus, 3, order) lfilter state
        self.zi_white = None
        margin = max(abs(x) for x in realism.skew_s) + 3 * realism.jitter_s + 2.0 / self.fs
        self.k_next = int(math.floor((t_first - margin) * self.fs))  # next sensor sample index to make
        self.rotor_phase = 0.0  # rad, of the fundamental at the last sensor sample made
        self.wander_phase = float(rng_timing.uniform(0, 2 * np.pi))
        self.rng_t = rng_timing
        self.acc = None  # average decimation: {imu: (sum, count)} of the sensor samples since the last pick

    def sample_times(self, t: np.ndarray) -> np.ndarray:
        r = self.r
        out = np.empty((self.imus, t.shape[0]))
        for i in range(self.imus):
            jit = np.clip(self.rng_t.normal(0.0, r.jitter_s, t.shape[0]), -3 * r.jitter_s, 3 * r.jitter_s) if r.jitter_s else 0.0
            out[i] = t + r.skew_s[i] + jit
        return out

    def _vibration(self, ts: np.ndarray, env: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Body-frame vibration (m, 3) at sensor times ``ts`` with the envelope ``env`` (m,)."""
        r = self.r
        m = ts.shape[0]
        out = np.zeros((m, 3))
        armed = env > 0.0
        a = np.clip((env - 0.3) / 0.7, 0.0, 1.0)  # 0 idling on the ground, 1 in the air
        g, i_, f_ = r.ground, r.idle, r.flight
        # rotor frequency and line amplitudes follow the envelope (spool-up between idle and flight)
        f_rot = np.where(armed, i_.rotor_hz + (f_.rotor_hz - i_.rotor_hz) * a, g.rotor_hz)
        wander = np.where(armed, i_.wander + (f_.wander - i_.wander) * a, g.wander)
        if np.any(f_rot > 0):
            wt = self.wander_phase + 2 * np.pi * 0.23 * ts
            f_inst = f_rot * (1.0 + wander * (0.7 * np.sin(wt) + 0.3 * np.sin(2.3 * wt + 1.0)))
            ph = self.rotor_phase + 2 * np.pi * np.cumsum(f_inst) / self.fs
            self.rotor_phase = float(ph[-1]) % (2 * np.pi)
            nh = max(len(g.harmonics), len(i_.harmonics), len(f_.harmonics))
            for h in range(nh):
                def amp(v):
                    return v.harmonics[h] if h < len(v.harmonics) else 0.0
                A = np.where(armed, amp(i_) + (amp(f_) - amp(i_)) * a, amp(g))
                if not np.any(A > 0):
                    continue
                gain = np.where(armed[:, None], np.array(i_.axis_gain) + (np.array(f_.axis_gain) - np.array(i_.axis_gain)) * a[:, None],
                                np.array(g.axis_gain))
                for j in range(3):
                    out[:, j] += A * gain[:, j] * np.sin((h + 1) * ph + 1.7 * j + 0.9 * h)
        bb = np.where(armed, i_.broadband + (f_.broadband - i_.broadband) * a, g.broadband)
        if np.any(bb > 0):
            gain = np.where(armed[:, None], np.array(i_.axis_gain) + (np.array(f_.axis_gain) - np.array(i_.axis_gain)) * a[:, None],
                            np.array(g.axis_gain))
            out += rng.standard_normal((m, 3)) * (bb[:, None] * gain)
        return out

    def run(self, t, slow, white_std, env, rng_vib, rngs, white_of=None):
        r, fs, imus = self.r, self.fs, self.imus
        n = t.shape[0]
        ts_imu = self.sample_times(t)  # (imus, n) when each IMU samples
        k_pick = np.floor(ts_imu * fs + 1e-9).astype(np.int64)  # newest sensor sample at that time
        k_end = int(k_pick.max()) + 1
        k0 = self.k_next
        k_pick = np.maximum(k_pick, k0)
        out = np.empty((imus, n, 3))
        wout = np.empty(n) if white_of is not None else None
        for c0 in range(k0, k_end, self.CHUNK):
            c1 = min(c0 + self.CHUNK, k_end)
            ts = np.arange(c0, c1) / fs
            e = np.interp(ts, t, env)
            vib = self._vibration(ts, e, rng_vib)
            sel = [(k_pick[i] >= c0) & (k_pick[i] < c1) for i in range(imus)]
            for i in range(imus):
                x = np.empty((c1 - c0, 3))
                wg = r.imu_vibration_gain[i]
                for j in range(3):
                    x[:, j] = np.interp(ts, t, slow[i, :, j])
                w = rngs[i].standard_normal((c1 - c0, 3)) * (white_std[i] * r.imu_noise_gain[i])
                vi = vib * np.asarray(wg)
                if r.vibration_mounted and self.mounts is not None:  # vibration is body rotation: same mounting
                    vi = vi @ self.mounts[i].T
                x += w + vi
                if r.gyro_lsb > 0:
                    x = np.round(x / r.gyro_lsb) * r.gyro_lsb
                y = self._filter(x, i, white=False)
                if white_of is not None and white_of[0] == i:
                    ax = white_of[1]
                    own = w[:, [ax]] + (vi[:, [ax]] if len(white_of) > 2 and white_of[2] else 0.0)
                    yw = self._filter(own, 0, white=True, imu=i)[:, 0]
                if sel[i].any():
                    kk = k_pick[i][sel[i]] - c0
                    if r.decimation == "latest":
                        out[i, sel[i]] = y[kk]
                        if white_of is not None and white_of[0] == i:
                            wout[sel[i]] = yw[kk]
                    else:
                        out[i, sel[i]] = self._average(i, y, kk, c0)
                        if white_of is not None and white_of[0] == i:
                            wout[sel[i]] = self._average(("w", i), yw[:, None], kk, c0)[:, 0]
                # tail: running sum of the samples after the last pick (average decimation)
                if r.decimation == "average":
                    self._carry(i, y, k_pick[i], c0, c1)
                    if white_of is not None and white_of[0] == i:
                        self._carry(("w", i), yw[:, None], k_pick[i], c0, c1)
        self.k_next = k_end
        return out, ts_imu, wout

    # average decimation: sum of the sensor samples since the previous pick (state across chunks)
    def _average(self, key, y, kk, c0):
        if self.acc is None:
            self.acc = {}
        cs = np.vstack([np.zeros((1, y.shape[1])), np.cumsum(y, axis=0)])
        prev_sum, prev_cnt = self.acc.get(key, (np.zeros(y.shape[1]), 0))
        ends = kk + 1
        starts = np.r_[0, ends[:-1]]
        s = cs[ends] - cs[starts]
        cnt = (ends - starts).astype(float)
        s[0] += prev_sum
        cnt[0] += prev_cnt
        return s / np.maximum(cnt, 1.0)[:, None]

    def _carry(self, key, y, k_pick, c0, c1):
        if self.acc is None:
            self.acc = {}
        inside = k_pick[(k_pick >= c0) & (k_pick < c1)]
        if inside.size:
            start = int(inside.max()) + 1 - c0
            self.acc[key] = (y[start:].sum(axis=0), y.shape[0] - start)
        else:
            ps, pc = self.acc.get(key, (np.zeros(y.shape[1]), 0))
            self.acc[key] = (ps + y.sum(axis=0), pc + y.shape[0])

    def _filter(self, x, i, white, imu=None):
        ba = self.ba_imu[i if imu is None else imu]
        if ba is None:
            return x
        from scipy import signal

        b, a = ba
        store = "zi_white" if white else "zi"
        zi_all = getattr(self, store)
        if zi_all is None:
            zi_all = {}
            setattr(self, store, zi_all)
        zi = zi_all.get(i)
        if zi is None:  # steady state for the first value (no start-up transient)
            zi = signal.lfilter_zi(b, a)[:, None] * (0.0 if white else x[0][None, :])
        y, zf = signal.lfilter(b, a, x, axis=0, zi=zi)
        zi_all[i] = zf
        return y


# ---------------------------------------------------------------------------------------------- analytic truth
def filtered_white_avar(N: float, realism: Realism, log_rate_hz: float, taus: np.ndarray) -> np.ndarray:
    """AVAR of white rate noise (two-sided PSD N^2) drawn at the sensor rate, through the gyro filter (the
    digital Butterworth of :meth:`Realism.filter_ba`) and decimated (newest sample) to ``log_rate_hz``: the
    analytic truth of the realistic path (:func:`companion.allan.filtered_white.avar_filtered_white`)."""
    from companion.allan.filtered_white import avar_filtered_white

    return avar_filtered_white(taus, N, realism.gyro_lpf_hz or None, float(log_rate_hz), realism.lpf_order,
                               sensor_hz=realism.sensor_rate_hz)


def psd_line_amplitude(y: np.ndarray, fs: float, f0: float, width_hz: float = 1.0) -> float:
    """Amplitude (rad/s) of a sinusoid near ``f0`` from a Hann-windowed periodogram: the power in
    ``f0 +- width_hz`` above the local floor, as sqrt(2 P)."""
    y = np.asarray(y, float) - np.mean(y)
    n = y.shape[0]
    w = np.hanning(n)
    Y = np.fft.rfft(y * w)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    p = 2.0 * np.abs(Y) ** 2 / (fs * np.sum(w ** 2))  # one-sided PSD
    p[0] /= 2.0
    df = fs / n
    band = np.abs(f - f0) <= width_hz
    side = (np.abs(f - f0) > 3 * width_hz) & (np.abs(f - f0) <= 8 * width_hz)
    floor = np.median(p[side]) if side.any() else 0.0
    power = float(np.sum(p[band] - floor) * df)
    return math.sqrt(max(2.0 * power, 0.0))


__all__ = ["Realism", "Vibration", "SensorStage", "DECIMATIONS", "PRESETS", "filtered_white_avar",
           "psd_line_amplitude"]
