"""How close the vehicle simulator comes to real autopilot logs, before and after the realistic gyro path.

For each real log (../shared/data, plus public logs fetched for local use under /work/reallogs when present)
the same measurements are made on the log, on the old simulator (the preset's noise model, no Realism:
``VehicleSimulator(model)``) and on the new one (the preset with its Realism), both run over the log's own
schedule (still, then armed/flying as the log says), IMU count, rate and start time:

- ``ground``: gyro noise std on the ground (median over still 2-s windows; mrad/s, mean of the axes) per IMU;
- ``adev``: ADEV sqrt(tau) of the longest still run at tau = 1..64 samples (the filter's roll-off shows at
  short tau); the gap is the rms of ln(sim / log) over tau;
- ``hf``: in-flight RMS in the upper band [fs/5, fs/2] per IMU and axis (vibration; what aliases there);
- ``peak``: frequency of the strongest in-flight line in that band (Welch);
- ``ratio``: per IMU, upper-band RMS in flight / on the ground;
- ``skew``: per IMU, lag against IMU0 from the cross-spectrum phase slope in flight over the body-motion band
  0.3-4 Hz (coherence-weighted, median over the axes, longest flight run; aliased vibration lines would multiply a lag by f/f_alias), ms (positive:
  the IMU's sample at a time stamp shows the body at a later time);
- ``bias``: bias change over the longest still run (difference of its first and last 5 s means, max over
  axes, mrad/s) and the temperature change there.

The table's gap columns: |ln(sim / log)| for magnitudes (0 = equal, 0.69 = a factor 2), |sim - log| in Hz or
ms for frequencies and skews. Each simulated figure is the median over ``--seeds`` seeds.

    python -m benchmarks.bench_realism                # the table (docs/vehicle.md)
    python -m benchmarks.bench_realism --fit copter   # the preset's per-IMU noise and vibration gains, fitted

Target: no fixed threshold: the gap columns show how far the simulator is from each log (0 equal; 0.69 a factor 2), before and after the realistic path. The public logs are used where fetched ($COMPANION_REALLOGS).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy import signal


from benchmarks import results
from benchmarks.results import SHARED_DATA
from companion.sim.preset import load_preset
from companion.sim.vehicle import Flight, Schedule, VehicleSimulator

HERE = Path(__file__).resolve().parents[1]
SHARED = SHARED_DATA
REAL = Path(os.environ.get("COMPANION_REALLOGS", "/work/reallogs/erle"))

# (label, path, preset, message/instances to use, whole log is a flight)
LOGS = [
    ("log171 (copter, 3 IMU, 50 Hz)", SHARED / "ardupilot" / "dronekit_log171.bin", "copter", False),
    ("pyulog_sample (PX4, 248 Hz, flight)", SHARED / "px4" / "pyulog_sample.ulg", "px4", True),
    ("pyulog_sample_log_small (PX4, 200 Hz)", SHARED / "px4" / "pyulog_sample_log_small.ulg", "px4", False),
    ("plane_4-12-2014_329 (10 Hz)", REAL / "pxf_plane_4-12-2014_329.BIN", "plane", False),
    ("plane_5-12-2014_E (10 Hz)", REAL / "pxf_plane_5-12-2014_05_12_2014_E.BIN", "plane", False),
    ("rover_25-8-2014_61 (50 Hz)", REAL / "pxf_rover_25-8-2014_61.BIN", "rover", False),
    ("rover_mpu6000_2 (50 Hz)", REAL / "pxf_rover_2-8-2014_mpu6000-ms5611_2.BIN", "rover", False),
]


# ----------------------------------------------------------------------------------------------- loading
def load_log(path: Path):
    """(t (n,), gyro (k, n, 3), temperature (k, n) or None, rate, armed intervals [(a, b)] in log time)."""
    from companion.sources import load

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = load(str(path))
    imu = [s for s in d.streams if s.key.message in ("IMU", "sensor_combined") and s.samples > 100]
    if not imu:
        imu = [max(d.streams, key=lambda s: s.samples)]
    imu.sort(key=lambda s: s.key.instance)
    n = min(s.samples for s in imu)
    t = imu[0].t[:n]
    gyro = np.stack([s.gyro[:n] for s in imu])
    temp = None
    if all(s.temperature is not None for s in imu):
        temp = np.stack([s.temperature[:n] for s in imu])
    armed, on = [], None
    for tt, a in sorted(d.meta.get("armed") or []):
        if a and on is None:
            on = tt
        elif not a and on is not None:
            armed.append((on, tt))
            on = None
    if on is not None:
        armed.append((on, float(t[-1]) + 1.0))
    params = d.meta.get("params") or {}
    return t, gyro, temp, float(imu[0].rate_hz), armed, params


# ----------------------------------------------------------------------------------------------- measuring
def _windows(t, g, fs, w_s=2.0):
    w = max(4, int(round(w_s * fs)))
    m = g.shape[1] // w
    return w, m


TUMBLE = 1.0  # rad/s: 2-s windows with a larger std are a crash or a tumble, not flight


def segments(t, gyro, fs, armed, whole_flight):
    """Boolean masks (still, flight) of the samples: still = disarmed 2-s windows whose std (IMU0, all axes)
    is within 3x the quietest decile's; flight = armed (the log's events) and moving, or, without events,
    windows with std above 20x the quietest decile's; windows above ``TUMBLE`` are left out of both."""
    n = t.shape[0]
    w = max(4, int(round(2.0 * fs)))
    m = n // w
    sd = gyro[0, :m * w].reshape(m, w, 3).std(1).mean(1)
    q = np.percentile(sd, 10)
    still_w = sd < 3.0 * q
    arm = np.zeros(n, bool)
    for a, b in armed:
        arm |= (t >= a) & (t < b)
    if whole_flight:
        arm[:] = True
    still = np.zeros(n, bool)
    still[:m * w] = np.repeat(still_w, w)
    still &= ~arm
    if armed or whole_flight:
        flight = arm.copy()
        moving = np.zeros(n, bool)
        moving[:m * w] = np.repeat((sd > 10.0 * q) & (sd < TUMBLE), w)
        if whole_flight:
            moving[:] = True
        flight &= moving
    else:
        flight = np.zeros(n, bool)
        flight[:m * w] = np.repeat((sd > 20.0 * q) & (sd < TUMBLE), w)
    return still, flight


