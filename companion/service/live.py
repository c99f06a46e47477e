"""The live receive loop of ``companion run``: messages from the link into the pipeline, link housekeeping,
stale-data detection (a warning; a STATUSTEXT every ``REPEAT_S`` until data return, since one sent while a
router is down is lost; the STALE health value every second; a STATUSTEXT and the real health at once when
data come back), a live warning when frames are rejected for their signature, periodic state saves."""

from __future__ import annotations

import time

REPEAT_S = 10.0  # wall seconds between two "IMU data stopped" texts, and between two signature warnings


def run_live(src: str, baud, signing, accept_unsigned: bool, duration, pcfg, link_cfg, period, baseline, scales,
             state, relearn: bool, save_period: float, writer, stop, log, warn, ready, gcs=()):
    """Open ``src``, build the pipeline and run until ``stop["flag"]`` or ``duration`` wall-clock seconds:
    (pipeline, link). ``ready(src)`` is called once the link is open (signals are handled by the caller).
    ``gcs``: ground-station connection strings (udpout:HOST:PORT, ...) that get a copy of every report."""
    from companion.health.detector import STALE
    from companion.mavlink.link import Link
    from companion.mavlink.reporter import MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING, Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.runner import restore, save
    from companion.sources.connection import open_connection

    conn = open_connection(src, baud, source_system=pcfg.sysid or 1, source_component=link_cfg.compid,
                           mavlink2=signing is not None)
    outputs = []
    try:
        if signing is not None:
            from companion.mavlink.signing import setup_signing

            setup_signing(conn, signing, accept_unsigned=accept_unsigned)
            log("MAVLink 2 signing on: sending signed frames, accepting "
                + ("signed and unsigned" if accept_unsigned else "only correctly signed") + " frames")
        link = Link(conn, link_cfg, pcfg.sysid, log=log)
        for spec in gcs:
            out = open_connection(spec, None, source_system=pcfg.sysid or 1, source_component=link_cfg.compid,
                                  mavlink2=signing is not None, input=False)
            outputs.append(out)
            link.outputs.append(out)
            log(f"reports also go to {spec}")
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
        last_rate_check = 0.0
        stale_since = last_stale_text = 0.0
        rejected_seen, last_rejected_warn, rejected_texted = 0, -1e18, False
        while not stop["flag"]:
            msg = conn.recv_match(blocking=True, timeout=0.1)
            now = time.monotonic()
            if msg is not None:
                link.count(msg)  # sequence numbers, loss, reordering per source
                if writer is not None:
                    writer.write_raw(msg.get_msgbuf(), time.time())
                if msg.get_type() != "BAD_DATA":
                    used = pipeline.handle(msg)
                    pipeline.raise_if_failed()
                    link.on_message(msg, is_vehicle_imu=used)
                    if used and stale:
                        stale = False
                        gap = now - stale_since
                        log(f"IMU data back after {gap:.0f} s")
                        reporter.statustext(f"companion: IMU data back after {gap:.0f} s", MAV_SEVERITY_NOTICE)
                        pipeline.send_health_now()  # HLTH leaves STALE at once, not at the next transition
                elif link.stats.rejected_signature > rejected_seen:
                    rejected_seen = link.stats.rejected_signature
                    if now - last_rejected_warn >= REPEAT_S:
                        last_rejected_warn = now
                        warn(f"{rejected_seen} frames rejected for their signature so far (wrong or missing "
                             f"signing key on the other side?)")
                        if not rejected_texted:
                            rejected_texted = True
                            reporter.statustext("companion: frames rejected: signature", MAV_SEVERITY_WARNING)
            link.service()
            if now - last_rate_check >= 0.5:
                last_rate_check = now
                rates = [ch.rate_hz for ch in pipeline.channels.values() if ch.rate_hz]
                link.check_rate(min(rates) if rates else None)
            if link.last_imu_wall is not None and now - link.last_imu_wall > link_cfg.stale_s:
                if not stale:
                    stale = True
                    stale_since = link.last_imu_wall
                    last_stale_text = -1e18
                    warn("IMU data stopped")
                if now - last_stale_text >= REPEAT_S:  # repeated: a text sent while a router is down is lost
                    last_stale_text = now
                    reporter.statustext(f"companion: IMU data stopped {now - stale_since:.0f} s ago",
                                        MAV_SEVERITY_WARNING)
                if now - last_stale_report >= 1.0:
                    pipeline.send_health_now(STALE)
                    last_stale_report = now
            if state is not None and now - last_save >= save_period:
                save(pipeline, state, warn)
                last_save = now
            if duration is not None and now - t_start >= duration:
                break
        pipeline.send_final()  # the last values sent are the summary's
        if link.rate_drops:
            log(f"IMU rate fell below the request {link.rate_drops} times (another client's stream requests); "
                f"asked again {link.rate_requests} times")
        log(f"stopping: {link.sent} messages sent, {link.values_sent} NAMED_VALUE_FLOAT, {link.texts} STATUSTEXT")
        return pipeline, link
    finally:
        for c in [conn, *outputs]:
            try:
                c.close()
            except Exception:
                pass
