"""The autopilot's own IMU health from a DataFlash log, a ULog, a tlog or live messages, as one
:class:`companion.health.autopilot_view.AutopilotView` (what it means: that module; docs/health.md).

- DataFlash: ``IMU`` (4.x, instance ``I``) or ``IMU``/``IMU2``/``IMU3`` (older): error counts ``EG``/``ErrG``,
  ``EA``/``ErrA``, health ``GH``/``GyHlt``, ``AH``/``AcHlt``, temperature ``T``/``Temp``, as the FMT records of
  the log define them; ``VIBE`` (one record with ``Clip0``-``Clip2`` for every IMU and the primary's
  ``VibeX``-``Z``, or per IMU with ``IMU`` and ``Clip``); ``ERR`` of the subsystems of
  :data:`~companion.health.autopilot_view.ERR_SUBSYSTEMS`.
- ULog: ``vehicle_imu_status`` per instance (error counts, ``accel_clipping[3]``, ``gyro_clipping[3]`` where
  logged, vibration metrics, temperatures); ``sensors_status_imu`` (the voter's ``gyro_healthy[k]``,
  ``gyro_inconsistency_rad_s[k]``, accel likewise) matched to the instance by device id; older PX4's
  ``sensor_preflight`` (one gyro inconsistency for all IMUs, vehicle-wide).
- MAVLink (tlog, live): ``SYS_STATUS`` bits ``3D_GYRO``/``3D_ACCEL`` and ``3D_GYRO2``/``3D_ACCEL2`` (present,
  enabled and not healthy = unhealthy; ArduPilot sets the first pair for all its IMUs together, so there it
  applies to every IMU of the system) and ``VIBRATION`` (``clipping_0``-``2`` per accelerometer, the primary's
  ``vibration_x``-``z``).
"""

from __future__ import annotations

import numpy as np

from companion.health.autopilot_view import (ERR_SUBSYSTEMS, AutopilotEvent, AutopilotImu, AutopilotView, count_rise,
                                              finite_max, unhealthy, vector_max)

#: (record attribute, the DataFlash columns that carry it, newest name first)
_DF_COUNTS = (("gyro_errors", ("EG", "ErrG")), ("accel_errors", ("EA", "ErrA")))
_DF_HEALTH = (("gyro", ("GH", "GyHlt")), ("accel", ("AH", "AcHlt")))
_DF_IMU_MESSAGES = (("IMU", 0), ("IMU2", 1), ("IMU3", 2))
_MIN_RECORDS = 10  # an instance with fewer records beside a real IMU's thousands is damaged records (dataflash_imu)
MAX_INSTANCE = 9

SYS_STATUS_ID, VIBRATION_ID, HEARTBEAT_ID = 1, 241, 0
SENSOR_GYRO, SENSOR_ACCEL, SENSOR_GYRO2, SENSOR_ACCEL2 = 1, 2, 1 << 17, 1 << 18  #: MAV_SYS_STATUS_SENSOR bits
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
_SYS_STATUS_DT = np.dtype([("present", "<u4"), ("enabled", "<u4"), ("health", "<u4")])
_VIBRATION_DT = np.dtype([("time_usec", "<u8"), ("vx", "<f4"), ("vy", "<f4"), ("vz", "<f4"),
                          ("c0", "<u4"), ("c1", "<u4"), ("c2", "<u4")])


def _imu(view: AutopilotView, instance: int, sysid: int | None = None) -> AutopilotImu:
    rec = view.imu(instance, sysid)
    if rec is None:
        rec = AutopilotImu(instance, sysid=sysid)
        view.imus.append(rec)
        view.imus.sort(key=lambda r: (r.sysid or 0, r.instance))
    return rec


def _col(cols: list[str], names) -> str | None:
    return next((c for c in names if c in cols), None)


def safe_view(fmt: str, read, *args) -> AutopilotView:
    """``read(*args)``, or an empty view naming the problem: a damaged health record (a layout that decodes to
    nonsense) must not stop the IMU analysis, and is said, never hidden."""
    try:
        return read(*args)
    except Exception as exc:  # noqa: BLE001 - any failure of these optional records becomes a note
        return AutopilotView(fmt, error=f"{type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}")


# ---------------------------------------------------------------------------------------------------- DataFlash

