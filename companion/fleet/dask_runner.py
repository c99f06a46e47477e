"""Run the per-log task over many logs: on Dask (a local cluster of processes, or a given scheduler) or
in this process, with one writer to the database and a progress line on stderr.

Flow: :func:`plan` turns the discovered files into work (content hashes: reused from the database when
the path's size and mtime are unchanged, else computed in threads; a hash already stored as ``ok`` --
or ``failed``, unless retried -- is skipped; a second copy of the same content in the batch is
skipped), then :func:`run_logs` submits :func:`companion.fleet.task.analyze_log` for each log, at most
``window`` in flight (the scheduler never holds a million futures), and records each result in its own
transaction as it arrives. A worker that dies (``KilledWorker``) or a task error is recorded as a
failed log with its one-line reason; the run goes on. Ctrl-C or ``deadline_s`` stops submitting,
cancels what is in flight (it is analysed again on the next run) and keeps every recorded log.
"""

from __future__ import annotations

import logging
import signal
import sys
import time
from dataclasses import dataclass, field
from typing import NamedTuple

from companion.errors import CompanionError
from companion.fleet.discover import LogFile, hash_files
from companion.fleet.task import analyze_log, analyze_logs, one_line
from companion.samples import GYRO_AXES

DASK_MISSING = ("fleet analyze runs on dask.distributed, which is not installed: "
                "pip install 'companion[fleet]' (or use --workers 0 to analyse in this process)")


@dataclass
class Work:
    log: LogFile
    hash: str
    replaces: str | None = None  # the hash of this path's earlier content, which the log grew from
    axes: tuple | None = None  # analysed for these axes (None: the run's); a log stored without some of them


@dataclass
class RunStats:
    total: int = 0  # logs given
    skipped: int = 0  # already in the database
    duplicates: int = 0  # the same content as another log of this run
    done: int = 0  # analysed and recorded ok in this run
    failed: int = 0  # analysed and recorded failed in this run
    elapsed_s: float = 0.0
    stopped: str = ""  # "", "interrupted" (Ctrl-C), "terminated" (SIGTERM) or "deadline"
    workers: int = 0
    batch: int = 1  # logs per Dask task
    failures: list = field(default_factory=list)  # (path, reason) of this run

    @property
    def rate(self) -> float:
        return (self.done + self.failed) / self.elapsed_s if self.elapsed_s > 0 else 0.0


class FleetProgress:
    """``fleet [#####.....] 120/1000 failed 3 | 4.2 logs/s | ETA 3:29`` on stderr: a fleet run's count, rate and ETA
    (the bar of one long computation is :class:`companion.cli.progress.Progress`).

    On a terminal the line is redrawn in place (at most 10 times a second); otherwise a line is written
    every ``every_s`` seconds and at the end, so a batch job's log shows progress too.
    """

    def __init__(self, total: int, skipped: int = 0, enabled: bool = True, stream=None, every_s: float = 10.0):
        self.stream = stream or sys.stderr
        self.total, self.skipped = total, skipped
        self.enabled = enabled
        self.tty = enabled and getattr(self.stream, "isatty", lambda: False)()
        self.t0 = time.monotonic()
        self.last = 0.0
        self.every_s = every_s
        self.done = self.failed = 0

    def line(self) -> str:
        n = self.done + self.failed
        el = time.monotonic() - self.t0
        rate = n / el if el > 0 else 0.0
        left = self.total - n
        eta = f"{int(left / rate) // 60}:{int(left / rate) % 60:02d}" if rate > 0 and left > 0 else "-"
        k = int(30 * n / self.total) if self.total else 30
        return (f"fleet [{'#' * k}{'.' * (30 - k)}] {n}/{self.total} done, {self.failed} failed"
                + (f", {self.skipped} skipped" if self.skipped else "") + f" | {rate:.2f} logs/s | ETA {eta}")

    def update(self, done: int, failed: int, force: bool = False) -> None:
        self.done, self.failed = done, failed
        if not self.enabled:
            return
        now = time.monotonic()
        if self.tty and (force or now - self.last >= 0.1):
            self.stream.write("\r" + self.line() + "  ")
            self.stream.flush()
            self.last = now
        elif not self.tty and (force or now - self.last >= self.every_s):
            self.stream.write(self.line() + "\n")
            self.stream.flush()
            self.last = now

    def close(self) -> None:
        if self.enabled:
            self.update(self.done, self.failed, force=True)
            if self.tty:
                self.stream.write("\n")
                self.stream.flush()


