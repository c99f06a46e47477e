"""The MAVLink 2 frames a simulated ArduPilot sends for a block of IMU samples and HEARTBEATs, built at once.

pymavlink packs one message per Python call (a message object, ``struct.pack``, the CRC): about 50 us a
message, which is most of what a loopback test's simulated autopilot spends (three IMUs at 100 Hz are 300
messages per simulated second). Here the block's payloads are numpy rows (:func:`imu_payloads`,
:func:`heartbeat_payload`) and the frames one :func:`encode_frames` call: the same bytes pymavlink's
``*_send`` would write, in the same order, with the same sequence numbers (tests/mavlink/test_imu_frames.py checks
them against pymavlink's own packing). Unsigned MAVLink 2 only; a signed link keeps pymavlink's path.
"""

from __future__ import annotations

import numpy as np

from companion.mavlink.tlog_writer import encode_frames, heartbeat_payload, imu_payloads
from companion.sim.vehicle_spec import IMU_MESSAGES  # IMU0, IMU1, IMU2 as ArduPilot sends them
from companion.sources import messages as M

DEFAULT_TEMPERATURE_C = 42.0  #: IMU temperature sent when the simulator has none (a warm autopilot board)


def block_frames(t, gyro, accel, temperature, sending, hb_times, hb_armed, seq0: int, sysid: int,
                 compid: int) -> tuple[bytes, np.ndarray, np.ndarray]:
    """The frames of one block in send order: at each sample time the IMUs in order (those whose
    ``sending[i]`` is true), and a HEARTBEAT before the first sample at or after each of ``hb_times``.

    ``t`` (n,) s since boot; ``gyro``/``accel`` (imus, n, 3) SI; ``temperature`` (imus, n) degC or None
    (then 42 C); ``hb_armed`` one bool per heartbeat time. Returns (the frames' bytes back to back, each
    frame's start offset, each frame's message name index: 0-2 the IMU, -1 a HEARTBEAT); the sequence
    numbers run from ``seq0``.
    """
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    imus = [i for i, on in enumerate(sending) if on]
    m = len(imus)
    hb_times = np.asarray(hb_times, dtype=np.float64)
    width = max(M.IMU_LAYOUTS[name].full_len for name in IMU_MESSAGES)
    total = n * m + hb_times.shape[0]
    payloads = np.zeros((total, width), dtype=np.uint8)
    msgid = np.empty(total, dtype=np.int64)
    extra = np.empty(total, dtype=np.uint16)
    kind = np.empty(total, dtype=np.int64)
    # position of each sample's first IMU frame and of each heartbeat in the merged order
    hb_before = np.searchsorted(t, hb_times, side="left")  # samples sent before heartbeat j
    hb_pos = hb_before * m + np.arange(hb_times.shape[0])
    is_hb = np.zeros(total, dtype=bool)
    is_hb[hb_pos] = True
    imu_rows = np.flatnonzero(~is_hb)  # k-major, IMU-minor
    for slot, i in enumerate(imus):
        layout = M.IMU_LAYOUTS[IMU_MESSAGES[i]]
        temp = DEFAULT_TEMPERATURE_C if temperature is None else temperature[i]
        rec = imu_payloads(layout.name, t, gyro[i], accel[i], instance=0, temperature=temp)
        rows = imu_rows[slot::m]
        payloads[rows, :layout.full_len] = rec.view(np.uint8).reshape(n, layout.full_len)
        msgid[rows] = layout.msgid
        extra[rows] = layout.crc_extra
        kind[rows] = i
    if hb_times.shape[0]:
        hb = heartbeat_payload(np.asarray(hb_armed, dtype=bool))
        payloads[hb_pos, :M.HEARTBEAT.full_len] = hb.view(np.uint8).reshape(-1, M.HEARTBEAT.full_len)
        msgid[hb_pos] = M.HEARTBEAT.msgid
        extra[hb_pos] = M.HEARTBEAT.crc_extra
        kind[hb_pos] = -1
    seq = ((seq0 + np.arange(total)) & 0xFF).astype(np.uint8)
    frames, flen = encode_frames(payloads, msgid, extra, seq, sysid, compid, mavlink2=True)
    keep = np.arange(frames.shape[1])[None, :] < flen[:, None]
    starts = np.zeros(total + 1, dtype=np.int64)
    np.cumsum(flen, out=starts[1:])
    return frames[keep].tobytes(), starts, kind