def from_dataflash(log) -> AutopilotView:
    """The autopilot's view from an indexed DataFlash log (:class:`companion.sources.dataflash.DataFlashLog`)."""
    view = AutopilotView("dataflash")
    for name, default in _DF_IMU_MESSAGES:
        if log.has(name) and ({"TimeUS", "TimeMS"} & set(log.columns(name))):
            _df_imu(log, view, name, default)
    if log.has("VIBE"):
        _df_vibe(log, view)
    if log.has("ERR", "Subsys", "ECode"):
        rec = log.records("ERR")
        t = log.time_s("ERR", rec)
        sub = log.values("ERR", "Subsys", rec)
        code = log.values("ERR", "ECode", rec)
        view.fields.append("ERR")
        for ti, s, c in zip(t, sub, code):
            if np.isfinite(s) and int(s) in ERR_SUBSYSTEMS and np.isfinite(c):
                view.events.append(AutopilotEvent(float(ti), ERR_SUBSYSTEMS[int(s)], int(c)))
    return view


def _df_imu(log, view: AutopilotView, name: str, default: int) -> None:
    cols = log.columns(name)
    wanted = [c for _, names in _DF_COUNTS + _DF_HEALTH for c in names if c in cols]
    if not wanted:
        return
    rec = log.records(name)
    t = log.time_s(name, rec)
    inst = log.values(name, "I", rec) if "I" in cols else np.full(t.shape[0], float(default))
    ids, counts = np.unique(inst[np.isfinite(inst)], return_counts=True)
    most = int(counts.max()) if counts.shape[0] else 0
    for k, n in zip(ids.tolist(), counts.tolist()):
        if not (0 <= k <= MAX_INSTANCE and k == int(k)) or (n < _MIN_RECORDS and most >= 100 * n):
            continue  # damaged records, as the IMU reader skips them
        sel = inst == k
        r = _imu(view, int(k))
        for attr, names in _DF_COUNTS:
            c = _col(cols, names)
            if c:
                setattr(r, attr, count_rise(t[sel], log.values(name, c, rec)[sel], f"{name}.{c}"))
                r.fields.append(f"{name}.{c}")
        for sensor, names in _DF_HEALTH:
            c = _col(cols, names)
            if c:
                v = log.values(name, c, rec)[sel]
                ok = np.isfinite(v)
                r.unhealthy.append(unhealthy(t[sel][ok], v[ok] != 0, f"{name}.{c}", sensor))
                r.fields.append(f"{name}.{c}")
        tc = _col(cols, ("T", "Temp"))
        if tc:
            temp = log.values(name, tc, rec)[sel]
            temp = temp[np.isfinite(temp)]
            r.temperature = [float(temp.min()), float(temp.max())] if temp.shape[0] else None
    view.fields.append(name)


def _df_vibe(log, view: AutopilotView) -> None:
    cols = log.columns("VIBE")
    rec = log.records("VIBE")
    t = log.time_s("VIBE", rec)
    vib = [c for c in ("VibeX", "VibeY", "VibeZ") if c in cols]
    vals = np.column_stack([log.values("VIBE", c, rec) for c in vib]) if len(vib) == 3 else None
    view.fields.append("VIBE")
    if "IMU" in cols and "Clip" in cols:  # one record per IMU instance
        inst = log.values("VIBE", "IMU", rec)
        clip = log.values("VIBE", "Clip", rec)
        for k in np.unique(inst[np.isfinite(inst)]).tolist():
            if not 0 <= k <= MAX_INSTANCE:
                continue
            sel = inst == k
            r = _imu(view, int(k))
            r.clip = count_rise(t[sel], clip[sel], "VIBE.Clip")
            r.fields.append("VIBE.Clip")
            if vals is not None:
                r.vibration_max = vector_max(vals[sel])
                r.fields.append("VIBE.Vibe")
        return
    for k in range(3):  # older: one record, Clip0-2 per IMU, the vibration of the primary IMU
        c = f"Clip{k}"
        if c not in cols:
            continue
        v = log.values("VIBE", c, rec)
        if k > 0 and view.imu(k) is None and not np.any(v):
            continue  # an IMU the vehicle does not have: its count stays 0
        r = _imu(view, k)
        r.clip = count_rise(t, v, f"VIBE.{c}")
        r.fields.append(f"VIBE.{c}")
        if k == 0 and vals is not None:
            r.vibration_max = vector_max(vals)
            r.fields.append("VIBE.Vibe")


# ---------------------------------------------------------------------------------------------------- ULog

def _ulog_fields(d, prefix: str) -> list[str]:
    return [k for k in d.data if k.startswith(prefix)]