def hash_on_cluster(client, chunk: int = 100):
    """A ``hasher`` for :func:`plan` that hashes files on the Dask workers (where the storage is)."""
    from companion.fleet.discover import hash_chunk

    def hasher(paths, prefixes=None):
        parts = [paths[i:i + chunk] for i in range(0, len(paths), chunk)]
        futs = [client.submit(hash_chunk, part, {p: prefixes[p] for p in part if p in (prefixes or {})},
                              pure=False) for part in parts]
        out = {}
        for f in futs:
            out.update(f.result())
        return out

    return hasher


class Plan(NamedTuple):
    """What a run will do with the logs given (see :func:`plan`)."""

    work: list[Work]  # to analyse
    skipped: int  # already in the database
    unreadable: list[tuple[str, str]]  # (path, reason)
    duplicates: int  # the same content as another of the logs given


def plan(store, logs: list[LogFile], retry_failed: bool = False, threads: int = 4,
         hasher=None, axes=None) -> Plan:
    """(work to do, number already in the database, unreadable [(path, reason)], number of duplicates: the
    same content as another of ``logs``) for ``logs`` against ``store``.

    Content hashes come from the ``paths`` table when a path's size and mtime are unchanged, else from
    ``hasher(paths, prefixes) -> {path: hex, (hex, prefix hex) or "error: reason"}`` (default: threads in
    this process). A path that is longer than when it was recorded is hashed together with its first
    recorded-size bytes: when those are the recorded content, the log grew (copied off the vehicle while
    still being written, then again) and its new analysis replaces the partial one instead of standing
    beside it as another flight. A path whose content changed otherwise (a log number reused after the
    card was wiped) is a different log: both stay.

    ``axes``: the axes asked for. A log stored as ``ok`` without some of them is analysed again for its
    stored axes and the new ones (its rows replaced in one transaction), so ``--axes`` on an existing
    database is never silently ignored.
    """
    from companion.samples import AXES

    hashes: dict[str, str] = {}
    unknown, prefixes, previous = [], {}, {}
    for lf in logs:
        h = store.cached_hash(lf.path, lf.size, lf.mtime)
        if h:
            hashes[lf.path] = h
            continue
        unknown.append(lf.path)
        prev = store.path_record(lf.path)
        if prev is not None and prev[1] is not None and 0 < prev[1] < lf.size:
            prefixes[lf.path] = int(prev[1])
            previous[lf.path] = prev[0]
    if hasher is None:
        found = {p: (h if isinstance(h, (str, tuple)) else f"error: {getattr(h, 'strerror', None) or h}")
                 for p, h in hash_files(unknown, threads, prefixes).items()}
    else:
        found = (hasher(unknown, prefixes) if prefixes else hasher(unknown)) if unknown else {}
    unreadable, grown = [], {}
    for p in unknown:
        h = found.get(p, "error: not hashed")
        if isinstance(h, tuple):
            h, head = h
            if head is not None and head == previous.get(p):
                grown[p] = head
        if h.startswith("error: "):
            unreadable.append((p, "cannot read (" + h[7:] + ")"))
        else:
            hashes[p] = h
    work, seen, skipped, duplicates = [], set(), 0, 0
    for lf in logs:
        h = hashes.get(lf.path)
        if h is None:
            continue
        st = store.status(h)
        in_db = st == "ok" or (st == "failed" and not retry_failed)
        if h in seen and not in_db:
            duplicates += 1
            continue
        more = None
        if st == "ok" and axes:
            have = store.axes(h)
            if not set(axes) <= have:
                more = tuple(a for a in AXES if a in have or a in axes)
                in_db = False
        if in_db:
            skipped += 1
            if st is not None and store.cached_hash(lf.path, lf.size, lf.mtime) != h:
                # the grown content may already be recorded (under another path): the partial one goes
                store.remember_path(lf.path, h, lf.size, lf.mtime, grown.get(lf.path))
            continue
        seen.add(h)
        work.append(Work(lf, h, grown.get(lf.path), more))
    return Plan(work, skipped, unreadable, duplicates)


def _record(store, stats: RunStats, w: Work, result: dict) -> None:
    _record_many(store, stats, [(w, result)])


def _record_many(store, stats: RunStats, pairs) -> None:
    """Write the results of one task (one log, or a --batch of logs) in one transaction, then count them."""
    store.record_many([(w.hash, r, w.log.size, w.log.mtime, w.replaces) for w, r in pairs])
    for w, result in pairs:
        if result["status"] == "ok":
            stats.done += 1
        else:
            stats.failed += 1
            stats.failures.append((w.log.path, result.get("error") or "failed"))


def _failed(w: Work, reason: str) -> dict:
    from companion.fleet.discover import log_format

    return {"path": w.log.path, "format": log_format(w.log.path), "status": "failed", "error": reason,
            "log": {}, "rows": [], "elapsed_s": None}


