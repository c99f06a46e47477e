"""A synthetic fleet: vehicles x flights telemetry logs in which chosen IMUs degrade slowly.

Every vehicle has ``imus`` gyros (ArduPilot's streams: IMU 0 as RAW_IMU, IMU 1 as SCALED_IMU2, IMU 2 as
SCALED_IMU3, int16 mrad/s; or all as float HIGHRES_IMU with ``message="HIGHRES_IMU"``), a MAVLink system
id (1, 2, ...), a 64-bit board id sent in AUTOPILOT_VERSION.uid and gyro ids sent as the INS_GYR_ID
parameters. Each IMU axis has its own white noise N (log-uniform in ``N_RANGE``), flicker bias
instability B and rate random walk K (log-uniform in ``B_RANGE``, ``K_RANGE``), synthesised by
:mod:`companion.sim.synth`. Flights are a day apart (start times in the tlog record stamps); each
flight is a still, disarmed recording of ``duration_s`` seconds at ``rate_hz`` with a warming
temperature.

``fmt="bin"`` writes ArduPilot DataFlash logs instead (``flight_<f>.bin``, 4.x layout): the IMUs as ``IMU``
instances 0-2 (float rad/s, no int16 rounding), the board's 96-bit id in the boot banner ``MSG``
(``CubeOrange 0000ABCD ...``; the truth's ``board_id`` is then those 24 hex digits), the gyro ids as
``INS_GYR*_ID`` parameters and the start time as one ``GPS`` record (week and ms of week).

``degrading`` IMUs, chosen at random, have their ``param`` (N, B or K) multiplied by
``rise ** (f / (F - 1))`` on all three gyro axes at flight f: a geometric rise to ``rise`` times the
first flight's value at the last flight. The truth (every IMU's parameters and which ones degrade) is
written to ``OUT_DIR/fleet_truth.json``; logs go to ``OUT_DIR/<vehicle>/flight_<f>.tlog`` (or ``.bin``).
"""

from __future__ import annotations

import json
import math
import os
import struct
from dataclasses import dataclass

import numpy as np

from companion.errors import CompanionError
from companion.sources import messages as M

#: per-axis parameter ranges, drawn log-uniformly: a consumer-grade MEMS gyro's spread
N_RANGE = (1.5e-4, 4.0e-4)  # rad/s/sqrt(Hz)  (0.5 - 1.4 deg/sqrt(h))
B_RANGE = (1.0e-5, 4.0e-5)  # rad/s           (2 - 8 deg/h)
K_RANGE = (2.0e-7, 1.0e-6)  # rad/s^1.5
ARDUPILOT_MESSAGES = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")  #: ArduPilot's messages of IMU 0, 1, 2
DAY = 86400.0  #: s between two flights of a vehicle
T0_UNIX = 1.75e9  #: unix time of the first flight (any fixed time: the same seed writes the same fleet)
FORMATS = ("tlog", "bin")  #: telemetry logs or ArduPilot DataFlash logs
MIN_SAMPLES = 64  #: fewest samples per flight: the shortest record the analysis fits at all
BIN_BOARD = "CubeOrange"  # the board name in a simulated DataFlash banner


def _loguniform(rng, lo_hi, size=None):
    lo, hi = lo_hi
    return np.exp(rng.uniform(math.log(lo), math.log(hi), size))


def imu_message(k: int, message: str) -> str:
    if message == "HIGHRES_IMU":
        return "HIGHRES_IMU"
    return ARDUPILOT_MESSAGES[k] if k < len(ARDUPILOT_MESSAGES) else "RAW_IMU"