def from_ulog(ulog) -> AutopilotView:
    """The autopilot's view from a parsed ULog (pyulog's ``ULog``)."""
    view = AutopilotView("ulog")
    by_dev: dict[int, int] = {}
    for d in ulog.data_list:
        if d.name != "vehicle_imu_status" or "timestamp" not in d.data:
            continue
        t = d.data["timestamp"].astype(np.float64) * 1e-6
        r = _imu(view, int(d.multi_id))
        for attr, f in (("gyro_errors", "gyro_error_count"), ("accel_errors", "accel_error_count")):
            if f in d.data:
                setattr(r, attr, count_rise(t, d.data[f], f"vehicle_imu_status.{f}"))
                r.fields.append(f"vehicle_imu_status.{f}")
        for attr, which in (("clip", "accel_clipping"), ("gyro_clip", "gyro_clipping")):
            axes = _ulog_fields(d, which + "[")
            if axes:
                total = np.sum([d.data[a].astype(np.float64) for a in axes], axis=0)
                setattr(r, attr, count_rise(t, total, f"vehicle_imu_status.{which}"))
                r.fields.append(f"vehicle_imu_status.{which}")
        for attr, f in (("gyro_vibration_max", "gyro_vibration_metric"),
                        ("accel_vibration_max", "accel_vibration_metric")):
            if f in d.data and d.data[f].shape[0]:
                setattr(r, attr, finite_max(d.data[f]))
                r.fields.append(f"vehicle_imu_status.{f}")
        tf = "temperature_gyro" if "temperature_gyro" in d.data else ("temperature" if "temperature" in d.data else None)
        if tf:
            temp = d.data[tf].astype(np.float64)
            temp = temp[np.isfinite(temp)]
            r.temperature = [float(temp.min()), float(temp.max())] if temp.shape[0] else None
        if "gyro_device_id" in d.data and d.data["gyro_device_id"].shape[0]:
            by_dev[int(d.data["gyro_device_id"][-1])] = int(d.multi_id)
        view.fields.append("vehicle_imu_status")
    for d in ulog.data_list:
        if d.name == "sensors_status_imu" and "timestamp" in d.data:
            _ulog_voter(d, view, by_dev)
        inc = d.data.get("gyro_inconsistency_rad_s") if d.name == "sensor_preflight" else None
        if inc is not None and finite_max(inc) is not None:
            view.gyro_inconsistency_max = finite_max(np.abs(inc.astype(np.float64)))
            view.fields.append("sensor_preflight")
    view.fields = sorted(set(view.fields))
    return view


def _ulog_voter(d, view: AutopilotView, by_dev: dict[int, int]) -> None:
    """``sensors_status_imu``: the voter's health and inconsistency per slot, the slot's gyro found by device id."""
    t = d.data["timestamp"].astype(np.float64) * 1e-6
    view.fields.append("sensors_status_imu")
    for k in range(8):
        hf = f"gyro_healthy[{k}]"
        if hf not in d.data:
            break
        dev = d.data.get(f"gyro_device_ids[{k}]")
        devs = dev[dev != 0] if dev is not None else np.zeros(0)
        if devs.shape[0] == 0:
            continue  # an empty slot
        inst = by_dev.get(int(devs[-1]), k)
        r = _imu(view, inst)
        r.unhealthy.append(unhealthy(t, d.data[hf] != 0, "sensors_status_imu.gyro_healthy", "gyro"))
        r.fields.append("sensors_status_imu.gyro_healthy")
        ah = f"accel_healthy[{k}]"
        if ah in d.data:
            r.unhealthy.append(unhealthy(t, d.data[ah] != 0, "sensors_status_imu.accel_healthy", "accel"))
        inc = d.data.get(f"gyro_inconsistency_rad_s[{k}]")
        if inc is not None and inc.shape[0]:
            r.gyro_inconsistency_max = finite_max(np.abs(inc.astype(np.float64)))
            r.fields.append("sensors_status_imu.gyro_inconsistency_rad_s")


# ---------------------------------------------------------------------------------------------------- MAVLink

