"""The saved state of a :class:`~companion.service.pipeline.Pipeline` (the ``--state`` file's content): the
vehicle's system id, the baseline, every IMU's channel (estimators, detectors), the IMU group and the logs
replayed into it. Atomic writing and reading of the file are :mod:`companion.service.state`."""

from __future__ import annotations

from typing import Mapping

from companion.health.baseline import Baseline
from companion.service.channel import Channel
from companion.service.imu_group import ImuGroup

STATE_FORMAT = "companion-run-state"  # the "format" key that tells our state file from any other JSON
#: version 2 adds "inflight" (the in-flight baselines, service.inflight_live); a version-1 file loads without them
#: the per-axis faults that describe the sensor itself, said again after a restart while they last (a
#: saturation was the last run's motion, a bias fault is judged within a run)
SENSOR_FAULTS = ("dead", "stuck", "noise", "spikes", "resolution")


def pipeline_state(p) -> dict:
    """The state of pipeline ``p`` as a JSON-ready dict (channels whose rate is known)."""
    chans = {str(imu): ch.state_dict() for imu, ch in p.channels.items() if ch.rate_hz is not None}
    return {"format": STATE_FORMAT, "version": 2, "sysid": p.sysid, "inflight": p.inflight.state_dict(),
            "baseline": p.baseline.to_dict() if p.baseline is not None else None, "channels": chans,
            "replayed": list(p.replayed), "evidence": p.evidence.state_dict(), **p.group.state_dict()}


def load_pipeline_state(p, d: Mapping) -> None:
    """Restore pipeline ``p`` from :func:`pipeline_state`; ValueError (the caller warns and starts fresh)
    when ``d`` is not ours or of another vehicle. A loaded (fixed) baseline wins over the saved one."""
    if not isinstance(d, Mapping) or d.get("format") != STATE_FORMAT or d.get("version") not in (1, 2):
        raise ValueError("not a companion run state")
    if p.sysid is not None and d.get("sysid") not in (None, p.sysid):
        raise ValueError(f"state is for system id {d.get('sysid')}, not {p.sysid}")
    channels = {int(key): Channel.from_state(int(key), c, p.cfg) for key, c in (d.get("channels") or {}).items()}
    group = ImuGroup(p.cfg.reset_s, p.cfg.faults)
    group.load_state_dict(d)
    p.group = group
    baseline = None
    if d.get("baseline") is not None:
        baseline = Baseline.from_dict(d["baseline"])
    if not p.baseline_fixed:
        p.baseline = baseline
    for ch in channels.values():
        if p._has_baseline(ch):
            ch.bank.stop_learning()
        elif not ch.learn:  # no baseline for this IMU and nothing being learned: learn afresh
            ch.relearn()
    p.channels = channels
    p.evidence.load_state_dict(d.get("evidence"))
    if d.get("inflight") is not None:  # version 1 files have none: learned afresh
        p.inflight.load_state_dict(d["inflight"])
    p.replayed = [dict(r) for r in d.get("replayed") or [] if isinstance(r, Mapping) and "sha256" in r]
    sensor = {imu: [(k, ax) for k, ax in ch.faults.active() if k in SENSOR_FAULTS] for imu, ch in channels.items()}
    p._restored = {imu: v for imu, v in sensor.items() if v}
    if d.get("sysid") is not None and p.sysid is None:
        p.sysid = int(d["sysid"])
