"""The live receive loop of ``companion run``: messages from the link into the pipeline, link housekeeping,
stale-data detection (a warning, a STATUSTEXT and the STALE health value every second), periodic state saves."""

from __future__ import annotations

import time


def run_live(src: str, baud, signing, accept_unsigned: bool, duration, pcfg, link_cfg, period, baseline, scales,
             state, relearn: bool, save_period: float, writer, stop, log, warn, ready):
    """Open ``src``, build the pipeline and run until ``stop["flag"]`` or ``duration`` wall-clock seconds:
    (pipeline, link). ``ready(src)`` is called once the link is open (signals are handled by the caller)."""
    from companion.health.detector import STALE
    from companion.mavlink.link import Link
    from companion.mavlink.reporter import MAV_SEVERITY_WARNING, Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.runner import restore, save
    from companion.sources.connection import open_connection

    conn = open_connection(src, baud, source_system=pcfg.sysid or 1, source_component=link_cfg.compid,
                           mavlink2=signing is not None)
    try:
        if signing is not None:
            from companion.mavlink.signing import setup_signing

            setup_signing(conn, signing, accept_unsigned=accept_unsigned)
            log("MAVLink 2 signing on: sending signed frames, accepting "
                + ("signed and unsigned" if accept_unsigned else "only correctly signed") + " frames")
        link = Link(conn, link_cfg, pcfg.sysid, log=log)
        if writer is not None:
            link.recorder = writer
        reporter = Reporter(link, period)
        pipeline = Pipeline(pcfg, reporter, baseline, log, scales)
        restore(pipeline, state, relearn, warn, log)
        if pipeline.sysid is not None and link.sysid is None:
            link.set_sysid(pipeline.sysid)
        ready(src)
        t_start = time.monotonic()
        last_save = t_start
        stale = False
        last_stale_report = 0.0
        while not stop["flag"]:
            msg = conn.recv_match(blocking=True, timeout=0.1)
            now = time.monotonic()
            if msg is not None:
                link.count(msg)  # sequence numbers, loss, reordering per source
                if writer is not None:
                    writer.write_raw(msg.get_msgbuf(), time.time())
                if msg.get_type() != "BAD_DATA":
                    used = pipeline.handle(msg)
                    link.on_message(msg, is_vehicle_imu=used)
                    if used and stale:
                        stale = False
                        log("IMU data back")
            link.service()
            if link.last_imu_wall is not None and now - link.last_imu_wall > link_cfg.stale_s:
                if not stale:
                    stale = True
                    warn("IMU data stopped")
                    reporter.statustext("companion: IMU data stopped", MAV_SEVERITY_WARNING)
                if now - last_stale_report >= 1.0:
                    pipeline.send_health_now(STALE)
                    last_stale_report = now
            if state is not None and now - last_save >= save_period:
                save(pipeline, state, warn)
                last_save = now
            if duration is not None and now - t_start >= duration:
                break
        log(f"stopping: {link.sent} messages sent, {reporter.sent} NAMED_VALUE_FLOAT, {reporter.texts} STATUSTEXT")
        return pipeline, link
    finally:
        try:
            conn.close()
        except Exception:
            pass
