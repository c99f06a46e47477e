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


# --- output paths, checked before any work (a bad path must not cost an hour's analysis) -------------------------------------------------
#: One rule for every file the CLI writes: the directory must already exist (nothing is created), the
#: path must not be a directory, and it must be writable. Checked before the work starts, so a typo costs
#: one line, not an analysis.
PLOT_FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")


def check_output_path(path, option: str) -> None:
    """Refuse (one :class:`CompanionError` line naming ``option``) a path that cannot be written."""
    import os

    p = os.fspath(path)
    if not p or p.endswith(os.sep):
        raise CompanionError(f"{option} {p!r}: expected a file name")
    if p == "-":  # only `gap --json -` writes to standard output (and never calls this); elsewhere a file named "-"
        raise CompanionError(f"{option} -: standard output is not supported here; give a file name (./- for a file "
                             "named '-')")
    if os.path.isdir(p):
        raise CompanionError(f"{option} {p}: is a directory; give a file name")
    parent = os.path.dirname(os.path.abspath(p))
    if not os.path.isdir(parent):
        what = "is not a directory" if os.path.exists(parent) else "does not exist"
        raise CompanionError(f"{option} {p}: directory {parent} {what} (create it first)")
    if os.path.exists(p):
        if not os.access(p, os.W_OK):
            raise CompanionError(f"{option} {p}: not writable")
    elif not os.access(parent, os.W_OK | os.X_OK):
        raise CompanionError(f"{option} {p}: directory {parent} is not writable")
    _probe(p, option)


def _probe(p: str, option: str) -> None:
    """Open the file for writing once (created and removed again when it was not there): os.access says yes
    to root everywhere, also in /proc or on a read-only mount, where the write would fail after the work."""
    import os

    existed = os.path.exists(p)
    if existed and not os.path.isfile(p):  # a FIFO would block until read, a device is the user's choice
        return
    try:
        with open(p, "a" if existed else "x"):
            pass
    except FileExistsError:  # made by someone else meanwhile: theirs, not ours to remove
        return
    except OSError as exc:
        raise CompanionError(f"{option} {p}: cannot write ({exc.strerror or exc})") from None
    if not existed:
        try:
            os.remove(p)
        except OSError:
            pass


def check_plot_path(path, option: str = "--plot") -> None:
    """An output path with an image format matplotlib writes, and matplotlib installed (without importing it)."""
    import importlib.util
    import os

    check_output_path(path, option)
    ext = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
    if ext not in PLOT_FORMATS:
        got = f"'.{ext}'" if ext else "no extension"
        raise CompanionError(f"{option} {path}: {got} is not a plot format; use one of "
                             + ", ".join("." + f for f in PLOT_FORMATS))
    if importlib.util.find_spec("matplotlib") is None:
        raise CompanionError("plotting needs matplotlib: pip install 'companion[plot]'")
