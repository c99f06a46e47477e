"""Source options that apply to one kind of source only: --time-unit (the time column of a CSV) and
--duration (how long to listen to a live link). Given for a source they do not apply to, each such option
gets one warning line on stderr and the work goes on.

A warning rather than a refusal: ``companion analyze a.csv b.tlog --time-unit ms`` is a sensible command
(the option applies to a.csv), and a script that passes the same options to every log should not fail on a
tlog; but a user who typed --time-unit for a tlog must learn that it changed nothing.
"""

from __future__ import annotations

import sys

#: dest -> (option, source kinds it applies to, how the warning names those kinds)
KIND_OPTIONS = {
    "time_unit": ("--time-unit", ("csv",), "CSV sources"),
    "duration": ("--duration", ("connection",), "live links (connection strings)"),
}


def ignored_option_warnings(args, sources) -> list[str]:
    """One sentence per option of :data:`KIND_OPTIONS` that is set on ``args`` and applies to none or only
    some of ``sources``. A source of unknown kind is not counted: loading it fails with its own error."""
    from companion.errors import CompanionError
    from companion.sources.kind import kind_of

    def kind(s) -> str:
        try:
            return kind_of(s)
        except CompanionError:  # an empty file, a Git LFS pointer: its own error when it is loaded, in its turn
            return "unknown"

    kinds = {str(s): kind(s) for s in sources}
    out = []
    for dest, (opt, applies, what) in KIND_OPTIONS.items():
        if getattr(args, dest, None) is None:
            continue
        off = [s for s, k in kinds.items() if k not in applies and k != "unknown"]
        if not off:
            continue
        on = [s for s, k in kinds.items() if k in applies]
        where = f" for {', '.join(off)}" if on else ""
        out.append(f"{opt} applies to {what} only: ignored{where}")
    return out


def warn_ignored_options(args, sources, command: str) -> None:
    """Print :func:`ignored_option_warnings` on stderr, one line each, as ``companion COMMAND: warning:``."""
    for text in ignored_option_warnings(args, sources):
        print(f"companion {command}: warning: {text}", file=sys.stderr)


def check_time_window(args) -> None:
    """--start/--end that cannot select anything (start at or after end, not a number) are refused before the
    log is read, in those words rather than as an empty selection after it."""
    import math

    from companion.errors import CompanionError

    start, end = getattr(args, "start", None), getattr(args, "end", None)
    for opt, v in (("--start", start), ("--end", end)):
        if v is not None and not math.isfinite(v):
            raise CompanionError(f"{opt} must be a number of seconds, got {v}")
    if start is not None and end is not None and start >= end:
        raise CompanionError(f"--start {start:g} is not before --end {end:g}: the time window is empty")
