"""MAVLink facts the readers and the writer need: message ids, CRC_EXTRA, payload layouts.

A MAVLink frame (https://mavlink.io/en/guide/serialization.html):

- v1: ``FE len seq sysid compid msgid`` (6-byte header) + payload + CRC16 (little-endian)
- v2: ``FD len incompat compat seq sysid compid msgid[3]`` (10-byte header) + payload + CRC16
  (+ 13-byte signature when ``incompat & 0x01``). MAVLink 2 trims trailing zero bytes of the payload;
  the receiver pads it back to the full length with zeros before decoding.

The checksum is CRC-16/MCRF4XX ("X.25" in MAVLink's words: reflected polynomial 0x8408, init 0xFFFF, no
final xor) over every byte after the magic byte, then the message's CRC_EXTRA byte (a hash of the
message definition, so a frame of a different definition fails). Payload fields are little-endian and
sorted by type size (wire order = pymavlink's ``ordered_fieldnames``); extension fields follow in
declaration order and are not part of the v1 (base) length.

The IMU layouts below are written out (checked against pymavlink's dialect in tests); the CRC_EXTRA
of every other message (to validate frames we do not decode) comes from pymavlink's ardupilotmega
dialect, which is a superset of common.xml.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAGIC_V1 = 0xFE  #: start byte of a MAVLink 1 frame
MAGIC_V2 = 0xFD  #: start byte of a MAVLink 2 frame
HEADER_V1 = 6  #: header bytes of a MAVLink 1 frame, magic included
HEADER_V2 = 10  #: header bytes of a MAVLink 2 frame, magic included
SIGNATURE_LEN = 13  #: bytes a MAVLink 2 signature adds after the CRC
IFLAG_SIGNED = 0x01  #: the incompat flag of a signed MAVLink 2 frame


@dataclass(frozen=True)
class MessageLayout:
    """Wire layout of one MAVLink message: ``dtype`` is the full (v2, with extensions) payload."""

    name: str
    msgid: int
    crc_extra: int
    dtype: np.dtype  # little-endian structured dtype, fields in wire order
    base_len: int  # MAVLink 1 payload length (without extension fields)

    @property
    def full_len(self) -> int:
        return int(self.dtype.itemsize)


_IMU_INT16 = [("xacc", "<i2"), ("yacc", "<i2"), ("zacc", "<i2"),
              ("xgyro", "<i2"), ("ygyro", "<i2"), ("zgyro", "<i2"),
              ("xmag", "<i2"), ("ymag", "<i2"), ("zmag", "<i2")]

HEARTBEAT = MessageLayout(
    "HEARTBEAT", 0, 50,
    np.dtype([("custom_mode", "<u4"), ("type", "u1"), ("autopilot", "u1"), ("base_mode", "u1"),
              ("system_status", "u1"), ("mavlink_version", "u1")]),
    9)
RAW_IMU = MessageLayout(
    "RAW_IMU", 27, 144,
    np.dtype([("time_usec", "<u8")] + _IMU_INT16 + [("id", "u1"), ("temperature", "<i2")]),
    26)
SCALED_IMU = MessageLayout(
    "SCALED_IMU", 26, 170, np.dtype([("time_boot_ms", "<u4")] + _IMU_INT16 + [("temperature", "<i2")]), 22)
SCALED_IMU2 = MessageLayout(
    "SCALED_IMU2", 116, 76, np.dtype([("time_boot_ms", "<u4")] + _IMU_INT16 + [("temperature", "<i2")]), 22)
SCALED_IMU3 = MessageLayout(
    "SCALED_IMU3", 129, 46, np.dtype([("time_boot_ms", "<u4")] + _IMU_INT16 + [("temperature", "<i2")]), 22)
HIGHRES_IMU = MessageLayout(
    "HIGHRES_IMU", 105, 93,
    np.dtype([("time_usec", "<u8"),
              ("xacc", "<f4"), ("yacc", "<f4"), ("zacc", "<f4"),
              ("xgyro", "<f4"), ("ygyro", "<f4"), ("zgyro", "<f4"),
              ("xmag", "<f4"), ("ymag", "<f4"), ("zmag", "<f4"),
              ("abs_pressure", "<f4"), ("diff_pressure", "<f4"), ("pressure_alt", "<f4"),
              ("temperature", "<f4"), ("fields_updated", "<u2"), ("id", "u1")]),
    62)

#: The IMU messages we decode, by name and by id.
IMU_LAYOUTS = {m.name: m for m in (RAW_IMU, SCALED_IMU, SCALED_IMU2, SCALED_IMU3, HIGHRES_IMU)}
IMU_BY_ID = {m.msgid: m for m in IMU_LAYOUTS.values()}
LAYOUTS = dict(IMU_LAYOUTS, HEARTBEAT=HEARTBEAT)

#: Fixed instance number of the messages without an ``id`` field (SCALED_IMU2 is the 2nd IMU, ...).
FIXED_INSTANCE = {"SCALED_IMU": 0, "SCALED_IMU2": 1, "SCALED_IMU3": 2}

#: the HEARTBEAT a simulated vehicle sends: a quadrotor on ArduPilot, standing by
MAV_TYPE_QUADROTOR = 2
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_STATE_STANDBY = 3


def _dialect_crc_extras() -> dict[int, tuple[int, str, int, int]]:
    """{msgid: (crc_extra, name, base_len, full_len)} for every message of pymavlink's dialect."""
    out: dict[int, tuple[int, str, int, int]] = {}
    try:
        from pymavlink.dialects.v20 import ardupilotmega as dialect
    except ImportError:  # pragma: no cover - pymavlink is a runtime dependency
        dialect = None
    if dialect is not None:
        for msgid, cls in dialect.mavlink_map.items():
            full = int(cls.unpacker.size)
            out[int(msgid)] = (int(cls.crc_extra), cls.msgname, full, full)
    for m in LAYOUTS.values():  # our own table wins (and is checked against pymavlink in tests)
        out[m.msgid] = (m.crc_extra, m.name, m.base_len, m.full_len)
    return out


