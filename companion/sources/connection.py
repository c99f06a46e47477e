"""Live MAVLink links through pymavlink, with the connection string checked first.

Accepted (pymavlink's syntax)::

    udpin:HOST:PORT    listen for UDP (e.g. udpin:0.0.0.0:14550, what a GCS forward sends to)
    udpout:HOST:PORT   send to / receive from a UDP peer
    udp:HOST:PORT      same as udpin
    tcp:HOST:PORT      connect to a TCP server (e.g. tcp:127.0.0.1:5760, SITL)
    tcpin:HOST:PORT    accept a TCP connection
    /dev/ttyACM0, /dev/serial/by-id/..., COM3   a serial device, with --baud (default 115200)

Anything else is refused with one clear line. Files are never handed to
``mavutil.mavlink_connection`` (it EXECUTES paths containing ``/bin/`` or ending ``.elf``): tlogs,
DataFlash logs, ULogs and CSVs are opened by :mod:`companion.sources.tlog`,
:mod:`companion.sources.dataflash`, :mod:`companion.sources.ulog` and :mod:`companion.sources.csvfile`.
"""

from __future__ import annotations

import os
import re
import sys

from companion.errors import CompanionError

NET_PREFIXES = ("udpin", "udpout", "udp", "tcp", "tcpin")
_NET = re.compile(r"^(udpin|udpout|udp|tcp|tcpin):([A-Za-z0-9.\-_]+|\[[0-9a-fA-F:]+\]):(\d{1,5})$")
_COM = re.compile(r"^COM\d{1,3}$", re.IGNORECASE)
DEFAULT_BAUD = 115200  #: a serial link's rate unless --baud says otherwise (ArduPilot's default telemetry rate)


def unknown_file(s: str) -> str:
    """The error of an existing file whose content none of the readers recognises."""
    return (f"{s}: unknown file type: its content is none of a tlog, a DataFlash .bin, a ULog .ulg or a CSV with a "
            "time_s header (each optionally gzip-compressed)")


def is_connection_string(spec: str) -> bool:
    """True if ``spec`` looks like a network link (prefix) or a serial device."""
    s = str(spec)
    return s.split(":", 1)[0].lower() in NET_PREFIXES or bool(_COM.match(s)) or s.startswith("/dev/")


def parse_connection(spec: str, baud: int | None = None) -> tuple[str, str]:
    """Validate ``spec``; returns (kind, canonical string) with kind ``net`` or ``serial``."""
    s = str(spec).strip()
    m = _NET.match(s)
    if m:
        port = int(m.group(3))
        if not 0 < port < 65536:
            raise CompanionError(f"{s}: port must be 1-65535")
        return "net", f"{m.group(1).lower()}:{m.group(2)}:{port}"
    if s.split(":", 1)[0].lower() in NET_PREFIXES:
        raise CompanionError(f"{s}: expected {s.split(':', 1)[0].lower()}:HOST:PORT, e.g. udpin:0.0.0.0:14550")
    if os.path.isfile(s):  # a file no reader took: said as every command says it, never opened as a link
        raise CompanionError(unknown_file(s))
    if "/bin/" in s or s.lower().endswith(".elf"):
        raise CompanionError(f"{s}: not a connection string or serial device")
    if _COM.match(s) or (s.startswith("/dev/") and re.match(r"^/dev/[A-Za-z0-9._/\-:]+$", s)):
        if s.startswith("/dev/") and not os.path.exists(s):
            raise CompanionError(f"{s}: no such serial device")
        if baud is not None and int(baud) <= 0:
            raise CompanionError(f"--baud must be positive, got {baud}")
        return "serial", s
    if os.path.isdir(s):  # the generic 'unknown source' would not say what is wrong with a folder
        raise CompanionError(f"{s}: is a directory; expected a log file (.tlog, .bin, .ulg, .csv, each optionally "
                             ".gz) or a connection string ('companion fleet analyze' takes directories of logs)")
    raise CompanionError(f"{s}: unknown source; expected a .tlog, DataFlash .bin, PX4 .ulg or .csv file (each "
                         "optionally .gz) or a connection string (udpin:HOST:PORT, udpout:, udp:, tcp:, tcpin:, "
                         "or a serial device with --baud)")


def _resolve(kind_prefix: str, host: str, port: int, spec: str) -> None:
    """A host name that does not resolve is one clear error line at once, not 'no IMU data' after listening."""
    import socket

    host = host.strip("[]")
    try:
        socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM if kind_prefix.startswith("udp") else socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise CompanionError(f"{spec}: cannot resolve host {host!r} ({getattr(exc, 'strerror', None) or exc})") from None


UDP_RCVBUF = 4 << 20  #: bytes: a few seconds of IMU messages at kHz rates (see _grow_receive_buffer)


def _grow_receive_buffer(conn) -> None:
    """Ask for a 4 MiB UDP receive buffer (the kernel caps it at net.core.rmem_max): a few seconds of IMU
    data survive a pause of this process instead of being dropped by the kernel."""
    import socket

    try:
        conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF)
    except (OSError, AttributeError):
        pass


def open_connection(spec: str, baud: int | None = None, source_system: int = 1, source_component: int = 191,
                    dialect: str = "ardupilotmega", retries: int = 3, mavlink2: bool = False, **kwargs):
    """Open a pymavlink link after :func:`parse_connection` accepted ``spec``.

    ``source_system``/``source_component`` identify us when we send (default compid 191 =
    MAV_COMP_ID_ONBOARD_COMPUTER; use the vehicle's sysid). ``robust_parsing`` is on, so corrupted bytes
    come back as BAD_DATA messages instead of exceptions. Extra ``kwargs`` go to
    ``mavutil.mavlink_connection`` (e.g. ``input=False`` for udpout). Returns the pymavlink connection.

    ``mavlink2``: use MAVLink 2 from the start (needed for signing, :mod:`companion.mavlink.signing`).
    Host names are resolved first; a ``tcp:`` server is tried ``retries`` more times a second apart (an
    autopilot still booting). Whatever pymavlink prints while connecting ("[Errno 111] Connection refused
    sleeping") is kept off stdout; a failure is one :class:`CompanionError` line.
    """
    import contextlib
    import io

    kind, s = parse_connection(spec, baud)
    if mavlink2:  # speak MAVLink 2 from the first frame (signing needs it; pymavlink reads this variable)
        os.environ["MAVLINK20"] = "1"
    if kind == "net":
        prefix, rest = s.split(":", 1)
        host, port = rest.rsplit(":", 1)
        if not (prefix in ("udpin", "udp", "tcpin") and host in ("0.0.0.0", "::", "[::]")):
            _resolve(prefix, host, int(port), s)
    from pymavlink import mavutil

    noise = io.StringIO()
    try:
        with contextlib.redirect_stdout(noise):
            conn = mavutil.mavlink_connection(s, baud=int(baud or DEFAULT_BAUD), source_system=source_system,
                                              source_component=source_component, dialect=dialect,
                                              robust_parsing=True, autoreconnect=kind == "serial",
                                              retries=retries, **kwargs)
        if s.startswith("udp"):
            _grow_receive_buffer(conn)
        return conn
    except Exception as exc:  # socket errors, serial errors: the user's link is not usable
        reason = (getattr(exc, "strerror", None) or str(exc).splitlines()[0]) if str(exc) else type(exc).__name__
        tries = f" after {max(retries, 1)} attempts" if s.startswith("tcp:") else ""
        raise CompanionError(f"{s}: cannot open link ({reason}){tries}") from None


def platform_serial_hint() -> str:
    return "COM3" if sys.platform.startswith("win") else "/dev/ttyACM0"
