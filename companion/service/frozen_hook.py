"""The sample-level dead/frozen test (health/frozen_watch.py) in the pipeline: every accepted row of every
IMU goes to one :class:`~companion.health.frozen_watch.FrozenWatch` per vehicle, whatever the stream's rate
and whether or not its blocks are held back (a rate being learned, blocks off the rate); what it names is
held on the IMU's fault code as an external fault (``ImuFaults.set_external``), as a disagreement is, and
said once (STATUSTEXT, run log) unless the block tests already say the same."""

from __future__ import annotations

import numpy as np

from companion.health.faults import FAULT


def watch_rows(pipeline, ch, rows: np.ndarray) -> None:
    """Hand one IMU's rows ``(t, gx, gy, gz, ax, ay, az, ...)`` to the watch; report what it names."""
    events = pipeline.frozen.add(ch.imu, rows[:, 0], rows[:, 1:4], rows[:, 4:7])
    for ev in events:
        target = pipeline.channels.get(ev.imu)
        if target is None:
            continue
        own = (ev.kind, ev.axis) in target.faults.active() and (ev.kind, ev.axis) not in target.faults.external
        target.faults.set_external(ev.kind, ev.axis, ev.state)
        if ev.state == FAULT and own:  # the block tests said it already
            continue
        pipeline._report([ev], float(target.last_t or rows[-1, 0]))
    # a rate switch makes the IMU's detectors afresh: what the watch holds stays on its code
    for imu, other in pipeline.channels.items():
        for kind, ax in pipeline.frozen.active(imu):
            if other.faults.external.get((kind, ax)) != FAULT:
                other.faults.set_external(kind, ax, FAULT)
                pipeline._set_state(other)