def _dialect_tables() -> dict:
    """CRC_INFO, MAX_MSGID, CRC_EXTRA_TABLE (CRC_EXTRA by message id; -1: unknown message, the frame cannot be
    validated) and MSG_NAMES."""
    info = _dialect_crc_extras()
    top = max(info)
    extra = np.full(top + 1, -1, dtype=np.int32)
    for mid, (crc_extra, _name, _base, _full) in info.items():
        extra[mid] = crc_extra
    return {"CRC_INFO": info, "MAX_MSGID": top, "CRC_EXTRA_TABLE": extra,
            "MSG_NAMES": {mid: v[1] for mid, v in info.items()}}


def __getattr__(name: str):
    """The dialect's tables, built on first use: importing pymavlink's dialect costs 0.1-0.2 s, which a CSV or
    DataFlash analysis never needs."""
    if name in ("CRC_INFO", "MAX_MSGID", "CRC_EXTRA_TABLE", "MSG_NAMES"):
        globals().update(_dialect_tables())
        return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _make_crc_table() -> np.ndarray:
    """Table of CRC-16/MCRF4XX (reflected poly 0x8408): crc' = (crc >> 8) ^ T[(crc ^ b) & 0xFF]."""
    table = np.zeros(256, dtype=np.uint16)
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x8408 if c & 1 else c >> 1
        table[i] = c
    return table


CRC_TABLE = _make_crc_table()


def _make_crc_table16() -> np.ndarray:
    """Two bytes at a time: with x = crc ^ (b0 | b1 << 8), the register after both bytes is T16[x]
    (a 16-bit register is fully shifted out by 16 bit steps, so the result depends on x only)."""
    c = np.arange(65536, dtype=np.uint32)
    for _ in range(16):
        c = np.where(c & 1, (c >> 1) ^ 0x8408, c >> 1)
    return c.astype(np.uint16)


CRC_TABLE16 = _make_crc_table16()


def crc_x25(data: bytes, crc: int = 0xFFFF) -> int:
    """Scalar CRC-16/MCRF4XX of ``data`` (for single frames; the reader uses :func:`crc_x25_rows`)."""
    for b in data:
        crc = (crc >> 8) ^ int(CRC_TABLE[(crc ^ b) & 0xFF])
    return crc


def crc_x25_rows(rows: np.ndarray, extra: np.ndarray | int) -> np.ndarray:
    """CRC of every row of a 2-D uint8 array followed by its CRC_EXTRA byte, column by column.

    ``rows`` is (n, L) uint8 (the bytes after the magic byte up to the end of the payload);
    ``extra`` is (n,) or a scalar. Returns (n,) uint16. Pairs of columns go through the 16-bit
    table (one xor and one lookup per two bytes), an odd last column and CRC_EXTRA through the
    8-bit table.
    """
    n, length = rows.shape
    crc = np.full(n, 0xFFFF, dtype=np.uint16)
    half = length // 2
    if half:
        words = np.ascontiguousarray(rows[:, :2 * half]).view("<u2").T.copy()  # contiguous columns
        t16 = CRC_TABLE16
        for j in range(half):
            crc = t16[crc ^ words[j]]
    table = CRC_TABLE
    if length % 2:
        crc = (crc >> 8) ^ table[(crc ^ rows[:, length - 1]) & 0xFF]
    crc = (crc >> 8) ^ table[(crc ^ np.asarray(extra, dtype=np.uint16)) & 0xFF]
    return crc


#: ArduPilot's gyro device-id parameters, per IMU instance (PARAM_VALUE in a tlog, PARM in a DataFlash log)
ARDUPILOT_GYRO_ID_PARAMS = {"INS_GYR_ID": 0, "INS_GYR2_ID": 1, "INS_GYR3_ID": 2}
ARDUPILOT_GYRO_ID_NAMES = {inst: name for name, inst in ARDUPILOT_GYRO_ID_PARAMS.items()}