def fleet_truth(vehicles: int, flights: int, imus: int = 3, degrading: int = 3, rise: float = 1.5,
                param: str = "N", seed: int = 0, fmt: str = "tlog") -> dict:
    """The fleet's parameters (no samples): vehicles, IMUs, their per-axis terms, the degrading IMUs."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}")
    if vehicles < 1 or flights < 1 or imus < 1:
        raise ValueError("vehicles, flights and imus must be >= 1")
    if not 0 <= degrading <= vehicles * imus:
        raise ValueError(f"degrading must be between 0 and vehicles x imus = {vehicles * imus}")
    if param not in ("N", "B", "K"):
        raise ValueError("param must be N, B or K")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 15]))
    pairs = [(v, k) for v in range(vehicles) for k in range(imus)]
    chosen = {pairs[i] for i in rng.choice(len(pairs), size=degrading, replace=False)} if degrading else set()
    out = {"vehicles": [], "flights": flights, "rise": rise, "param": param, "seed": seed}
    for v in range(vehicles):
        uid = int(rng.integers(1, 2**63))
        board = f"{uid:016x}" if fmt == "tlog" else f"{v + 1:08x}{uid:016x}"  # 64-bit uid / 96-bit MCU id
        veh = {"name": f"vehicle_{v:03d}", "sysid": v % 250 + 1, "board_id": board, "imus": []}
        for k in range(imus):
            axes = {a: {"N": float(_loguniform(rng, N_RANGE)), "B": float(_loguniform(rng, B_RANGE)),
                        "K": float(_loguniform(rng, K_RANGE))} for a in ("gx", "gy", "gz")}
            veh["imus"].append({"imu": k, "gyro_id": int(rng.integers(1, 2**22)), "axes": axes,
                                "degrading": (v, k) in chosen})
        out["vehicles"].append(veh)
    return out


def _meta_payloads(board_id: str, gyro_ids: list[int]):
    """(payload bytes, msgid) of AUTOPILOT_VERSION and the INS_GYR*_ID PARAM_VALUEs."""
    av = struct.pack("<QQIIIIHH8s8s8s18s", 0, int(board_id, 16), 0x04050000, 0, 0, 0, 0, 0, b"", b"", b"", b"")
    out = [(av, 148)]
    for k, gid in enumerate(gyro_ids[:3]):
        name = M.ARDUPILOT_GYRO_ID_NAMES[k]
        out.append((struct.pack("<fHH16sB", float(gid), 3, k, name.encode(), 6), 22))  # MAV_PARAM_TYPE_INT32
    return out


@dataclass
class _Clock:
    """One flight's times: boot offset and IMU sample times (s since boot), unix start, temperature (deg C)."""

    boot: float
    t: np.ndarray
    start: float
    temperature: np.ndarray


def _clock(rng, n: int, rate_hz: float, f: int, vehicle: dict) -> _Clock:
    """Flight ``f``'s clock: logging starts 20-120 s after boot, the flight a day after the previous one at an
    hour of the vehicle's own, and the IMUs warm by 3 deg C with a 300-s time constant."""
    boot = float(rng.uniform(20.0, 120.0))
    t = boot + np.arange(n) / rate_hz
    start = T0_UNIX + f * DAY + (vehicle["sysid"] % 24) * 3600.0 + float(rng.uniform(0, 3000))
    temp0 = float(rng.uniform(15.0, 35.0))
    return _Clock(boot, t, start, temp0 + 3.0 * (1.0 - np.exp(-(t - boot) / 300.0)))


def _imu_data(imu: dict, param: str, factor: float, rate_hz: float, n: int, rng):
    """(gyro (n, 3), accel (n, 3), the parameters used per axis) of one IMU at rest: N, B and K of each axis
    (the degrading parameter times ``factor``) and a constant bias; the accelerometer at 1 g with noise."""
    from companion.sim.synth import flicker, random_walk, white_noise

    gyro = np.zeros((n, 3))
    par = {}
    for j, a in enumerate(("gx", "gy", "gz")):
        p = dict(imu["axes"][a])
        if imu["degrading"]:
            p[param] *= factor
        par[a] = p
        gyro[:, j] = (white_noise(p["N"], rate_hz, n, rng) + flicker(p["B"], rate_hz, n, rng)
                      + random_walk(p["K"], rate_hz, n, rng) + rng.normal(0.0, 0.01))  # + a constant bias
    accel = rng.normal(0.0, 0.02, (n, 3))
    accel[:, 2] -= 9.80665
    return gyro, accel, par


def _write_bin(path, vehicle: dict, clock: _Clock, gyros, accels) -> None:
    """A DataFlash log: the IMUs, the gyro ids as parameters, the board id in the boot banner, a GPS fix."""
    from companion.sim.dataflash_writer import write_imu_log

    b = vehicle["board_id"]
    params = {M.ARDUPILOT_GYRO_ID_NAMES[i["imu"]]: float(i["gyro_id"]) for i in vehicle["imus"][:3]}
    banner = f"{BIN_BOARD} {b[0:8].upper()} {b[8:16].upper()} {b[16:24].upper()}"
    write_imu_log(path, clock.t, np.stack(gyros), np.stack(accels), "4.x", params=params,
                  temperature=float(clock.temperature.mean()),
                  messages=["ArduCopter V4.5.7 (companion fleet simulate)", banner],
                  gps_utc=(clock.boot, clock.start))


