"""The sample-level dead/frozen test (health/frozen_watch.py) and clip test (health/clip_watch.py) in the pipeline: every accepted row of every
IMU goes to one :class:`~companion.health.frozen_watch.FrozenWatch` per vehicle, whatever the stream's rate
and whether or not its blocks are held back (a rate being learned, blocks off the rate); what it names is
held on the IMU's fault code as an external fault (``ImuFaults.set_external``), as a disagreement is, and
said once (STATUSTEXT, run log) unless the block tests already say the same.

The samples are judged at every block close of any IMU (:func:`say_frozen`; once a block, not once a sample,
for a live link at 400 Hz) and the events said with the message time of the sample that decided them: a
replay feeds the samples between two block closes in any order (service/replay.py), and what is sent must
not depend on that order."""

from __future__ import annotations

import numpy as np

from companion.health.hold import FAULT, OK


def watch_rows(pipeline, ch, rows: np.ndarray) -> None:
    """Hand one IMU's rows ``(t, gx, gy, gz, ax, ay, az, ...)`` to the watch; they are judged at
    :func:`say_frozen`."""
    pipeline.frozen.add(ch.imu, rows[:, 0], rows[:, 1:4], rows[:, 4:7])
    pipeline.clip.add(ch.imu, rows[:, 0], rows[:, 1:4])


def say_frozen(pipeline) -> None:
    """At a block close: the watch's events so far on the IMUs' fault codes, the log and STATUSTEXT."""
    clips = pipeline.clip.take()
    for t, ev in sorted(pipeline.frozen.judge() + clips, key=lambda te: te[0]):
        target = pipeline.channels.get(ev.imu)
        if target is None:
            continue
        own = (ev.kind, ev.axis) in target.faults.active() and (ev.kind, ev.axis) not in target.faults.external
        if ev.state == OK and own:  # the block test holds it: its own clear says when it ends
            continue
        target.faults.set_external(ev.kind, ev.axis, ev.state)
        if ev.kind == "saturation":
            if not own:  # the level quoted (ImuFaults.value_of)
                target.faults.axes[ev.axis].saturation.value = ev.value
        else:
            target.faults.external_detail[ev.axis] = ev.detail
        if ev.state == FAULT and own:  # the block tests said it already
            pipeline._set_state(target)
            continue
        pipeline.evidence.from_watch = ev if ev.kind != "saturation" else None  # the frozen watch's statistic
        if ev.state == FAULT:
            pipeline.watch_said.add((ev.imu, ev.kind, ev.axis))
        pipeline._report([ev], t)
    # a rate switch makes the IMU's detectors afresh: what the watch holds stays on its code
    for imu, other in pipeline.channels.items():
        for kind, ax in pipeline.frozen.active(imu) + pipeline.clip.active(imu):
            if other.faults.external.get((kind, ax)) != FAULT:
                other.faults.set_external(kind, ax, FAULT)
                if kind == "saturation":
                    other.faults.axes[ax].saturation.value = pipeline.clip.level(imu, ax)
                else:
                    other.faults.external_detail[ax] = pipeline.frozen.detail(imu, ax)
                pipeline._set_state(other)


def not_said_by_watch(pipeline, ch, events) -> list:
    """The block tests' events of one IMU less those the watch has said itself: a dead or stuck axis the watch
    announced and still holds is not announced again (or cleared) by the block test that comes to the same
    conclusion later. What the block tests said first, and their later words on it, stay theirs."""
    said = {(k, ax) for imu, k, ax in pipeline.watch_said
            if imu == ch.imu and ch.faults.external.get((k, ax)) == FAULT}
    return [ev for ev in events if (ev.kind, ev.axis) not in said]
