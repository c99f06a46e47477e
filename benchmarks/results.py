"""One results file for every benchmark: ``benchmarks/RESULTS.md``.

A benchmark's ``__main__`` block calls :func:`run` with its ``main``. Everything the benchmark prints goes to
the terminal as usual and, when ``main`` returns normally, replaces that benchmark's own section of
RESULTS.md (the other sections are kept): the script's name, the date, the machine (platform, CPU model,
cores), the exact command and the printed figures. ``--no-record`` on the command line (removed before the
benchmark parses its arguments) leaves RESULTS.md untouched; so does ``--help`` or an error exit.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import io
import os
import platform
import re
import shlex
import sys
from pathlib import Path
from typing import Callable

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
REPO = Path(__file__).resolve().parent.parent
#: the real recordings some benchmarks read (not in the repository): $COMPANION_SHARED_DATA, else ../shared/data
SHARED_DATA = Path(os.environ.get("COMPANION_SHARED_DATA", REPO.parent / "shared" / "data"))
NO_RECORD = "--no-record"  #: the switch that runs a benchmark without touching RESULTS.md

HEADER = """# Benchmark results

Written by the scripts in `benchmarks/` (`python -m benchmarks.NAME ...` from the repository root, through
`benchmarks/results.py`): each run that ends normally replaces its own section below with the date, the
machine, the exact command and what it printed. Rerun a command to refresh its section; `--help` of each
script says what it measures and its target, `--quick` gives the short run recorded here.

Times are from a shared 2-core machine (other processes ran beside the benchmarks): compare the ratios
printed side by side in the same run, not absolute times across sections.
"""

_BEGIN = "<!-- begin {} -->"
_END = "<!-- end {} -->"
_SECTION = re.compile(r"<!-- begin (.+?) -->.*?<!-- end \1 -->", re.S)


class _Tee(io.TextIOBase):
    """Writes to the real stream and keeps a copy."""

    def __init__(self, stream):
        self.stream = stream
        self.copy = io.StringIO()

    def write(self, s: str) -> int:
        self.copy.write(s)
        return self.stream.write(s)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return False


def machine() -> str:
    """Platform, CPU model and logical cores of this machine, one line."""
    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{platform.platform()}, {model}, {os.cpu_count()} logical cores, Python {platform.python_version()}"


def section(name: str, command: str, output: str, when: _dt.datetime | None = None) -> str:
    """The Markdown section of one benchmark run."""
    when = when or _dt.datetime.now(_dt.timezone.utc)
    body = output.rstrip("\n") or "(no output)"
    return "\n".join([
        _BEGIN.format(name),
        f"## {name}",
        "",
        f"- date: {when:%Y-%m-%d %H:%M} UTC",
        f"- machine: {machine()}",
        f"- command: `{command}`",
        "",
        "```text",
        body,
        "```",
        _END.format(name),
    ])


def replace_section(text: str, name: str, new: str) -> str:
    """``text`` with the section of ``name`` replaced by ``new`` (added if absent; sections sorted by name)."""
    sections = {m.group(1): m.group(0) for m in _SECTION.finditer(text)}
    sections[name] = new
    return HEADER + "\n" + "\n\n".join(sections[k] for k in sorted(sections)) + "\n"


def record(name: str, command: str, output: str) -> None:
    """Replace the section of ``name`` in RESULTS.md."""
    text = RESULTS.read_text() if RESULTS.exists() else ""
    RESULTS.write_text(replace_section(text, name, section(name, command, output)))


def run(main: Callable[[], int | None], name: str | None = None) -> int:
    """Run a benchmark's ``main`` with its printed output recorded in RESULTS.md; returns the exit code.

    ``name`` is the section's name, by default the module's (``bench_fit``); a benchmark with modes passes
    e.g. ``"bench_fit draws"`` so that each mode keeps its own section.
    """
    module = Path(sys.argv[0]).stem
    name = name or module
    keep = NO_RECORD not in sys.argv[1:]
    sys.argv = [a for a in sys.argv if a != NO_RECORD]
    command = " ".join(["python -m", f"benchmarks.{module}", *map(shlex.quote, sys.argv[1:])])
    tee = _Tee(sys.stdout)
    sys.stdout = tee
    try:
        rc = main()
    finally:
        sys.stdout = tee.stream
    rc = int(rc or 0)
    if keep and rc == 0:
        record(name, command, tee.copy.getvalue())
        print(f"(recorded in {RESULTS})")
    return rc


def parse_args(ap: argparse.ArgumentParser, quick: dict, argv: list[str] | None = None) -> argparse.Namespace:
    """``ap.parse_args(argv)`` with a ``--quick`` switch whose defaults are ``quick`` (explicit options win)."""
    shown = ", ".join(f"--{k.replace('_', '-')} {' '.join(map(str, v)) if isinstance(v, list) else v}"
                      for k, v in quick.items())
    ap.add_argument("--quick", action="store_true", help=f"the short run recorded in RESULTS.md ({shown})")
    argv = sys.argv[1:] if argv is None else argv
    if "--quick" in argv:
        ap.set_defaults(**quick)
    return ap.parse_args(argv)
