"""The live receive loop of ``companion run``: messages from the link into the pipeline, link housekeeping,
stale-data detection (a warning; a STATUSTEXT every ``REPEAT_S`` until data return, since one sent while a
router is down is lost; the STALE health value every second; a STATUSTEXT and the real health at once when
data come back), a live warning when frames are rejected for their signature, periodic state saves."""

from __future__ import annotations

import time
from dataclasses import dataclass

from companion.service.run_options import RunHooks, RunOptions

REPEAT_S = 10.0  # wall seconds between two "IMU data stopped" texts, and between two signature warnings
RATE_CHECK_S = 0.5  # wall seconds between two checks of the IMU rate against the request
STALE_REPORT_S = 1.0  # wall seconds between two STALE health values while the data are stale
RECV_TIMEOUT_S = 0.1  # wall seconds one receive waits: the loop's housekeeping runs at least this often


@dataclass
class StaleWatch:
    """Whether the IMU data stopped, since when, and when it was last said."""

    stale: bool = False
    since: float = 0.0  # wall time of the last IMU message before they stopped
    last_text: float = 0.0
    last_report: float = 0.0


@dataclass
class RejectWatch:
    """Frames rejected for their signature: how many seen, when last warned, whether a STATUSTEXT went."""

    seen: int = 0
    last_warn: float = -1e18
    texted: bool = False


class LiveLoop:
    """One live run on an open link: :meth:`on_message` per message, :meth:`housekeeping` per pass."""

    def __init__(self, opts: RunOptions, hooks: RunHooks, conn, link, pipeline, writer=None):
        self.opts, self.hooks = opts, hooks
        self.conn, self.link, self.pipeline, self.writer = conn, link, pipeline, writer
        self.reporter = pipeline.reporter
        self.stale = StaleWatch()
        self.rejected = RejectWatch()
        self.last_save = self.last_rate_check = 0.0

    def run(self) -> None:
        """Receive and serve until stopped or ``opts.duration`` wall seconds; then send the summary's terms."""
        t_start = time.monotonic()
        self.last_save = t_start
        while not self.hooks.stop():
            msg = self.conn.recv_match(blocking=True, timeout=RECV_TIMEOUT_S)
            now = time.monotonic()
            if msg is not None:
                self.on_message(msg, now)
            self.housekeeping(now)
            if self.opts.duration is not None and now - t_start >= self.opts.duration:
                break
        self.pipeline.send_final()  # the last values sent are the summary's
        link = self.link
        if link.rate_drops:
            self.hooks.log(f"IMU rate fell below the request {link.rate_drops} times (another client's stream "
                           f"requests); asked again {link.rate_requests} times")
        self.hooks.log(f"stopping: {link.sent} messages sent, {link.values_sent} NAMED_VALUE_FLOAT, "
                       f"{link.texts} STATUSTEXT")

    def on_message(self, msg, now: float) -> None:
        """One received message: counted, recorded, fed to the pipeline (or a rejected frame noted)."""
        from companion.mavlink.reporter import MAV_SEVERITY_NOTICE

        self.link.count(msg)  # sequence numbers, loss, reordering per source
        if self.writer is not None:
            self.writer.write_raw(msg.get_msgbuf(), time.time())
        if msg.get_type() == "BAD_DATA":
            self._rejected(now)
            return
        used = self.pipeline.handle(msg)
        self.pipeline.raise_if_failed()
        self.link.on_message(msg, is_vehicle_imu=used)
        if used and self.stale.stale:
            self.stale.stale = False
            gap = now - self.stale.since
            self.hooks.log(f"IMU data back after {gap:.0f} s")
            self.reporter.statustext(f"companion: IMU data back after {gap:.0f} s", MAV_SEVERITY_NOTICE)
            self.pipeline.send_health_now()  # HLTH leaves STALE at once, not at the next transition

    def _rejected(self, now: float) -> None:
        """A frame pymavlink refused: warn (every REPEAT_S) when its signature was the reason."""
        from companion.mavlink.reporter import MAV_SEVERITY_WARNING

        r = self.rejected
        count = self.link.stats.rejected_signature
        if count <= r.seen:
            return
        r.seen = count
        if now - r.last_warn < REPEAT_S:
            return
        r.last_warn = now
        self.hooks.warn(f"{count} frames rejected for their signature so far (wrong or missing signing key on "
                        "the other side?)")
        if not r.texted:
            r.texted = True
            self.reporter.statustext("companion: frames rejected: signature", MAV_SEVERITY_WARNING)

    def housekeeping(self, now: float) -> None:
        """Every pass: the link's heartbeat and requests, the rate check, stale data, the periodic save."""
        from companion.service.run_session import save

        self.link.service()
        if now - self.last_rate_check >= RATE_CHECK_S:
            self.last_rate_check = now
            rates = [ch.rate_hz for ch in self.pipeline.channels.values() if ch.rate_hz]
            self.link.check_rate(min(rates) if rates else None)
        last_imu = self.link.last_imu_wall
        if last_imu is not None and now - last_imu > self.opts.link.stale_s:
            self._stale(now, last_imu)
        if self.opts.state is not None and now - self.last_save >= self.opts.save_period:
            save(self.pipeline, self.opts.state, self.hooks.warn)
            self.last_save = now

    def _stale(self, now: float, last_imu: float) -> None:
        """No IMU data for ``stale_s``: warn once, a STATUSTEXT every REPEAT_S, STALE health every second."""
        from companion.health.degradation import STALE
        from companion.mavlink.reporter import MAV_SEVERITY_WARNING

        s = self.stale
        if not s.stale:
            s.stale = True
            s.since = last_imu
            s.last_text = -1e18
            self.hooks.warn("IMU data stopped")
        if now - s.last_text >= REPEAT_S:  # repeated: a text sent while a router is down is lost
            s.last_text = now
            self.reporter.statustext(f"companion: IMU data stopped {now - s.since:.0f} s ago", MAV_SEVERITY_WARNING)
        if now - s.last_report >= STALE_REPORT_S:
            self.pipeline.send_health_now(STALE)
            s.last_report = now


