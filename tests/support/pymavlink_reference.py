"""pymavlink as the independent reference decoder: every message of a tlog, as pymavlink reads it."""

from pymavlink import mavutil


def pymavlink_messages(path) -> list:
    """All messages pymavlink decodes from the tlog at ``path`` (mavlogfile, never mavlink_connection)."""
    log = mavutil.mavlogfile(str(path))
    out = []
    while True:
        m = log.recv_msg()
        if m is None:
            return out
        out.append(m)