def run_serial(store, work: list[Work], progress: FleetProgress, axes=GYRO_AXES, vehicle_from="auto",
               deadline_s: float | None = None) -> RunStats:
    """Analyse ``work`` one log after the other in this process (``--workers 0``; the benchmark's baseline)."""
    stats = RunStats(total=len(work), workers=0)
    t0 = time.monotonic()
    try:
        for w in work:
            if deadline_s is not None and time.monotonic() - t0 > deadline_s:
                stats.stopped = "deadline"
                break
            _record(store, stats, w, analyze_log(w.log.path, w.axes or axes, vehicle_from))
            progress.update(stats.done, stats.failed)
    except KeyboardInterrupt as exc:
        stats.stopped = _stopped_by(exc)
    stats.elapsed_s = time.monotonic() - t0
    return stats


def _stopped_by(exc: KeyboardInterrupt) -> str:
    from companion.errors import Terminated

    return "terminated" if isinstance(exc, Terminated) else "interrupted"


def open_client(workers: int | None = None, scheduler: str | None = None, timeout_s: float = 60.0):
    """(client, cluster or None): a LocalCluster of ``workers`` single-threaded processes on 127.0.0.1,
    or a client of the scheduler at ``scheduler`` (``tcp://HOST:8786``)."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise CompanionError(DASK_MISSING) from None
    for name in ("distributed", "distributed.nanny", "distributed.scheduler", "distributed.worker",
                 "distributed.core", "distributed.comm", "asyncio"):
        # shutting down on Ctrl-C, the scheduler and nannies in this process may log a closed connection with
        # its traceback (and asyncio a nanny whose worker was killed with the process group: "Task exception
        # was never retrieved"); what goes wrong with a log comes back as its task's exception and is recorded
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if scheduler:
        if "://" not in scheduler:
            scheduler = "tcp://" + scheduler
        try:
            return Client(scheduler, timeout=timeout_s), None
        except (OSError, TimeoutError) as exc:
            raise CompanionError(f"cannot reach the Dask scheduler at {scheduler} ({one_line(exc)})") from None
    n = int(workers or 0)
    if n < 1:
        raise CompanionError("--workers must be >= 1 for a Dask cluster (0 analyses in this process)")
    # Dask's nanny exports MALLOC_TRIM_THRESHOLD_=65536 to its workers; a fixed trim threshold also freezes
    # glibc's mmap threshold at 128 kB, so every array of a log is mmap'ed, unmapped and faulted in again:
    # measured 0.37 -> 0.68 CPU s per ten-minute log (13x the page faults). Unset it (None; after importing
    # distributed, whose defaults would come back otherwise); its one-BLAS-thread-per-worker settings stay.
    import dask

    dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None})
    # the workers' statistical profiler samples every thread's stack every 10 ms and keeps an hour of
    # profiles: CPU taken from the analysis and worker memory that grows through the first hour (measured
    # on 1,000 ten-minute logs: 0.433 CPU s per log and 174 -> 203 MB per worker with it). Nobody looks
    # at a dashboard here; a user's own scheduler (--scheduler) keeps its own settings.
    dask.config.set({"distributed.worker.profile.enabled": False})
    # the worker processes inherit an ignored SIGINT: a Ctrl-C (sent to the whole process group) is handled
    # by this process alone, which stops submitting and closes the cluster (no traceback from each worker)
    try:
        old_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread
        old_int = None
    try:
        # the workers' own logs at CRITICAL only: a worker whose heartbeat meets the scheduler closing (a
        # Ctrl-C on a loaded machine) logs an ERROR with a traceback, which the user would take for a crash;
        # a task's real failure reaches this process as its future's exception and is recorded per log
        before = _clusters()
        try:
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL)
        except BaseException as exc:
            # a cluster that failed half-way through its start (its workers killed by a SIGTERM to the process
            # group) is closed here, else distributed's exit hook tries again and prints a traceback
            for c in _clusters() - before:
                _close_quietly(c)
            if isinstance(exc, Exception):
                raise CompanionError(f"cannot start a local Dask cluster of {n} workers ({one_line(exc)})") \
                    from None
            raise
    finally:
        if old_int is not None:
            signal.signal(signal.SIGINT, old_int)
    try:
        client = Client(cluster, timeout=timeout_s)
    except BaseException:
        cluster.close()
        raise
    return client, cluster


#: --batch by default: about TASKS_PER_THREAD tasks per worker thread, at most MAX_AUTO_BATCH logs per task
TASKS_PER_THREAD = 100
MAX_AUTO_BATCH = 20


def auto_batch(n_logs: int, nthreads: int) -> int:
    """Logs per task when ``--batch`` is not given: 1 for small runs; for large ones enough that the
    scheduler's per-task cost (milliseconds) and one database transaction per task stay small against the
    analysis (a third of a second per ten-minute 100 Hz log), while the last tasks still finish together
    (about TASKS_PER_THREAD tasks per worker thread; 1,000 logs on 2 workers: 5 logs per task)."""
    return int(min(max(n_logs // (max(nthreads, 1) * TASKS_PER_THREAD), 1), MAX_AUTO_BATCH))


def run_dask(store, work: list[Work], progress: FleetProgress, client, axes=GYRO_AXES, vehicle_from="auto",
             deadline_s: float | None = None, window: int | None = None, batch: int | None = None) -> RunStats:
    """Analyse ``work`` on the Dask ``client``'s workers; this process is the only database writer.

    ``batch``: logs per task (None: :func:`auto_batch`; a large cluster wants tasks of tens of seconds,
    docs/fleet.md). ``window``: tasks in flight (default 4 per worker thread).
    """
    from dask.distributed import wait

    nthreads = max(sum(client.nthreads().values()), 1)
    stats = RunStats(total=len(work), workers=len(client.nthreads()))
    window = window or max(4 * nthreads, 8)
    batch = auto_batch(len(work), nthreads) if batch is None else max(int(batch), 1)
    stats.batch = batch
    t0 = time.monotonic()
    pending: dict = {}
    todo = iter(work)
    exhausted = False

    def fill():
        nonlocal exhausted
        while not exhausted and len(pending) < window:
            ws = [w for w in (next(todo, None) for _ in range(batch)) if w is not None]
            if not ws:
                exhausted = True
                return
            if batch == 1:
                fut = client.submit(analyze_log, ws[0].log.path, tuple(ws[0].axes or axes), vehicle_from, pure=False,
                                    retries=0)
            else:
                fut = client.submit(analyze_logs, [w.log.path for w in ws], [tuple(w.axes or axes) for w in ws],
                                    vehicle_from, pure=False, retries=0)
            pending[fut] = ws

    try:
        fill()
        while pending:
            if deadline_s is not None and time.monotonic() - t0 > deadline_s:
                stats.stopped = "deadline"
                break
            try:
                finished = wait(list(pending), timeout=0.5, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                finished = ()
            for fut in finished:
                ws = pending.pop(fut)
                try:
                    results = fut.result()
                    results = [results] if isinstance(results, dict) else results
                except Exception as exc:  # noqa: BLE001 - KilledWorker, lost connection: recorded, run goes on
                    results = [_failed(w, f"worker: {one_line(exc)}"[:500]) for w in ws]
                _record_many(store, stats, list(zip(ws, results)))
            progress.update(stats.done, stats.failed)
            fill()
    except KeyboardInterrupt as exc:
        stats.stopped = _stopped_by(exc)
    finally:
        if pending:
            try:
                client.cancel(list(pending))
            except Exception:  # noqa: BLE001 - shutting down anyway
                pass
    stats.elapsed_s = time.monotonic() - t0
    return stats


def _clusters() -> set:
    try:
        from distributed.deploy.spec import SpecCluster
    except ImportError:
        return set()
    return set(SpecCluster._instances)


def _close_quietly(cluster) -> None:
    """Close ``cluster``; whatever fails, distributed's exit hook is not to try again (its second attempt at
    a cluster whose workers were killed ends in a traceback at exit)."""
    try:
        cluster.close(timeout=20)
    except Exception:  # noqa: BLE001 - shutting down anyway
        pass
    finally:
        cluster.shutdown_on_close = False


def close_client(client, cluster) -> None:
    try:
        client.close(timeout=10)
    except Exception:  # noqa: BLE001
        pass
    if cluster is not None:
        _close_quietly(cluster)


def describe(stats: RunStats) -> str:
    s = (f"{stats.done} analysed, {stats.failed} failed, {stats.skipped} already in the database, "
         + (f"{stats.duplicates} duplicate(s) of another log given, " if stats.duplicates else "")
         + f"{stats.elapsed_s:.1f} s")
    if stats.done + stats.failed and stats.elapsed_s > 0:
        s += f" ({stats.rate:.2f} logs/s" + (f" on {stats.workers} workers)" if stats.workers else " in-process)")
    if stats.stopped:
        left = stats.total - stats.done - stats.failed
        s += f"; {stats.stopped}: {left} log(s) not analysed, run again to resume"
    return s


__all__ = ["plan", "hash_on_cluster", "run_serial", "run_dask", "auto_batch", "open_client", "close_client", "FleetProgress", "RunStats", "describe",
           "DASK_MISSING"]
