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
- Ground-station outputs (``companion run --gcs CONN``): the reports (NAMED_VALUE_FLOAT, STATUSTEXT) and
  our HEARTBEAT are also written, byte for byte (so with the same signature), to each of these links. A
  router such as MAVProxy does not forward what its ``--out`` peer sends to its other outputs; this does.
  Requests to the autopilot (COMMAND_LONG, REQUEST_DATA_STREAM) go only to the main link.

Wall-clock time is used only here (heartbeats, retries); estimates and reports run on message time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from companion.config import LINK

# MAVLink enum values (common.xml) this link sends or reads
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_TYPE_GCS = 6
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
MAV_DATA_STREAM_RAW_SENSORS = 1
MAV_COMP_ID_ONBOARD_COMPUTER = 191
MAV_SEVERITY_WARNING = 4
MAV_SEVERITY_NOTICE = 5

#: message ids of the IMU messages a link may ask for (run.messages)
IMU_MESSAGE_IDS = {"RAW_IMU": 27, "SCALED_IMU": 26, "SCALED_IMU2": 116, "SCALED_IMU3": 129, "HIGHRES_IMU": 105}


# --- link health: loss, reordering and late packets per source, from MAVLink sequence numbers ---

IMU_TIME_FIELDS = {"RAW_IMU": "time_usec", "HIGHRES_IMU": "time_usec", "SCALED_IMU": "time_boot_ms",
                   "SCALED_IMU2": "time_boot_ms", "SCALED_IMU3": "time_boot_ms"}


class SourceStats:
    """Counters of one sender (system id, component id): every MAVLink frame carries an 8-bit sequence
    number that its sender increments per frame on the link, so a jump of d > 1 means d - 1 frames lost,
    a frame behind the newest one is out of order (it was counted lost at the jump and is taken back), a
    repeat of the last number is a duplicate. Jumps of 128 or more are read as reordering, not loss."""

    __slots__ = ("received", "lost", "out_of_order", "duplicates", "late", "last_seq", "window_rx", "window_lost")

    def __init__(self):
        self.received = 0
        self.lost = 0
        self.out_of_order = 0
        self.duplicates = 0
        self.late = 0  # IMU samples older than the newest one of their stream (arrived after a later one)
        self.last_seq: int | None = None
        self.window_rx = 0
        self.window_lost = 0

    def on_seq(self, seq: int, gap_hint: float | None = None) -> None:
        """``gap_hint``: for a frame newer (in message time) than everything of its IMU stream, how many
        frames of this sender the time gap suggests were lost. Only used to resolve what 8 bits cannot: a
        run of 128 or more lost frames (else read as reordering) or of 256 and more (else invisible)."""
        self.received += 1
        self.window_rx += 1
        if self.last_seq is None:
            self.last_seq = seq
            return
        d = (seq - self.last_seq) & 0xFF
        if gap_hint is not None and gap_hint > 64:
            base = (d - 1) & 0xFF
            lost = base + 256 * max(0, int(round((gap_hint - base) / 256.0)))
            self.lost += lost
            self.window_lost += lost
            self.last_seq = seq
            return
        if d == 1:
            self.last_seq = seq
        elif d == 0:
            self.duplicates += 1
        elif d < 128:
            self.lost += d - 1
            self.window_lost += d - 1
            self.last_seq = seq
        else:  # behind the newest: a frame we had given up as lost
            self.out_of_order += 1
            if self.lost > 0:
                self.lost -= 1
            if self.window_lost > 0:
                self.window_lost -= 1

    @property
    def expected(self) -> int:
        return self.received - self.duplicates + self.lost

    def loss_fraction(self) -> float:
        return self.lost / self.expected if self.expected else 0.0

    def as_dict(self) -> dict:
        return {"received": self.received, "lost": self.lost, "loss": self.loss_fraction(),
                "out_of_order": self.out_of_order, "duplicates": self.duplicates, "late": self.late}


