"""Who flew a log: the autopilot's board id, the IMU ids and the log's start time, from its metadata.

The readers find these while they read the IMU data (one pass over the file) and put them in
``LoadResult.meta["identity"]``; this module gives the fleet database one shape for every format:

- telemetry log (.tlog, :func:`companion.sources.tlog.identity`): ``AUTOPILOT_VERSION.uid`` (the board's
  64-bit unique id), the ``INS_GYR_ID``/``INS_GYR2_ID``/``INS_GYR3_ID`` ``PARAM_VALUE``s (IMU ids), and
  the first record's time stamp as the start time.
- DataFlash .bin (:func:`companion.sources.dataflash_meta.log_identity`): the boot banner logged as ``MSG``
  (e.g. ``Pixhawk4 0047002B 34385105 36363539``: the MCU's 96-bit unique id), the ``INS_GYR*_ID``
  parameters, and the start time from the first GPS record with a 3D fix (GPS week and ms, leap seconds
  applied) and the time since boot of the first IMU sample.
- ULog .ulg (:func:`companion.sources.ulog.identity`): the ``sys_uuid`` info field, the ``CAL_GYROn_ID``
  parameters, and the start time from the first GPS ``time_utc_usec``.
- CSV: nothing (no ids, no time of day): the vehicle is ``sys0`` unless ``--vehicle dir`` is used; the
  database then records the file's modification time as the start (``logs.start_source = 'mtime'``).

Missing metadata is simply absent (None / empty): never an error.
"""

from __future__ import annotations

EMPTY = {"board_id": None, "board": None, "imu_ids": {}, "start_time": None, "board_by_sysid": {}}


def tlog_identity(data: bytes) -> dict:
    """The identity of a tlog given as bytes (see :func:`companion.sources.tlog.identity`)."""
    from companion.sources import tlog

    return tlog.identity(tlog.scan(data))


def log_identity(meta: dict | None) -> dict:
    """The identity found by the reader (``LoadResult.meta``), with every key present."""
    found = (meta or {}).get("identity") or {}
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in EMPTY.items()}
    out.update({k: v for k, v in found.items() if v is not None})
    return out
