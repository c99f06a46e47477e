"""What the pipeline says after a fault was first reported: faults a restored state holds, said again when this
run's detectors confirm them, and a bias jump's size once the blocks after it are known."""

from __future__ import annotations

import math

from companion.health.faults import FaultEvent
from companion.health.hold import FAULT

CONFIRM_BLOCKS = 3  #: still blocks after a bias jump is flagged before its size is confirmed (their median)


def announce_restored(pipeline, ch, t: float) -> None:
    """The faults a restored state holds as active were said in the run that saved it, not in this one:
    those its detectors still hold after this run's first block are said again (STATUSTEXT and log, as
    when found), so that the next flight's ground station hears of a gyro that died in the last one. Only
    what describes the sensor (SENSOR_FAULTS): a saturation was the last run's motion, a bias fault is
    judged within a run."""
    for kind, ax in pipeline._restored.pop(ch.imu):
        if ch.faults.axes[ax].states().get(kind) != FAULT:
            continue
        ev = ch.faults.event_of(kind, ax)
        pipeline.log(f"IMU{ch.imu}: {ev.text()} (active when the state was saved)")
        pipeline._report([ev], t)


def confirm_bias(pipeline, ch, t: float) -> None:
    """A bias jump is flagged on the block that holds the step, often part-way (a 1 deg/s step half a
    block in is first sized 0.5 deg/s): after CONFIRM_BLOCKS more still blocks its size is known
    (health.bias: their median offset); when that differs by more than 10 % from what was said, say it
    again with the confirmed size."""
    for ax, af in ch.faults.axes.items():
        b = af.bias
        said = pipeline._bias_said.get((ch.imu, ax))
        if b.state != FAULT or said is None or len(b.post) != CONFIRM_BLOCKS or not math.isfinite(b.value):
            continue
        pipeline._bias_said.pop((ch.imu, ax), None)
        if abs(b.value - said) > 0.1 * abs(b.value):
            pipeline._report([FaultEvent(ch.imu, ax, "bias_jump", FAULT, b.value)], t)
