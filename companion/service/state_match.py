"""A restored run state checked against the log it is about to take in: the same IMUs, each with the same
message and rate. Restored into another vehicle's (or another setup's) log, a state would report an IMU the
log does not have ("IMU2 healthy; 0 samples") and pool a 250 Hz stream's estimates with a 400 Hz one's; so a
difference is refused, named, with the way out (a new --state file, or --no-state)."""

from __future__ import annotations

import math

from companion.errors import CompanionError

#: relative rate difference taken for another rate (the rate tracker's figures of one stream agree far closer)
RATE_TOLERANCE = 0.05


def differences(channels: dict, streams) -> list[str]:
    """What differs between the restored channels ({imu: Channel}) and the source's streams, in words."""
    have = {s.key.instance: s for s in streams}
    out = []
    if set(have) != set(channels):
        out.append(f"IMUs: the state has {_imus(channels)}, the source {_imus(have)}")
    for imu in sorted(set(have) & set(channels)):
        ch, s = channels[imu], have[imu]
        if ch.message != s.key.message:
            out.append(f"IMU{imu}: message {ch.message} in the state, {s.key.message} in the source")
        rate, was = float(s.rate_hz), ch.rate_hz
        if was and math.isfinite(rate) and rate > 0 and abs(rate - was) > RATE_TOLERANCE * was:
            out.append(f"IMU{imu}: {was:.4g} Hz in the state, {rate:.4g} Hz in the source")
    return out


def state_check(pipeline, src, state):
    """``check(streams)`` for the replay of the log ``src`` (it hands over the streams it is about to feed, from
    its own reading of the log): refuses (one line) a restored state whose IMUs, messages or rates are not
    those streams'."""

    def check(streams) -> None:
        if not pipeline.channels:
            return
        diff = differences(pipeline.channels, streams)
        if diff:
            raise CompanionError(f"{src}: does not match the state file {state}: {'; '.join(diff)}; give a new "
                                 "--state file for this setup, or --no-state")

    return check


def _imus(keys) -> str:
    return ", ".join(f"IMU{k}" for k in sorted(keys)) or "none"
