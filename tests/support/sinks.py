"""A reporter sink that records what the pipeline sends, for the tests that feed a Pipeline directly."""

from __future__ import annotations


class RecordingSink:
    """``values``: the last NAMED_VALUE_FLOAT value per name; ``texts``: (severity, text) of every STATUSTEXT;
    ``msgs``: both in the order sent, ``(ms, name, value)`` and ``("T", severity, text)``."""

    def __init__(self):
        self.values, self.texts, self.msgs = {}, [], []

    def send_named_value_float(self, ms, name, value):
        self.values[name] = value
        self.msgs.append((ms, name, float(value)))

    def send_statustext(self, sev, text, time_boot_ms=None):
        self.texts.append((sev, text))
        self.msgs.append(("T", sev, text))