class LinkStats:
    """Per-source link health: :class:`SourceStats` per (sysid, compid), bad frames, rejected (unsigned or
    wrongly signed) frames, and the loss over the last ``window_s`` of wall clock for the warning."""

    def __init__(self):
        self.sources: dict[tuple[int, int], SourceStats] = {}
        self.bad_frames = 0
        self.rejected_signature = 0
        self._imu: dict[tuple, list] = {}  # per IMU stream: newest message time (s), sample period, frames
        self._last_imu_t: dict[tuple, float] = {}  # per sender: message time of its newest IMU frame

    def on_message(self, msg) -> None:
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            if "signature" in str(getattr(msg, "reason", "")):
                self.rejected_signature += 1  # unsigned, wrongly signed or replayed (signing is on)
            else:
                self.bad_frames += 1
            return
        key = (msg.get_srcSystem(), msg.get_srcComponent())
        st = self.sources.get(key)
        if st is None:
            st = self.sources[key] = SourceStats()
        field = IMU_TIME_FIELDS.get(mtype)
        t = getattr(msg, field, None) if field is not None else None
        if t is None:
            st.on_seq(msg.get_seq())
            return
        t = float(t) * (1e-6 if field == "time_usec" else 1e-3)
        k = (key, mtype, getattr(msg, "id", 0))
        s = self._imu.get(k)
        if s is None:
            s = self._imu[k] = [t, None, 0]  # newest time, sample period (EMA), frames received
            st.on_seq(msg.get_seq())
            s[2] += 1
            self._last_imu_t[key] = max(t, self._last_imu_t.get(key, t))
            return
        newest, period, count = s
        s[2] = count + 1
        dt = t - newest
        if dt < 0 and -dt < 1.0:
            st.late += 1  # older than one already received (a step back of >= 1 s is a reboot)
            st.on_seq(msg.get_seq())
            return
        hint = None
        last_any = self._last_imu_t.get(key)
        if dt > 0 and period is not None and last_any is not None and t > last_any:
            # frames this sender sends per second of message time: per sample of this stream (several
            # IMUs and heartbeats interleave) times the stream's rate; the gap since its last IMU frame
            per_sample = max(1.0, st.received / max(count, 1))
            hint = max(0.0, (t - last_any) / period * per_sample - 1.0)
        st.on_seq(msg.get_seq(), hint)
        if last_any is None or t > last_any or last_any - t > 1.0:
            self._last_imu_t[key] = t
        if dt > 0:
            if period is None:
                s[1] = dt
            elif dt < 1.5 * period:
                s[1] = 0.95 * period + 0.05 * dt
        s[0] = t

    def window(self) -> tuple[int, int]:
        """(received, lost) since the last call, summed over sources; restarts the window."""
        rx = lost = 0
        for st in self.sources.values():
            rx += st.window_rx
            lost += st.window_lost
            st.window_rx = st.window_lost = 0
        return rx, lost

    def summary_lines(self) -> list[str]:
        out = []
        for (sysid, compid), st in sorted(self.sources.items()):
            out.append(f"link from {sysid}/{compid}: {st.received} frames received, {st.lost} lost "
                       f"({100 * st.loss_fraction():.1f} %), {st.out_of_order} out of order, {st.duplicates} duplicates, "
                       f"{st.late} late IMU samples")
        if self.bad_frames or self.rejected_signature:
            out.append(f"link: {self.bad_frames} bad frames, {self.rejected_signature} rejected for their signature")
        return out