def _open_link(opts: RunOptions, hooks: RunHooks, conn, outputs: list):
    """The Link on ``conn``: signing set up, the --gcs outputs opened (appended to ``outputs``)."""
    from companion.mavlink.link import Link
    from companion.sources.connection import open_connection

    pcfg, link_cfg = opts.pipeline, opts.link
    if opts.signing is not None:
        from companion.mavlink.signing import setup_signing

        setup_signing(conn, opts.signing, accept_unsigned=opts.accept_unsigned)
        hooks.log("MAVLink 2 signing on: sending signed frames, accepting "
                  + ("signed and unsigned" if opts.accept_unsigned else "only correctly signed") + " frames")
    link = Link(conn, link_cfg, pcfg.sysid, log=hooks.log)
    for spec in opts.gcs:
        out = open_connection(spec, None, source_system=pcfg.sysid or 1, source_component=link_cfg.compid,
                              mavlink2=opts.signing is not None, input=False)
        outputs.append(out)
        link.outputs.append(out)
        hooks.log(f"reports also go to {spec}")
    return link


def run_live(opts: RunOptions, hooks: RunHooks, writer=None):
    """Open ``opts.source``, build the pipeline and run until ``hooks.stop()`` or ``opts.duration`` wall-clock
    seconds: (pipeline, link). ``hooks.ready(source)`` is called once the link is open (signals are handled
    by the caller); ``writer`` (a TlogWriter) records what was received and sent."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.run_session import restore
    from companion.sources.connection import open_connection

    conn = open_connection(opts.source, opts.baud, source_system=opts.pipeline.sysid or 1,
                           source_component=opts.link.compid, mavlink2=opts.signing is not None)
    outputs: list = []
    try:
        link = _open_link(opts, hooks, conn, outputs)
        if writer is not None:
            link.recorder = writer
        pipeline = Pipeline(opts.pipeline, Reporter(link, opts.report_period), opts.baseline, hooks.log, opts.scales)
        restore(pipeline, opts.state, opts.relearn, hooks.warn, hooks.log)
        hooks.started(pipeline)
        if pipeline.sysid is not None and link.sysid is None:
            link.set_sysid(pipeline.sysid)
        hooks.ready(opts.source)
        LiveLoop(opts, hooks, conn, link, pipeline, writer).run()
        return pipeline, link
    finally:
        for c in [conn, *outputs]:
            try:
                c.close()
            except Exception:
                pass
