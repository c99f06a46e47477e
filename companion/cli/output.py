"""Writing the CLI's files: one place that turns numpy values into JSON and OSError into a user error."""

from __future__ import annotations

import json

import numpy as np

from companion.errors import CompanionError


def json_default(o):
    """``json.dumps`` fallback for numpy scalars, booleans and arrays."""
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def to_json(obj, indent: int = 1) -> str:
    return json.dumps(obj, indent=indent, default=json_default)


def write_text(path, text: str, what: str = "file") -> None:
    """Write ``text`` to ``path``; a failure is a one-line :class:`CompanionError` naming the path."""
    try:
        with open(path, "w") as fh:
            fh.write(text)
    except OSError as exc:
        raise CompanionError(f"{path}: cannot write {what} ({exc.strerror or exc})") from None
