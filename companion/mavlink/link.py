"""The companion's side of a live MAVLink link: who we are, what we ask for, where replies go.

- Identity: our own HEARTBEAT once a second (wall clock) as ``MAV_TYPE_ONBOARD_CONTROLLER`` (18),
  autopilot ``MAV_AUTOPILOT_INVALID`` (8), component id 191 (``MAV_COMP_ID_ONBOARD_COMPUTER``) by default,
  system id of the vehicle (the configured one, else the first system sending IMU data).
- Asking for IMU data: ``MAV_CMD_SET_MESSAGE_INTERVAL`` (511) per message at the configured rate; when the
  autopilot refuses (COMMAND_ACK result != ACCEPTED) or two requests ``retry_s`` apart get neither an ACK
  nor data (an autopilot without the command), also ``REQUEST_DATA_STREAM`` (``MAV_DATA_STREAM_RAW_SENSORS``) at min(rate, 50) Hz. If IMU data stops for
  ``stale_s`` the requests are repeated every ``retry_s`` (link loss and return, autopilot reboot).
- Replies go where the IMU data came from: on a ``udpin:`` link (several peers may write to our port),
  every message we send goes to the address of the last IMU message of the vehicle, not to all peers.

Wall-clock time is used only here (heartbeats, retries); estimates and reports run on message time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_TYPE_GCS = 6
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
MAV_DATA_STREAM_RAW_SENSORS = 1
MAV_COMP_ID_ONBOARD_COMPUTER = 191

IMU_MESSAGE_IDS = {"RAW_IMU": 27, "SCALED_IMU": 26, "SCALED_IMU2": 116, "SCALED_IMU3": 129, "HIGHRES_IMU": 105}


@dataclass
class LinkConfig:
    rate_hz: float = 100.0
    messages: tuple[str, ...] = ("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")
    compid: int = MAV_COMP_ID_ONBOARD_COMPUTER
    heartbeat_s: float = 1.0
    stale_s: float = 3.0
    retry_s: float = 5.0


class Link:
    """Wraps a pymavlink connection (from companion.sources.connection.open_connection).

    Call :meth:`on_message` for every received message and :meth:`service` regularly (a few times a
    second); use it as the reporter's sink (:meth:`send_named_value_float`, :meth:`send_statustext`).
    """

    def __init__(self, conn, cfg: LinkConfig | None = None, sysid: int | None = None, clock=time.monotonic, log=None):
        self.conn = conn
        self.cfg = cfg or LinkConfig()
        self.clock = clock
        self.log = log or (lambda line: None)
        self.sysid = sysid  # the vehicle's system id (None: the first one sending IMU data)
        self.autopilot_compid: int | None = None
        self.imu_address = None
        self.last_imu_wall: float | None = None
        self.last_heartbeat_wall = -1e18
        self.last_request_wall: float | None = None
        self.use_data_stream = False
        self.acked = False  # the autopilot accepted a SET_MESSAGE_INTERVAL
        self.requests = 0
        self.sent = 0
        self.recorder = None  # a TlogWriter: every frame we send is also recorded
        self._udp_server = bool(getattr(conn, "udp_server", False))
        self._conn_write = conn.write
        self._mav_seen = None
        self._mav()

    def _mav(self):
        """The connection's encoder, set up as ours. pymavlink replaces ``conn.mav`` when it switches to
        MAVLink 2 on the first v2 frame received, so this is checked before every send."""
        mav = self.conn.mav
        if mav is not self._mav_seen:
            mav.srcSystem = self.sysid if self.sysid is not None else 1
            mav.srcComponent = int(self.cfg.compid)
            mav.file = self  # every frame we send goes through write() below
            self._mav_seen = mav
        return mav

    def set_sysid(self, sysid: int) -> None:
        """The vehicle's system id (known from a restored state): we send with it from now on."""
        self.sysid = int(sysid)
        self._mav_seen = None

    # --- writing ---
    def write(self, buf: bytes) -> None:
        """Send one frame: on udpin to the vehicle's address only, else through the connection."""
        if self._udp_server and self.imu_address is not None:
            try:
                self.conn.port.sendto(buf, self.imu_address)
            except OSError:
                pass
        else:
            try:
                self._conn_write(buf)
            except OSError:
                pass
        self.sent += 1
        if self.recorder is not None:
            self.recorder.write_raw(bytes(buf), time.time())

    def send_named_value_float(self, time_boot_ms: int, name: str, value: float) -> None:
        self._mav().named_value_float_send(int(time_boot_ms), name.encode("ascii"), float(value))

    def send_statustext(self, severity: int, text: str) -> None:
        self._mav().statustext_send(int(severity), text.encode("ascii", "replace")[:50])

    def send_heartbeat(self) -> None:
        self._mav().heartbeat_send(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE)

    # --- receiving ---
    def on_message(self, msg, is_vehicle_imu: bool = False) -> None:
        """Track the vehicle: its autopilot component, acks to our requests, where its IMU data comes from."""
        mtype = msg.get_type()
        src = msg.get_srcSystem()
        if self.sysid is not None and src != self.sysid:
            return
        if mtype == "HEARTBEAT":
            if msg.autopilot != MAV_AUTOPILOT_INVALID and msg.type not in (MAV_TYPE_GCS, MAV_TYPE_ONBOARD_CONTROLLER):
                self.autopilot_compid = msg.get_srcComponent()
        elif mtype == "COMMAND_ACK":
            if msg.command == MAV_CMD_SET_MESSAGE_INTERVAL and msg.result == MAV_RESULT_ACCEPTED:
                self.acked = True
            elif msg.command == MAV_CMD_SET_MESSAGE_INTERVAL and not self.use_data_stream:
                self.log(f"autopilot refused SET_MESSAGE_INTERVAL (result {msg.result}); using REQUEST_DATA_STREAM")
                self.use_data_stream = True
                self.last_request_wall = None  # ask again right away
        if is_vehicle_imu:
            if self.sysid is None:
                self.sysid = src
                self._mav().srcSystem = src
                self.log(f"vehicle: system id {src}")
            self.last_imu_wall = self.clock()
            if self._udp_server:
                addr = self._last_sender()
                if addr is not None:
                    self.imu_address = addr

    def _last_sender(self):
        """Address of the peer that sent the datagram just parsed (pymavlink's udpin keeps a client set)."""
        alive = getattr(self.conn, "clients_last_alive", None)
        if alive:
            return max(alive.items(), key=lambda kv: kv[1])[0]
        return None

    # --- periodic ---
    def service(self) -> None:
        now = self.clock()
        if now - self.last_heartbeat_wall >= self.cfg.heartbeat_s:
            self.send_heartbeat()
            self.last_heartbeat_wall = now
        data_stale = self.last_imu_wall is None or now - self.last_imu_wall > self.cfg.stale_s
        if not data_stale:
            return
        if self.last_request_wall is not None:
            waited = now - self.last_request_wall
            if waited < self.cfg.retry_s:
                return
            if self.requests >= 2 and not self.acked and not self.use_data_stream:
                self.use_data_stream = True  # two requests without an answer nor data: old autopilot? fall back too
        self.request_streams()
        self.last_request_wall = now

    def request_streams(self) -> None:
        target = self.sysid if self.sysid is not None else 0
        comp = self.autopilot_compid if self.autopilot_compid is not None else 0
        interval_us = 1e6 / self.cfg.rate_hz
        for name in self.cfg.messages:
            self._mav().command_long_send(target, comp, MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                            IMU_MESSAGE_IDS[name], interval_us, 0, 0, 0, 0, 0)
        if self.use_data_stream:
            rate = int(max(1, min(50, round(self.cfg.rate_hz))))
            self._mav().request_data_stream_send(target, comp, MAV_DATA_STREAM_RAW_SENSORS, rate, 1)
        self.requests += 1
        self.log(f"asked for IMU data at {self.cfg.rate_hz:g} Hz" + (" (and REQUEST_DATA_STREAM)" if self.use_data_stream else ""))
