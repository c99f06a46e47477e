"""One ``fleet analyze`` run end to end: the options, the Dask client's life, the plan, the run, the outcome.

:func:`analyze_fleet` opens the database, opens a Dask client (an existing scheduler's, or a local cluster
once there is work), plans the work (:func:`companion.fleet.dask_runner.plan`), runs it (serially with
``workers=0``, else on Dask) and closes the client; the command line only parses and prints.
SIGTERM stops the run like Ctrl-C (:class:`TermSignal`).
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
from dataclasses import dataclass

from companion.errors import EXIT_FAULTS, EXIT_INTERRUPTED, EXIT_NO_DATA, CompanionError, Terminated
from companion.errors import EXIT_TIME_LIMIT as EXIT_DEADLINE
from companion.samples import AXES

#: unreadable or failed logs listed one per line; the rest are counted (the HTML report lists them all)
LISTED = 10


class TermSignal:
    """SIGTERM (a batch system's time limit, ``kill``, systemd) stops the run like Ctrl-C -- what is recorded
    stays, the next run resumes -- and exits 143 (:class:`companion.errors.Terminated`). While the local
    cluster starts or closes the signal is held and acted on right after: raised in the middle of
    distributed's start-up it would leave a half-made cluster whose clean-up at exit prints tracebacks."""

    def __init__(self):
        self.hold = 0
        self.pending = False
        try:
            self.old = signal.signal(signal.SIGTERM, self._handler)
        except ValueError:  # not the main thread
            self.old = None

    def _handler(self, signum, frame):
        if self.hold:
            self.pending = True
            return
        raise Terminated

    @contextlib.contextmanager
    def held(self):
        self.hold += 1
        try:
            yield
        except Exception:
            if self.pending:  # the start failed because the signal killed the workers too
                raise Terminated from None
            raise
        finally:
            self.hold -= 1
        if self.pending and not self.hold:
            raise Terminated

    def restore(self) -> None:
        if self.old is not None:
            signal.signal(signal.SIGTERM, self.old)


@dataclass
class AnalyzeOptions:
    """What ``fleet analyze`` was asked to do (see its help)."""

    logs: list[str]
    db: str
    axes_spec: str = "gx,gy,gz"
    workers: int | None = None  # None: one per CPU core; 0: in this process
    scheduler: str | None = None
    vehicle: str = "auto"
    batch: int | None = None
    retry_failed: bool = False
    time_limit: float | None = None
    quiet: bool = False

    @property
    def axes(self) -> tuple[str, ...]:
        return tuple(a.strip() for a in self.axes_spec.split(",") if a.strip())

    def check(self) -> None:
        """One error line for a value out of range."""
        if not self.axes or any(a not in AXES for a in self.axes):
            raise CompanionError(f"bad --axes {self.axes_spec!r}: expected a comma list of {', '.join(AXES)}")
        if self.batch is not None and self.batch < 1:
            raise CompanionError("--batch must be >= 1")
        if self.workers is not None and self.workers < 0:
            raise CompanionError("--workers must be >= 0")
        if self.time_limit is not None and not (self.time_limit > 0 and math.isfinite(self.time_limit)):
            raise CompanionError("--time-limit must be a positive number of seconds")


@dataclass
class AnalyzeOutcome:
    """What a run did: its statistics (None when there was nothing to analyse) and the database's counts."""

    stats: object | None  # companion.fleet.dask_runner.RunStats
    counts: dict[str, int]
    faults: bool = False  #: the database holds a gyro found dead, stuck or saturated

    def exit_code(self) -> int:
        """Stopped early (130, 143, 3), else a faulty gyro in the database (4), else no log analysed at all (5),
        else 0 (README "Exit status")."""
        stopped = self.stats.stopped if self.stats is not None else ""
        code = {"interrupted": EXIT_INTERRUPTED, "terminated": Terminated.exit_code,
                "deadline": EXIT_DEADLINE}.get(stopped, 0)
        if code:
            return code
        if self.faults:
            return EXIT_FAULTS
        return EXIT_NO_DATA if not self.counts.get("ok") else 0

    def failure_lines(self) -> list[str]:
        if self.stats is None:
            return []
        fails = self.stats.failures
        lines = [f"failed: {path}: {reason}" for path, reason in fails[:LISTED]]
        if len(fails) > LISTED:
            lines.append(f"... and {len(fails) - LISTED} more failed (fleet report --html lists them)")
        return lines


def plan_summary(n_logs: int, todo, db: str, axes) -> str:
    """The line that says what a run will do (``todo``: :class:`companion.fleet.dask_runner.Plan`) before it starts."""
    more = sum(w.axes is not None for w in todo.work)
    return (f"{n_logs} log(s): {len(todo.work)} to analyse"
            + (f" ({more} of them stored before without some of the axes {','.join(axes)})" if more else "")
            + f", {todo.skipped} already in {db}"
            + (f", {todo.duplicates} duplicate(s) (the same content as another log given)" if todo.duplicates else "")
            + (f", {len(todo.unreadable)} unreadable" if todo.unreadable else ""))


@dataclass
class _Client:
    """The Dask client of a run and the local cluster it opened (None: none yet, or an existing scheduler)."""

    client: object | None = None
    cluster: object | None = None


def analyze_fleet(opts: AnalyzeOptions, say) -> AnalyzeOutcome:
    """Run ``fleet analyze`` (module docstring); ``say(line)`` is told what the run will do before it starts
    (unreadable logs, then :func:`plan_summary`)."""
    from companion.fleet.discover import discover
    from companion.fleet.dask_runner import FleetProgress, close_client, hash_on_cluster, open_client, plan
    from companion.fleet.store import FleetStore

    logs = discover(opts.logs)
    held = _Client()
    term = TermSignal()
    try:
        with FleetStore(opts.db) as store:
            hasher = None
            if opts.scheduler:  # a cluster: hash the files on the workers, next to the storage
                with term.held():
                    held.client, held.cluster = open_client(None, opts.scheduler)
                hasher = hash_on_cluster(held.client)
            todo = plan(store, logs, retry_failed=opts.retry_failed, hasher=hasher, axes=opts.axes)
            for path, reason in todo.unreadable[:LISTED]:
                say(f"warning: {path}: {reason}; skipped")
            say(plan_summary(len(logs), todo, opts.db, opts.axes))
            progress = FleetProgress(len(todo.work), todo.skipped + todo.duplicates, enabled=not opts.quiet)
            stats = _run(opts, store, todo.work, progress, held, term)
            if stats is not None:
                progress.close()
                stats.skipped, stats.duplicates = todo.skipped, todo.duplicates
            return AnalyzeOutcome(stats, store.counts(), store.has_faults())
    finally:
        try:
            if held.client is not None:
                with term.held():
                    close_client(held.client, held.cluster)
        finally:
            term.restore()


def _run(opts: AnalyzeOptions, store, work, progress, held: _Client, term: TermSignal):
    """The planned ``work``: in this process with ``workers=0`` (and no scheduler), else on Dask (a local
    cluster of ``workers`` processes opened here when no scheduler was given). None without work."""
    from companion.fleet.dask_runner import open_client, run_dask, run_serial

    if not work:
        return None
    if opts.workers == 0 and not opts.scheduler:
        return run_serial(store, work, progress, opts.axes, opts.vehicle, opts.time_limit)
    if held.client is None:
        with term.held():
            held.client, held.cluster = open_client(opts.workers or os.cpu_count() or 1, None)
    return run_dask(store, work, progress, held.client, opts.axes, opts.vehicle, opts.time_limit, batch=opts.batch)