@dataclass
class LinkConfig:
    """The link keys of the ``run`` section; defaults from the schema (:data:`companion.config.LINK`)."""

    rate_hz: float = LINK["rate_hz"].default
    messages: tuple[str, ...] = tuple(LINK["messages"].default)
    compid: int = LINK["compid"].default  # MAV_COMP_ID_ONBOARD_COMPUTER
    heartbeat_s: float = LINK["heartbeat_s"].default
    stale_s: float = LINK["stale_s"].default
    retry_s: float = LINK["retry_s"].default
    # STATUSTEXT when more than this fraction of frames was lost over loss_window_s
    loss_warn: float = LINK["loss_warn"].default
    loss_window_s: float = LINK["loss_window_s"].default


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
        self._stale_asks = 0  # requests sent during the current silence of the IMU data (the log says the first two)
        self.use_data_stream = False
        self.acked = False  # the autopilot accepted a SET_MESSAGE_INTERVAL
        self.requests = 0
        self.sent = 0
        self.texts = 0  # STATUSTEXT sent (the reporter's and the link's own)
        self.values_sent = 0  # NAMED_VALUE_FLOAT sent
        self.recorder = None  # a TlogWriter: every frame we send is also recorded
        self.outputs: list = []  # ground-station links (pymavlink connections): reports are copied there
        self.output_sent = 0  # frames written to them (per output)
        self._fanout = False  # the frame being encoded is a report or heartbeat (copied to ``outputs``)
        self.stats = LinkStats()
        self._loss_window_start: float | None = None
        self._unanswered = 0  # rate requests since the rate was last as asked
        self._given_up_at: float | None = None  # the rate the autopilot kept after three requests
        self.rate_low = False  # the measured rate is below what we asked for (another client's request)
        self.rate_drops = 0  # times it fell below, each answered by asking again
        self._rate_reached = False  # the rate was as asked at least once (before, a low rate is no "drop")
        self.rate_requests = 0
        self._rate_request_wall: float | None = None
        self._loss_warned = False
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
        if self._fanout and self.outputs:
            for out in self.outputs:
                try:
                    out.write(buf)
                except OSError:
                    pass  # a ground station not there (yet): UDP refusals are not our link's problem
            self.output_sent += 1
        if self.recorder is not None:
            self.recorder.write_raw(bytes(buf), time.time())

    def _report(self, send, *args) -> None:
        """Encode and send one report frame (also copied to the ground-station outputs)."""
        self._fanout = True
        try:
            send(*args)
        finally:
            self._fanout = False

    def send_named_value_float(self, time_boot_ms: int, name: str, value: float) -> None:
        self.values_sent += 1
        self._report(self._mav().named_value_float_send, int(time_boot_ms), name.encode("ascii"), float(value))

    def send_statustext(self, severity: int, text: str, time_boot_ms: int | None = None) -> None:
        self.texts += 1
        self._report(self._mav().statustext_send, int(severity), text.encode("ascii", "replace")[:50])

    def send_heartbeat(self) -> None:
        self._report(self._mav().heartbeat_send, MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0,
                     MAV_STATE_ACTIVE)

    def drain_outputs(self) -> None:
        """Read and drop what ground stations send back on their outputs (their heartbeats), so their
        sockets never fill; a GCS talks to the autopilot through its own link, not through ours."""
        for out in self.outputs:
            try:
                for _ in range(64):
                    if out.recv_msg() is None:
                        break
            except Exception:
                pass

    # --- receiving ---
    def count(self, msg) -> None:
        """Link accounting of every received frame (BAD_DATA included): sequence numbers per source."""
        self.stats.on_message(msg)

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
            self.drain_outputs()
        self._check_loss(now)
        data_stale = self.last_imu_wall is None or now - self.last_imu_wall > self.cfg.stale_s
        if not data_stale:
            if self._stale_asks > 1:
                self.log(f"IMU data back (asked {self._stale_asks} times while there were none)")
            self._stale_asks = 0
            return
        # data stopped (a reboot, the link lost): what comes back streams at the autopilot's own rate until our
        # request takes effect again -- "not yet" the rate asked for, not another client's request
        self._rate_reached = False
        if self.last_request_wall is not None:
            waited = now - self.last_request_wall
            if waited < self.cfg.retry_s:
                return
            if self.requests >= 2 and not self.acked and not self.use_data_stream:
                self.use_data_stream = True  # two requests without an answer nor data: old autopilot? fall back too
                self.log("no answer to SET_MESSAGE_INTERVAL: asking with REQUEST_DATA_STREAM too")
        # the first request of each silence is logged, then that they repeat: every retry_s for as long as an
        # autopilot is off or rebooting, one line each would fill the log
        if self._stale_asks == 1:
            self.log(f"no IMU data yet: asking again every {self.cfg.retry_s:g} s until they come")
        self.request_streams(quiet=self._stale_asks > 0)
        self._stale_asks += 1
        self.last_request_wall = now

    def requested_rate(self) -> float:
        """The IMU rate our requests ask for (REQUEST_DATA_STREAM is capped at 50 Hz)."""
        return min(self.cfg.rate_hz, 50.0) if self.use_data_stream and not self.acked else self.cfg.rate_hz

    def check_rate(self, measured_hz: float | None) -> None:
        """The IMU rate measured in message time (the slowest IMU). Below 0.8 x the rate we asked for,
        another client's stream request (a GCS or router setting stream rates on a shared link) or a rate
        change took it: ask again, at most every ``retry_s``; the first time of each drop is logged. An
        autopilot that does not give more after three requests in a row is not asked again at that rate."""
        if measured_hz is None or not measured_hz > 0:
            return
        now = self.clock()
        if self.last_imu_wall is None or now - self.last_imu_wall > self.cfg.stale_s:
            return  # no data: the stale path asks again
        target = self.requested_rate()
        if measured_hz >= 0.8 * target:
            self._unanswered = 0
            self._given_up_at = None
            if self.rate_low:
                self.rate_low = False
                if not self._rate_reached:
                    self.log(f"IMU rate {measured_hz:.0f} Hz, as asked")
                elif self.rate_drops == 1:
                    self.log(f"IMU rate back to {measured_hz:.0f} Hz")
            self._rate_reached = True
            return
        if self._given_up_at is not None and abs(measured_hz / self._given_up_at - 1.0) <= 0.2:
            return
        self._given_up_at = None
        if not self.rate_low:
            self.rate_low = True
            if not self._rate_reached:
                # the first data may come before the first request took effect (the autopilot streams at its
                # own rate until then): not yet a drop, and no other client to suspect
                self.log(f"IMU rate {measured_hz:.1f} Hz, not yet the {target:.0f} Hz asked for: asking again")
            else:
                self.rate_drops += 1
                if self.rate_drops == 1:  # said once; the count is in the exit line
                    self.log(f"IMU rate {measured_hz:.1f} Hz, below the {target:.0f} Hz asked for (another client's "
                             "stream request?): asking again")
        if self._rate_request_wall is not None and now - self._rate_request_wall < self.cfg.retry_s:
            return
        if self._unanswered >= 3:
            self._given_up_at = measured_hz
            self._unanswered = 0
            self.log(f"the autopilot keeps the IMU at {measured_hz:.1f} Hz after 3 requests: not asking again at that rate")
            return
        self._rate_request_wall = now
        self._unanswered += 1
        self.rate_requests += 1
        self.request_streams(quiet=True)

    def request_streams(self, quiet: bool = False) -> None:
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
        if not quiet:
            self.log(f"asked for IMU data at {self.cfg.rate_hz:g} Hz" + (" (and REQUEST_DATA_STREAM)" if self.use_data_stream else ""))

    def _check_loss(self, now: float) -> None:
        """Every ``loss_window_s``: a WARNING STATUSTEXT when more than ``loss_warn`` of the frames of the
        window were lost (at least 50 expected), a NOTICE when it is back below half of that."""
        if self._loss_window_start is None:
            self._loss_window_start = now
            self.stats.window()
            return
        if now - self._loss_window_start < self.cfg.loss_window_s:
            return
        self._loss_window_start = now
        rx, lost = self.stats.window()
        expected = rx + lost
        if expected < 50:
            return
        frac = lost / expected
        if frac > self.cfg.loss_warn and not self._loss_warned:
            self._loss_warned = True
            text = f"companion: link loss {100 * frac:.0f}% ({lost}/{expected})"
            self.log(text)
            self.send_statustext(MAV_SEVERITY_WARNING, text)
        elif self._loss_warned and frac < self.cfg.loss_warn / 2:
            self._loss_warned = False
            text = f"companion: link loss back to {100 * frac:.1f}%"
            self.log(text)
            self.send_statustext(MAV_SEVERITY_NOTICE, text)
