"""The simulated autopilot's frames built at once (companion.mavlink.imu_frames) are byte for byte what
pymavlink's own ``*_send`` calls write: the same messages, order, sequence numbers, trimming and CRCs."""

from __future__ import annotations

import os

import numpy as np
import pytest

from companion.mavlink.imu_frames import block_frames

G0 = 9.80665


def pymavlink_bytes(t, gyro, accel, temp, sending, hb_times, hb_armed, seq0):
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    out = []

    class F:
        def write(self, b):
            out.append(bytes(b))

    mav = mavlink.MAVLink(F(), srcSystem=7, srcComponent=1)
    mav.seq = seq0
    senders = (lambda k, a, g, c: mav.raw_imu_send(int(round(t[k] * 1e6)), *a, *g, 0, 0, 0, 0, c),
               lambda k, a, g, c: mav.scaled_imu2_send(int(round(t[k] * 1e3)), *a, *g, 0, 0, 0, c),
               lambda k, a, g, c: mav.scaled_imu3_send(int(round(t[k] * 1e3)), *a, *g, 0, 0, 0, c))
    ai = np.clip(np.rint(accel / (G0 * 1e-3)), -32768, 32767).astype(int).tolist()
    gi = np.clip(np.rint(gyro / 1e-3), -32768, 32767).astype(int).tolist()
    ci = (np.full(gyro.shape[:2], 4200) if temp is None else
          np.clip(np.rint(temp * 100.0), -32768, 32767)).astype(int).tolist()
    k = 0
    for j, th in enumerate(list(hb_times) + [np.inf]):
        while k < len(t) and t[k] < th:
            for i, on in enumerate(sending):
                if on:
                    senders[i](k, ai[i][k], gi[i][k], ci[i][k])
            k += 1
        if th != np.inf:
            mav.heartbeat_send(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                               0x81 if hb_armed[j] else 0x01, 0,
                               mavlink.MAV_STATE_ACTIVE if hb_armed[j] else mavlink.MAV_STATE_STANDBY)
    return out


@pytest.mark.parametrize("seed", range(4))
def test_block_frames_equal_pymavlink_send(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 120))
    t = 1.0 + np.sort(rng.uniform(0, 3.0, n))
    gyro = rng.normal(0, 0.05, (3, n, 3)) * rng.choice([0.0, 1.0, 1e4], (3, n, 3), p=[0.1, 0.8, 0.1])  # zeros, clipping
    accel = np.array([0.0, 0.0, -G0]) + rng.normal(0, 0.5, (3, n, 3))
    accel[:, :3] = 0.0  # trailing zero bytes trimmed differently
    temp = None if seed % 2 else 20.0 + rng.normal(0, 5, (3, n))
    sending = [True, bool(seed % 3), True]
    hb_times = np.arange(np.ceil(t[0]) - 1.0, t[-1] + 1.0, 1.0)  # before, inside and after the block
    hb_armed = rng.random(hb_times.size) < 0.5
    seq0 = int(rng.integers(0, 256))
    ref = pymavlink_bytes(t, gyro, accel, temp, sending, hb_times, hb_armed, seq0)
    buf, starts, kind = block_frames(t, gyro, accel, temp, sending, hb_times, hb_armed, seq0, 7, 1)
    got = [buf[a:b] for a, b in zip(starts[:-1].tolist(), starts[1:].tolist())]
    assert len(got) == len(ref) == n * sum(sending) + hb_times.size
    assert got == ref
    assert int(np.count_nonzero(kind == -1)) == hb_times.size