def _write_tlog(path, vehicle: dict, clock: _Clock, duration_s: float, rows, msgids, times) -> None:
    """A tlog of the payloads ``rows`` (ids ``msgids``, times ``times``) and a HEARTBEAT a second, in time
    order (the identity messages first), record stamps at the flight's unix time."""
    from companion.mavlink.tlog_writer import encode_frames, heartbeat_payload, pack_records

    hb_t = clock.boot + np.arange(0.0, duration_s, 1.0)
    rows.append(np.repeat(heartbeat_payload().view(np.uint8).reshape(1, -1), hb_t.size, axis=0))
    msgids.append(np.full(hb_t.size, M.HEARTBEAT.msgid))
    times.append(hb_t)
    width = max(r.shape[1] for r in rows)
    payloads = np.zeros((sum(r.shape[0] for r in rows), width), dtype=np.uint8)
    i = 0
    for r in rows:
        payloads[i:i + r.shape[0], :r.shape[1]] = r
        i += r.shape[0]
    msgid = np.concatenate(msgids).astype(np.int64)
    t_all = np.concatenate(times)
    order = np.argsort(t_all, kind="stable")
    payloads, msgid, t_all = payloads[order], msgid[order], t_all[order]
    extra = M.CRC_EXTRA_TABLE[msgid].astype(np.uint16)
    seq = (np.arange(msgid.size) & 0xFF).astype(np.uint8)
    frames, flen = encode_frames(payloads, msgid, extra, seq, vehicle["sysid"], 1, True)
    stamps = np.rint((clock.start + (t_all - clock.boot)) * 1e6).astype(np.uint64)
    with open(path, "wb") as fh:
        fh.write(pack_records(stamps, frames, flen))


def write_flight(path, vehicle: dict, f: int, flights: int, rise: float, param: str, duration_s: float,
                 rate_hz: float, message: str, seed, fmt: str = "tlog") -> dict:
    """Write one flight's log (tlog or DataFlash .bin); returns what it holds (start time, per-IMU
    parameters used)."""
    from companion.mavlink.tlog_writer import imu_payloads

    rng = np.random.default_rng(seed)
    n = int(round(duration_s * rate_hz))
    if n < 2:
        raise ValueError("a flight needs at least 2 samples")
    clock = _clock(rng, n, rate_hz, f, vehicle)
    factor = rise ** (f / (flights - 1)) if flights > 1 else 1.0
    rows, msgids, times, used = [], [], [], []
    meta = _meta_payloads(vehicle["board_id"], [i["gyro_id"] for i in vehicle["imus"]]) if fmt == "tlog" else []
    for payload, mid in meta:
        rows.append(np.frombuffer(payload, dtype=np.uint8).reshape(1, -1))  # first in the log (stable sort)
        msgids.append(np.array([mid]))
        times.append(np.array([clock.boot]))
    gyros, accels = [], []
    for imu in vehicle["imus"]:
        gyro, accel, par = _imu_data(imu, param, factor, rate_hz, n, rng)
        if fmt == "bin":
            gyros.append(gyro)
            accels.append(accel)
            used.append({"imu": imu["imu"], "message": "IMU", "axes": par})
            continue
        msg = imu_message(imu["imu"], message)
        rec = imu_payloads(msg, clock.t, gyro, accel, instance=imu["imu"], temperature=clock.temperature + imu["imu"])
        rows.append(rec.view(np.uint8).reshape(n, -1))
        msgids.append(np.full(n, M.IMU_LAYOUTS[msg].msgid))
        times.append(clock.t)
        used.append({"imu": imu["imu"], "message": msg, "axes": par})
    if fmt == "bin":
        _write_bin(path, vehicle, clock, gyros, accels)
    else:
        _write_tlog(path, vehicle, clock, duration_s, rows, msgids, times)
    return {"path": str(path), "start_time": clock.start, "imus": used}


def check_fleet_options(vehicles: int, flights: int, imus: int, degrading: int, rise: float, duration_s: float,
                        rate_hz: float, seed: int, message: str, fmt: str) -> None:
    """One :class:`CompanionError` line for a fleet that cannot be written as asked."""
    for name, value in (("vehicles", vehicles), ("flights", flights), ("imus", imus)):
        if value < 1:
            raise CompanionError(f"--{name} must be >= 1")
    if not (duration_s > 0 and math.isfinite(duration_s)) or not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise CompanionError("--duration and --rate must be positive")
    if duration_s * rate_hz < MIN_SAMPLES:
        raise CompanionError(f"--duration {duration_s:g} s at {rate_hz:g} Hz is fewer than {MIN_SAMPLES} samples "
                             "per flight")
    if not 0 <= degrading <= vehicles * imus:
        raise CompanionError(f"--degrading must be between 0 and --vehicles x --imus = {vehicles * imus}")
    if seed < 0:
        raise CompanionError("--seed must be >= 0")
    if not (rise > 0 and math.isfinite(rise)):
        raise CompanionError("--rise must be a positive ratio")
    if fmt == "bin" and message != "ardupilot":
        raise CompanionError("--message chooses the MAVLink message of tlogs; DataFlash logs hold IMU messages")
    if fmt == "bin" and imus > 3:
        raise CompanionError("--format bin writes at most 3 IMUs (ArduPilot's IMU instances 0-2)")


