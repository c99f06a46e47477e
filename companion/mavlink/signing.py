"""MAVLink 2 message signing on a live link (``--signing-key FILE``).

With signing on, every frame we send carries a 13-byte signature (link id, 48-bit timestamp in 10 us
since 2015-01-01, the first 6 bytes of SHA-256(key + frame)), and a received frame is accepted only when
its signature checks out with the same key and its timestamp moves forward (replays are refused). This is
what ArduPilot does once signing is set up on it: it then drops unsigned frames (except RADIO_STATUS), so
a companion that does not sign is no longer heard.

The key is 32 bytes: a file holding them raw (``head -c 32 /dev/urandom > companion.key``) or as 64 hex
digits. The autopilot gets the same key through a SETUP_SIGNING message sent over a trusted link (USB),
e.g. MAVProxy ``signing setup PASSPHRASE`` (key = SHA-256 of the passphrase; write that key file with
``python3 -c "import hashlib,sys; sys.stdout.buffer.write(hashlib.sha256(b'PASSPHRASE').digest())" >
companion.key``) or Mission Planner's MAVLink Signing page. Details: docs/run.md#signed-links.

pymavlink does the signing and the checks (``mavfile.setup_signing``); frames it refuses come back as
BAD_DATA "Invalid signature", which :class:`companion.mavlink.link.LinkStats` counts as rejected.
"""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path

from companion.errors import CompanionError

KEY_LEN = 32  # bytes of a MAVLink 2 signing key (SETUP_SIGNING.secret_key)


def load_signing_key(path, warn=None) -> bytes:
    """The 32-byte key from ``path`` (raw bytes or 64 hex digits); one-line CompanionError otherwise.
    ``warn`` (a callable) is told when the file is readable by other users."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise CompanionError(f"--signing-key {path}: no such file") from None
    except OSError as exc:
        raise CompanionError(f"--signing-key {path}: cannot read ({exc.strerror or exc})") from None
    key = None
    if len(data) == KEY_LEN:
        key = data
    else:
        text = data.strip()
        try:
            if len(text) == 2 * KEY_LEN:
                key = bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            key = None
    if key is None:
        raise CompanionError(f"--signing-key {path}: expected a 32-byte key (32 raw bytes or 64 hex digits), "
                             f"got {len(data)} bytes")
    if warn is not None and sys.platform != "win32":
        try:
            if os.stat(p).st_mode & (stat.S_IRGRP | stat.S_IROTH):
                warn(f"signing key {path} is readable by other users (chmod 600 it)")
        except OSError:
            pass
    return key


class UnsignedFilter:
    """pymavlink's ``allow_unsigned_callback`` that lets unsigned frames through but never a wrongly signed
    one: pymavlink asks it for both, and a failed signature check shows as a rise of ``badsig_count``."""

    def __init__(self):
        self.bad_seen = 0

    def __call__(self, mav, msgid) -> bool:
        bad = mav.signing.badsig_count
        if bad != self.bad_seen:  # a signature was just checked and failed: refuse
            self.bad_seen = bad
            return False
        return True


def setup_signing(conn, key: bytes, accept_unsigned: bool = False) -> None:
    """Sign every frame sent on ``conn`` and accept only correctly signed frames (``accept_unsigned``:
    unsigned frames are let through too; wrongly signed ones never are). The connection must speak
    MAVLink 2 from the start (``open_connection(..., mavlink2=True)``): pymavlink would drop the signing
    state when it switches versions."""
    callback = UnsignedFilter() if accept_unsigned else None  # None: pymavlink refuses every unsigned frame
    conn.setup_signing(key, sign_outgoing=True, allow_unsigned_callback=callback)
