"""MAVLink side of companion: the tlog writer (``tlog_writer``), reporting and the live link loop.

Adapters only: this package may import pymavlink; nothing numerical imports it.
"""