#: bytes a log takes per IMU sample (measured: `fleet simulate` of 1 vehicle x 1 flight, 60 s at 100 Hz, 3 IMUs:
#: RAW_IMU/SCALED_IMU2/3 tlog 824 kB, HIGHRES_IMU tlog 1.48 MB, DataFlash 901 kB), rounded up
BYTES_PER_SAMPLE = {("tlog", "ardupilot"): 47, ("tlog", "HIGHRES_IMU"): 83, ("bin", "ardupilot"): 51}
#: the most a fleet may take on disk, whatever is free: a typo (--flights 1000 for 100) must not fill a disk
MAX_FLEET_BYTES = 200e9


def fleet_bytes(vehicles: int, flights: int, imus: int, duration_s: float, rate_hz: float, message: str,
                fmt: str) -> float:
    """About how many bytes the fleet's logs take (within a few per cent)."""
    per = BYTES_PER_SAMPLE.get((fmt, message), max(BYTES_PER_SAMPLE.values()))
    return float(vehicles) * flights * imus * round(duration_s * rate_hz) * per


def check_fleet_size(out_dir, est_bytes: float) -> None:
    """Refuse, before the first log, a fleet larger than :data:`MAX_FLEET_BYTES` or than the free space where
    it goes (the nearest existing folder of ``out_dir``)."""
    import shutil

    size = f"about {est_bytes / 1e9:.3g} GB"
    if est_bytes > MAX_FLEET_BYTES:
        raise CompanionError(f"the fleet would take {size} (limit {MAX_FLEET_BYTES / 1e9:g} GB); fewer --vehicles, "
                             "--flights, --imus, or a shorter --duration / lower --rate")
    where = os.path.abspath(os.fspath(out_dir))
    while not os.path.isdir(where) and os.path.dirname(where) != where:
        where = os.path.dirname(where)
    try:
        free = shutil.disk_usage(where).free
    except OSError:
        return
    if est_bytes > free:
        raise CompanionError(f"the fleet would take {size}, {where} has {free / 1e9:.3g} GB free; fewer "
                             "--vehicles or --flights, or another OUT_DIR")


def degrading_imus(truth: dict) -> list[str]:
    """``"vehicle_000 IMU1"`` for every degrading IMU of a fleet's truth."""
    return [f"{v['name']} IMU{i['imu']}" for v in truth["vehicles"] for i in v["imus"] if i["degrading"]]


def simulate_fleet(out_dir, vehicles: int, flights: int, imus: int = 3, degrading: int = 3, rise: float = 1.5,
                   param: str = "N", duration_s: float = 600.0, rate_hz: float = 100.0, seed: int = 0,
                   message: str = "ardupilot", progress=None, fmt: str = "tlog") -> dict:
    """Write the fleet's logs and ``fleet_truth.json`` into ``out_dir``; returns the truth dict.

    ``progress``: optional callable(done, total) after each log. ``fmt``: ``tlog`` or ``bin``.
    """
    truth = fleet_truth(vehicles, flights, imus, degrading, rise, param, seed, fmt)
    truth.update(duration_s=duration_s, rate_hz=rate_hz, message=message if fmt == "tlog" else "IMU",
                 format=fmt, logs=[])
    os.makedirs(out_dir, exist_ok=True)
    total = vehicles * flights
    done = 0
    for v, veh in enumerate(truth["vehicles"]):
        vdir = os.path.join(out_dir, veh["name"])
        os.makedirs(vdir, exist_ok=True)
        for f in range(flights):
            path = os.path.join(vdir, f"flight_{f:03d}.{fmt}")
            info = write_flight(path, veh, f, flights, rise, param, duration_s, rate_hz, message,
                                np.random.SeedSequence([seed, 16, v, f]), fmt)
            truth["logs"].append({"path": os.path.relpath(path, out_dir), "vehicle": veh["name"],
                                  "flight": f, "start_time": info["start_time"]})
            done += 1
            if progress:
                progress(done, total)
    with open(os.path.join(out_dir, "fleet_truth.json"), "w") as fh:
        json.dump(truth, fh, indent=1)
    return truth