def link_view(fmt: str, sysid: int, ardupilot: bool, status_t: np.ndarray, status: np.ndarray,
              vib_t: np.ndarray, vib: np.ndarray, instances: list[int], view: AutopilotView | None = None
              ) -> AutopilotView:
    """The view from one system's SYS_STATUS rows (``status``: present, enabled, health) and VIBRATION rows
    (``vib``: vx vy vz c0 c1 c2), on message time. ``instances``: the system's IMU instances (the ones an
    ArduPilot all-gyro bit applies to)."""
    view = view or AutopilotView(fmt)
    # a SYS_STATUS without any IMU bit present comes from another component of the system (a companion computer,
    # a gimbal): it says nothing about the IMUs and must not end an unhealthy interval
    imu_bits = SENSOR_GYRO | SENSOR_ACCEL | SENSOR_GYRO2 | SENSOR_ACCEL2
    keep = (status["present"] & imu_bits) != 0
    status, status_t = status[keep], np.asarray(status_t)[keep]
    if status.shape[0]:
        view.fields.append("SYS_STATUS")
        pairs = ((SENSOR_GYRO, "gyro", None), (SENSOR_ACCEL, "accel", None), (SENSOR_GYRO2, "gyro", 1),
                 (SENSOR_ACCEL2, "accel", 1))
        for bit, sensor, second in pairs:
            used = ((status["present"] & bit) != 0) & ((status["enabled"] & bit) != 0)
            if not used.any():
                continue
            targets = [second] if second is not None else (sorted(set(instances) or {0}) if ardupilot else [0])
            label = "SYS_STATUS" + (f" 3D_{sensor.upper()}, all IMUs" if second is None and ardupilot else "")
            ok = ((status["health"] & bit) != 0) | ~used
            for i in targets:
                r = _imu(view, i, sysid)
                r.unhealthy.append(unhealthy(status_t, ok, label, sensor))
                r.fields.append(f"SYS_STATUS.{sensor}{'2' if second else ''}")
    if vib.shape[0]:
        view.fields.append("VIBRATION")
        for k in range(3):
            c = vib[:, 3 + k]
            if k > 0 and not np.any(c) and view.imu(k, sysid) is None and k not in instances:
                continue
            r = _imu(view, k, sysid)
            r.clip = count_rise(vib_t, c, f"VIBRATION.clipping_{k}")
            r.fields.append(f"VIBRATION.clipping_{k}")
            if k == 0:
                r.vibration_max = vector_max(vib[:, :3])
    return view


def from_tlog(idx, imu_keys) -> AutopilotView:
    """The view from an indexed tlog (:class:`companion.sources.tlog.FrameIndex`): SYS_STATUS and VIBRATION of
    every system with IMU streams (``imu_keys``), SYS_STATUS put on the IMU messages' clock."""
    from companion.sources.tlog import imu_clock, to_message_time

    view = AutopilotView("tlog")
    by_sys: dict[int, list] = {}
    for k in imu_keys:
        by_sys.setdefault(int(k.sysid), []).append(k)
    for sysid, keys in sorted(by_sys.items()):
        ref_frames, ref_t = max((imu_clock(idx, k) for k in keys), key=lambda c: c[0].shape[0])
        sel = np.flatnonzero((idx.msgid == SYS_STATUS_ID) & (idx.sysid == sysid))
        status = idx.payloads(sel, _SYS_STATUS_DT.itemsize).copy().view(_SYS_STATUS_DT).reshape(-1)
        st_t = to_message_time(idx, sel, ref_frames, ref_t)
        good = np.isfinite(st_t)
        vs = np.flatnonzero((idx.msgid == VIBRATION_ID) & (idx.sysid == sysid))
        vr = idx.payloads(vs, _VIBRATION_DT.itemsize).copy().view(_VIBRATION_DT).reshape(-1)
        vib = np.column_stack([vr[c].astype(np.float64) for c in ("vx", "vy", "vz", "c0", "c1", "c2")]) \
            if vr.shape[0] else np.zeros((0, 6))
        hb = np.flatnonzero((idx.msgid == HEARTBEAT_ID) & (idx.sysid == sysid))
        ap = idx.payloads(hb, 6)[:, 5] if hb.shape[0] else np.zeros(0, np.uint8)  # HEARTBEAT.autopilot
        link_view("tlog", sysid, bool(np.any(ap == MAV_AUTOPILOT_ARDUPILOTMEGA)), st_t[good], status[good],
                  vr["time_usec"].astype(np.float64) * 1e-6 if vr.shape[0] else np.zeros(0), vib,
                  sorted({k.instance for k in keys}), view)
    view.fields = sorted(set(view.fields))
    return view


# ---------------------------------------------------------------------------------------------------- reports