def _runs(mask):
    d = np.diff(np.r_[0, mask.astype(int), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _adev_sqrt_tau(y, fs, ms):
    out = []
    for m in ms:
        if y.shape[0] < 4 * m:
            out.append(np.nan)
            continue
        c = np.cumsum(np.r_[0.0, y])
        a = (c[m:] - c[:-m]) / m
        out.append(math.sqrt(0.5 * np.mean((a[m:] - a[:-m]) ** 2)) * math.sqrt(m / fs))
    return np.array(out)


MS = (1, 2, 4, 8, 16, 32, 64)


def measure(t, gyro, temp, fs, still, flight):
    k = gyro.shape[0]
    out = {"ground": np.full(k, np.nan), "adev": np.full((k, len(MS)), np.nan), "hf": np.full((k, 3), np.nan),
           "hf_ground": np.full(k, np.nan), "peak": np.full(k, np.nan), "skew": np.full(k, np.nan),
           "bias": np.full(k, np.nan), "dT": np.full(k, np.nan)}
    lo, hi = fs / 5.0, fs / 2.0
    runs = [(a, b) for a, b in _runs(still) if b - a >= 10 * fs]
    longest = max(runs, key=lambda r: r[1] - r[0]) if runs else None
    for i in range(k):
        if still.sum() > 4 * fs:  # median over 2-s windows: the noise, not the drift
            w = max(4, int(round(2.0 * fs)))
            sds = [gyro[i, a + o:a + o + w].std(0).mean() for a, b in _runs(still) for o in range(0, b - a - w + 1, w)]
            out["ground"][i] = 1e3 * float(np.median(sds)) if sds else np.nan
        if longest is not None:
            a, b = longest
            y = gyro[i, a:b]
            out["adev"][i] = np.mean([_adev_sqrt_tau(y[:, j] - y[:, j].mean(), fs, MS) for j in range(3)], axis=0)
            w5 = int(5 * fs)
            out["bias"][i] = 1e3 * np.max(np.abs(y[-w5:].mean(0) - y[:w5].mean(0)))
            if temp is not None:
                out["dT"][i] = float(temp[i, b - 1] - temp[i, a])
            nper = min(256, b - a)
            f, p = signal.welch(y, fs=fs, nperseg=nper, axis=0)
            band = (f >= lo) & (f <= hi)
            out["hf_ground"][i] = math.sqrt(np.sum(p[band].mean(1)) * (f[1] - f[0]))
        if flight.sum() > 20 * fs:
            runs_f = [(a, b) for a, b in _runs(flight) if b - a >= 256]
            ps = []
            for a, b in runs_f:
                f, p = signal.welch(gyro[i, a:b], fs=fs, nperseg=256, axis=0)
                ps.append(p * (b - a))
            if ps:
                p = np.sum(ps, 0) / sum(b - a for a, b in runs_f)
                band = (f >= lo) & (f <= hi)
                out["hf"][i] = np.sqrt(np.sum(p[band], 0) * (f[1] - f[0]))
                out["peak"][i] = f[band][np.argmax(p[band].sum(1))]
            if i > 0 and runs_f:
                # the body-motion band only: a line that aliased from f to f_a shows a lag d as f/f_a d
                nps = int(2 ** math.ceil(math.log2(10 * fs)))
                a, b = max(runs_f, key=lambda r: r[1] - r[0])  # the longest flight run (not the crash)
                if b - a >= nps:
                    f, c = signal.csd(gyro[0, a:b], gyro[i, a:b], fs=fs, nperseg=nps, axis=0)
                    _, coh = signal.coherence(gyro[0, a:b], gyro[i, a:b], fs=fs, nperseg=nps, axis=0)
                    m = (f > 0.3) & (f < 4.0)
                    lags = []
                    for j in range(3):
                        ph = np.unwrap(np.angle(c[m, j]))
                        lags.append(np.sum(coh[m, j] * f[m] * ph) / np.sum(coh[m, j] * f[m] ** 2) / (2 * np.pi))
                    out["skew"][i] = 1e3 * float(np.median(lags))  # median over axes: one vibrating axis can mislead
    out["ratio"] = out["hf"].mean(1) / out["hf_ground"]
    return out


# ----------------------------------------------------------------------------------------------- simulating
def simulate(preset, t, fs, armed, whole_flight, imus, seed, realistic, overrides=None):
    P = load_preset(preset)
    r = P["realism"]
    if overrides:
        from dataclasses import replace

        r = replace(r, **overrides)
    t0 = float(t[0])
    dur = float(t[-1] - t[0]) + 1.0 / fs
    flights = []
    if whole_flight:
        flights = [Flight(0.0, dur + 10.0, max_rate=P["vehicle"].get("max_rate", 1.5))]
    else:
        for a, b in armed:
            a, b = max(a - t0, 0.0), min(b - t0, dur + 10.0)
            if b - a >= 4.0:
                flights.append(Flight(a, b, max_rate=P["vehicle"].get("max_rate", 1.5)))
    sim = VehicleSimulator(P["model"], imus=imus, seed=seed, rate_hz=fs, t_start=t0,
                           schedule=Schedule(flights=tuple(flights)), realism=r if realistic else None)
    blk = sim.run(dur)
    return blk.t, blk.gyro, blk.temperature


def plane_rover_armed(t, gyro, fs, armed):
    """Logs without arm events (old ArduPlane/Rover): the moving stretches (2-s windows above 20x the
    quietest decile's std, gaps under 10 s bridged, at least 10 s long) stand for the armed times."""
    if armed:
        return armed
    w = max(4, int(round(2.0 * fs)))
    m = gyro.shape[1] // w
    sd = gyro[0, :m * w].reshape(m, w, 3).std(1).mean(1)
    mov = sd > 20.0 * np.percentile(sd, 10)
    out = []
    for a, b in _runs(mov):
        ta, tb = float(t[a * w]), float(t[min(b * w, t.shape[0] - 1)])
        if out and ta - out[-1][1] < 10.0:
            out[-1] = (out[-1][0], tb)
        else:
            out.append((ta, tb))
    return [(a, b) for a, b in out if b - a >= 10.0]


def overrides_for(path: Path, params: dict, fs: float):
    """What the log itself says about the autopilot: its gyro filter, PX4's averaging."""
    o = {}
    if path.suffix.lower() == ".ulg":
        o["decimation"] = "average"
        if params.get("IMU_GYRO_CUTOFF"):
            o["gyro_lpf_hz"] = float(params["IMU_GYRO_CUTOFF"])
    else:
        for k in ("INS_GYRO_FILTER", "INS_MPU6K_FILTER"):
            if params.get(k):
                o["gyro_lpf_hz"] = float(params[k])
    return o


def run_log(label, path, preset, whole, seeds):
    t, gyro, temp, fs, armed, params = load_log(path)
    armed = plane_rover_armed(t, gyro, fs, armed) if not whole else armed
    still, flight = segments(t, gyro, fs, armed, whole)
    real = measure(t, gyro, temp, fs, still, flight)
    res = {"real": real, "fs": fs, "imus": gyro.shape[0], "dur": float(t[-1] - t[0])}
    ov = overrides_for(path, params, fs)
    for name, realistic in (("old", False), ("new", True)):
        ms = []
        for s in range(seeds):
            ts, gs, Ts = simulate(preset, t, fs, armed, whole, gyro.shape[0], s, realistic, ov if realistic else None)
            n = min(ts.shape[0], t.shape[0])
            ms.append(measure(ts[:n], gs[:, :n], None if Ts is None else Ts[:, :n], fs, still[:n], flight[:n]))
        res[name] = {k: np.nanmedian(np.stack([m[k] for m in ms]), axis=0) for k in ms[0]}
    return res


# ----------------------------------------------------------------------------------------------- table
def _lr(a, b):
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.abs(np.log(np.asarray(a, float) / np.asarray(b, float)))
    return float(np.nanmean(v)) if np.any(np.isfinite(v)) else np.nan


def _f(x, fmt="{:.2f}"):
    x = np.atleast_1d(np.asarray(x, float))
    return "/".join("-" if not np.isfinite(v) else fmt.format(v) for v in x)


def rows(label, res):
    R, O, N = res["real"], res["old"], res["new"]
    out = []

    def add(what, key, fmt, gap):
        g_old, g_new = gap(O[key], R[key]), gap(N[key], R[key])
        if not (np.isfinite(g_old) or np.isfinite(g_new)) and not np.any(np.isfinite(R[key])):
            return
        out.append(f"| {label} | {what} | {_f(R[key], fmt)} | {_f(O[key], fmt)} | {_f(N[key], fmt)} | "
                   f"{_f(g_old)} -> {_f(g_new)} |")

    def ad(a, b):
        v = np.abs(np.asarray(a, float) - np.asarray(b, float))
        return float(np.nanmean(v)) if np.any(np.isfinite(v)) else np.nan

    def adev_gap(a, b):
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.log(np.asarray(a) / np.asarray(b))
        return float(np.sqrt(np.nanmean(v ** 2))) if np.any(np.isfinite(v)) else np.nan

    add("ground noise, mrad/s per IMU", "ground", "{:.2f}", _lr)
    if np.any(np.isfinite(R["adev"])):
        for name, d in (("log", R), ("old", O), ("new", N)):
            d["adev_1"] = d["adev"][:, 0] * 1e3
            d["adev_64"] = d["adev"][:, -1] * 1e3
        out.append(f"| {label} | ADEV x sqrt(tau) at tau0 / 64 tau0, mrad/s/sqrt(Hz) per IMU | "
                   f"{_f(R['adev_1'])} / {_f(R['adev_64'])} | {_f(O['adev_1'])} / {_f(O['adev_64'])} | "
                   f"{_f(N['adev_1'])} / {_f(N['adev_64'])} | {_f(adev_gap(O['adev'], R['adev']))} -> "
                   f"{_f(adev_gap(N['adev'], R['adev']))} (rms ln over tau) |")
    for d in (R, O, N):
        d["hfm"] = np.nanmean(d["hf"], axis=1) if np.any(np.isfinite(d["hf"])) else d["hf"][:, 0]
    if np.any(np.isfinite(R["hf"])):  # the gap per IMU and axis, the figures as the axes' mean
        out.append(f"| {label} | flight upper-band RMS (axes' mean), rad/s per IMU | {_f(R['hfm'], '{:.3f}')} | "
                   f"{_f(O['hfm'], '{:.3f}')} | {_f(N['hfm'], '{:.3f}')} | {_f(_lr(O['hf'], R['hf']))} -> "
                   f"{_f(_lr(N['hf'], R['hf']))} (per axis) |")
    add("flight line, Hz per IMU", "peak", "{:.1f}", ad)
    add("upper band flight / ground per IMU", "ratio", "{:.0f}", _lr)
    if res["imus"] > 1:
        add("skew vs IMU0, ms", "skew", "{:.1f}", ad)
    add("bias change over the still run, mrad/s", "bias", "{:.2f}", _lr)
    if np.any(np.isfinite(R["dT"])):
        add("temperature change over the still run, K", "dT", "{:.1f}", ad)
    if not out:
        out.append(f"| {label} | {res['dur']:.1f} s: no still run of 10 s and no flight of 20 s to measure | | | | |")
    return out


def fit(preset, seeds):
    """Per-IMU noise gains and per-IMU per-axis vibration gains of ``preset`` that match its logs."""
    logs = [x for x in LOGS if x[2] == preset and x[1].exists()]
    label, path, _, whole = logs[0]
    t, gyro, temp, fs, armed, params = load_log(path)
    armed = plane_rover_armed(t, gyro, fs, armed)
    still, flight = segments(t, gyro, fs, armed, whole)
    real = measure(t, gyro, temp, fs, still, flight)
    P = load_preset(preset)
    r = P["realism"]
    ov = overrides_for(path, params, fs)
    ng = np.array(r.imu_noise_gain, float)
    vg = np.array(r.imu_vibration_gain, float)
    k = gyro.shape[0]
    for it in range(3):
        ms = []
        for s in range(seeds):
            o = dict(ov, imu_noise_gain=tuple(ng), imu_vibration_gain=tuple(map(tuple, vg)))
            ts, gs, Ts = simulate(preset, t, fs, armed, whole, k, s, True, o)
            n = min(ts.shape[0], t.shape[0])
            ms.append(measure(ts[:n], gs[:, :n], None, fs, still[:n], flight[:n]))
        sim = {kk: np.nanmedian(np.stack([m[kk] for m in ms]), axis=0) for kk in ms[0]}
        ng[:k] *= np.where(np.isfinite(real["ground"] / sim["ground"]), real["ground"] / sim["ground"], 1.0)
        ratio = real["hf"] / sim["hf"]
        vg[:k] *= np.where(np.isfinite(ratio), ratio, 1.0)
        print(f"iteration {it}: ground real {_f(real['ground'])} sim {_f(sim['ground'])}; hf real {_f(real['hf'].ravel(), '{:.3f}')} "
              f"sim {_f(sim['hf'].ravel(), '{:.3f}')}")
    print(f"{preset} ({label}): imu_noise_gain {np.round(ng, 3).tolist()} (x the model's N; IMU0's factor goes into N), "
          f"imu_vibration_gain {np.round(vg, 3).tolist()}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--fit", metavar="PRESET")
    ap.add_argument("--only", metavar="TEXT", help="only logs whose label contains TEXT")
    a = results.parse_args(ap, {"seeds": 1}, argv)
    if a.fit:
        fit(a.fit, a.seeds)
        return 0
    print("| log | quantity | log | old simulator | new simulator (preset) | gap old -> new |")
    print("|---|---|---|---|---|---|")
    t0 = time.time()
    for label, path, preset, whole in LOGS:
        if a.only and a.only not in label:
            continue
        if not path.exists():
            print(f"| {label} | (not present: {path}) | | | | |")
            continue
        res = run_log(label, path, preset + "", whole, a.seeds)
        print("\n".join(rows(f"{label}, preset {preset}", res)), flush=True)
    print(f"\n({time.time() - t0:.0f} s; {a.seeds} seeds per simulator; gaps: |ln(sim/log)| for magnitudes, "
          "|sim - log| for Hz, ms, K; ADEV: rms of ln(sim/log) over tau = 1..64 samples)")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
