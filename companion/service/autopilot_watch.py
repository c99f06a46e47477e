"""``run`` and the autopilot's own view of its IMUs: SYS_STATUS and VIBRATION on the link (a STATUSTEXT when
the autopilot newly marks a gyro unhealthy), the view of a replayed log, and the summary's cross-check with
our findings (health/autopilot_view.py)."""

from __future__ import annotations

from companion.sources.autopilot_health import LinkHealth  # noqa: F401  (the pipeline's link view)

AUTOPILOT_MESSAGES = ("SYS_STATUS", "VIBRATION")


def on_message(pipeline, msg) -> bool:
    """A SYS_STATUS or VIBRATION of the vehicle: kept; a gyro newly unhealthy is logged and sent as STATUSTEXT at
    the time of the last IMU sample (SYS_STATUS carries no time of its own)."""
    from companion.mavlink.reporter import MAV_SEVERITY_WARNING

    t = max((ch.last_t or 0.0 for ch in pipeline.channels.values()), default=0.0)
    for text in pipeline.autopilot_link.on_message(msg, msg.get_srcSystem(), t):
        pipeline.log(text)
        pipeline.reporter.statustext(text, MAV_SEVERITY_WARNING, t)
    return False  # not an IMU sample


def report(pipeline) -> dict | None:
    """The ``autopilot`` entry of the run: the view (the replayed log's, or what the link said) beside our
    findings per IMU (its active faults, or its health when it is not healthy)."""
    from companion.sources.autopilot_health import check_report

    rows = pipeline.summary()
    instances = [r["imu"] for r in rows]
    view = pipeline.autopilot_view or pipeline.autopilot_link.view(instances)
    ours = {r["imu"]: list(r.get("faults") or ([r["health"]] if r["health"] not in ("healthy", "learning")
                                                else [])) for r in rows}
    for r in rows:  # a gyro reading exactly 0 throughout is a finding (the exit status says so) too
        if r.get("all_zero") and not ours[r["imu"]]:
            ours[r["imu"]] = [f"IMU{r['imu']} gyro X, Y, Z exactly 0 in every sample"]
    return check_report(view, ours, instances)


def summary_lines(pipeline) -> list[str]:
    rep = report(pipeline)
    return [f"autopilot: {line}" for line in rep["lines"]] if rep else []