def check_report(view: AutopilotView | None, ours: dict[int, list[str]], instances: list[int]) -> dict | None:
    """The ``autopilot`` entry of a report: the view, the cross-check per IMU and its printed lines; None when the
    source carries no autopilot health at all (a CSV, a tlog without SYS_STATUS or VIBRATION)."""
    from companion.health.autopilot_view import cross_check, event_lines, inconsistency_text

    if view is None or not (view.fields or view.error):
        return None
    checks = cross_check(view, ours, instances)
    lines = [c.line() for c in checks] + event_lines(view.events)
    if view.gyro_inconsistency_max is not None:
        lines.append(inconsistency_text(view.gyro_inconsistency_max))
    if view.error:
        lines.append(f"health records not read: {view.error}")
    return {"view": view.to_dict(), "cross_check": [c.to_dict() for c in checks], "lines": lines}


class LinkHealth:
    """SYS_STATUS and VIBRATION of one vehicle as they arrive on a live link (or a replay fed message by message):
    kept as rows for :meth:`view`, and each gyro health bit that turns unhealthy said once (:meth:`on_message`)."""

    def __init__(self):
        self.status_t: list[float] = []
        self.status: list[tuple[int, int, int]] = []
        self.vib_t: list[float] = []
        self.vib: list[tuple[float, ...]] = []
        self.sysid: int | None = None
        self.ardupilot = False
        self._was_bad: dict[int, bool] = {}

    def on_heartbeat(self, sysid: int, autopilot: int) -> None:
        if self.sysid is None or sysid == self.sysid:
            self.ardupilot = self.ardupilot or autopilot == MAV_AUTOPILOT_ARDUPILOTMEGA

    def on_message(self, msg, sysid: int, t_s: float) -> list[str]:
        """One SYS_STATUS or VIBRATION of system ``sysid`` at message time ``t_s`` (SYS_STATUS has no time of
        its own: the caller gives the last IMU sample's). Returns the texts of gyro bits newly unhealthy."""
        if self.sysid is not None and sysid != self.sysid:
            return []
        self.sysid = sysid
        if msg.get_type() == "VIBRATION":
            self.vib_t.append(float(msg.time_usec) * 1e-6)
            self.vib.append((msg.vibration_x, msg.vibration_y, msg.vibration_z, msg.clipping_0, msg.clipping_1,
                             msg.clipping_2))
            return []
        row = (int(msg.onboard_control_sensors_present), int(msg.onboard_control_sensors_enabled),
               int(msg.onboard_control_sensors_health))
        self.status_t.append(float(t_s))
        self.status.append(row)
        out = []
        for bit, name in ((SENSOR_GYRO, "3D_GYRO"), (SENSOR_GYRO2, "3D_GYRO2")):
            bad = bool(row[0] & row[1] & bit) and not row[2] & bit
            if bad and not self._was_bad.get(bit, False):
                who = "gyros" if bit == SENSOR_GYRO and self.ardupilot else ("IMU1 gyro" if bit == SENSOR_GYRO2
                                                                            else "IMU0 gyro")
                out.append(f"autopilot: {who} unhealthy ({name})")
            self._was_bad[bit] = bad
        return out

    def view(self, instances: list[int]) -> AutopilotView | None:
        if not self.status and not self.vib:
            return None
        st = np.array(self.status, dtype=np.uint64).reshape(-1, 3)
        status = np.zeros(st.shape[0], dtype=_SYS_STATUS_DT)
        for j, k in enumerate(("present", "enabled", "health")):
            status[k] = st[:, j]
        view = link_view("live", self.sysid or 0, self.ardupilot, np.array(self.status_t), status,
                         np.array(self.vib_t), np.array(self.vib, dtype=float).reshape(-1, 6), instances)
        view.fields = sorted(set(view.fields))
        return view


def on_link_message(health: LinkHealth, msg, acc: dict) -> None:
    """``inspect`` on a live link: a HEARTBEAT, SYS_STATUS or VIBRATION to ``health``; SYS_STATUS on the clock of
    the latest IMU sample received (``acc``: key -> rows, time first)."""
    name = msg.get_type()
    if name == "HEARTBEAT":
        health.on_heartbeat(msg.get_srcSystem(), msg.autopilot)
    elif name in ("SYS_STATUS", "VIBRATION"):
        t = max((rows[-1][0] for rows in acc.values() if rows), default=0.0)
        health.on_message(msg, msg.get_srcSystem(), t)
