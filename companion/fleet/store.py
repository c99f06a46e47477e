"""The fleet results database: SQLite (standard library), one writer, one transaction per log.

Schema (``SCHEMA``; documented with examples in docs/fleet.md):

- ``meta(key, value)``: ``schema_version``.
- ``logs``: one row per log *content* (``hash`` = BLAKE2b-128 of the bytes, primary key): ``path``,
  ``size``, ``mtime``, ``format``, ``sysid``, ``vehicle``, ``board_id``, ``imu_ids`` (JSON
  ``{"0": 2359586}``), ``start_time`` (unix s) and ``start_source`` (``log`` or ``mtime``), ``duration_s``,
  ``streams``, ``status`` (``ok`` / ``failed``), ``error`` (one line), ``analyzed_at``, ``elapsed_s``,
  ``version`` (companion's).
- ``results``: one row per (log, vehicle, IMU, axis), primary key (hash, sysid, compid, message, imu,
  axis): ``status``/``note`` of the axis, ``rate_hz``, ``samples``, ``still_s`` (seconds analysed),
  ``temp_min``/``temp_max`` (degC), every linear IEEE 952 term ``Q N B K R`` in SI with its 95 %
  interval ``*_lo``/``*_hi`` (NULL when the fit did not select the term), ``model_error``, ``chi2``,
  ``dof``, ``extra`` (JSON: Gauss-Markov / sinusoid terms with their intervals; the 95 % upper bounds of a
  condition's terms not resolved) and ``condition`` (``still``, ``ground`` or ``flight``: the key holds it;
  ``still_s`` is then the seconds of that condition). A schema-1 database (no condition) is migrated on
  opening: its rows are still rows.
- ``paths``: every path a content was seen under (a copied log is recognised, not re-analysed).

Idempotent: :meth:`FleetStore.record` writes a log and all its rows in one transaction, replacing a
failed attempt of the same content; a hash already stored as ``ok`` is never analysed again.
WAL journal: readers (``fleet report``) do not block the writer. An interrupted run leaves every
committed log intact; the logs in flight are simply not there and are analysed on the next run.
"""

from __future__ import annotations

import json
import sqlite3
import time

from companion.errors import CompanionError

SCHEMA_VERSION = 2  #: stored in the database; a database of another version is refused, not misread
#: older schemas this one migrates on opening (1: no ``condition`` column; its rows are still data)
MIGRATES = ("1",)
#: the conditions a result row is for: still (disarmed, not moving), ground (armed, not moving), flight
CONDITIONS = ("still", "ground", "flight")
PARAMS = ("Q", "N", "B", "K", "R")  #: the coefficients stored per axis

SCHEMA = f"""
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE IF NOT EXISTS logs (
    hash TEXT PRIMARY KEY,
    path TEXT NOT NULL,
    size INTEGER,
    mtime REAL,
    format TEXT,
    sysid INTEGER,
    vehicle TEXT,
    board_id TEXT,
    imu_ids TEXT,
    start_time REAL,
    start_source TEXT,
    duration_s REAL,
    streams INTEGER,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    error TEXT,
    analyzed_at REAL,
    elapsed_s REAL,
    version TEXT
);
CREATE INDEX IF NOT EXISTS logs_vehicle ON logs (vehicle, start_time);
CREATE TABLE IF NOT EXISTS paths (
    path TEXT PRIMARY KEY,
    hash TEXT NOT NULL,
    size INTEGER,
    mtime REAL
);
CREATE TABLE IF NOT EXISTS results (
    hash TEXT NOT NULL REFERENCES logs (hash) ON DELETE CASCADE,
    vehicle TEXT NOT NULL,
    sysid INTEGER NOT NULL,
    compid INTEGER NOT NULL,
    imu INTEGER NOT NULL,
    message TEXT NOT NULL,
    axis TEXT NOT NULL,
    status TEXT NOT NULL,
    note TEXT,
    rate_hz REAL,
    samples INTEGER,
    still_s REAL,
    temp_min REAL,
    temp_max REAL,
    {", ".join(f"{p} REAL, {p}_lo REAL, {p}_hi REAL" for p in PARAMS)},
    model_error REAL,
    chi2 REAL,
    dof INTEGER,
    extra TEXT,
    condition TEXT NOT NULL DEFAULT 'still',
    PRIMARY KEY (hash, sysid, compid, message, imu, axis, condition)
);
CREATE INDEX IF NOT EXISTS results_imu ON results (vehicle, imu, axis);
"""

RESULT_COLUMNS = (["hash", "vehicle", "sysid", "compid", "imu", "message", "axis", "status", "note", "rate_hz",
                   "samples", "still_s", "temp_min", "temp_max"]
                  + [c for p in PARAMS for c in (p, p + "_lo", p + "_hi")]
                  + ["model_error", "chi2", "dof", "extra", "condition"])


def _migrate(con, version: str) -> None:
    """Schema 1 -> 2: the results table rebuilt with ``condition`` (``still`` for every old row) in its key."""
    old = [c for c in RESULT_COLUMNS if c != "condition"]
    with con:
        con.execute("ALTER TABLE results RENAME TO results_v1")
        con.execute("DROP INDEX IF EXISTS results_imu")
        con.executescript(SCHEMA)
        con.execute(f"INSERT INTO results ({', '.join(old)}, condition) SELECT {', '.join(old)}, 'still' "
                    "FROM results_v1")
        con.execute("DROP TABLE results_v1")
        con.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),))


class FleetStore:
    """The database at ``path`` (created with its schema when missing). Use from one process/thread."""

    def __init__(self, path, create: bool = True):
        import os

        self.path = str(path)
        if os.path.isdir(self.path):
            raise CompanionError(f"{self.path}: is a directory; give the database file")
        if not create and not os.path.isfile(self.path):
            raise CompanionError(f"{self.path}: no such database (run `companion fleet analyze ... --db {self.path}`)")
        try:
            self.con = sqlite3.connect(self.path, timeout=30.0)
            self.con.execute("PRAGMA foreign_keys = ON")
            tables = {t for (t,) in self.con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            version = self.con.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone() \
                if "meta" in tables else None
            if tables and version is None:
                # another program's database: adding our tables to it would change a file that is not ours
                self.con.close()
                raise CompanionError(f"{self.path}: not a fleet database (an SQLite database with tables "
                                     f"{', '.join(sorted(tables)[:5])}{', ...' if len(tables) > 5 else ''}); "
                                     "give a new file or one written by fleet analyze")
            if version is not None and str(version[0]) in MIGRATES:
                _migrate(self.con, str(version[0]))
                version = (str(SCHEMA_VERSION),)
            if version is not None and str(version[0]) != str(SCHEMA_VERSION):
                self.con.close()
                raise CompanionError(f"{self.path}: fleet database schema {version[0]}, "
                                     f"this companion reads {SCHEMA_VERSION}")
            if create:
                self.con.execute("PRAGMA journal_mode = WAL")
                self.con.execute("PRAGMA synchronous = NORMAL")
                with self.con:
                    self.con.executescript(SCHEMA)
                    self.con.execute("INSERT OR IGNORE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
            row = self.con.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
        except sqlite3.DatabaseError as exc:
            raise CompanionError(f"{self.path}: not a fleet database ({exc})") from None
        if row is None or str(row[0]) != str(SCHEMA_VERSION):
            raise CompanionError(f"{self.path}: fleet database schema {row[0] if row else 'missing'}, "
                                 f"this companion reads {SCHEMA_VERSION}")

    def close(self) -> None:
        self.con.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    # ---- what is known -------------------------------------------------------------------------
    def cached_hash(self, path: str, size: int, mtime: float) -> str | None:
        """The content hash recorded for this path if its size and mtime are unchanged (no re-hashing)."""
        r = self.con.execute("SELECT hash FROM paths WHERE path = ? AND size = ? AND mtime = ?",
                             (path, size, mtime)).fetchone()
        return r[0] if r else None

    def path_record(self, path: str) -> tuple | None:
        """(hash, size, mtime) last recorded for ``path``, whatever its size and mtime are now."""
        return self.con.execute("SELECT hash, size, mtime FROM paths WHERE path = ?", (path,)).fetchone()

    def drop_superseded(self, old: str, path: str) -> bool:
        """Remove the log ``old`` (its row and results): the earlier, shorter content of ``path``, which has
        grown since (a log copied off the vehicle while it was still being written). Kept when another path
        still holds that content (a copy of the partial log is a log of its own). Returns whether removed.
        Call inside a transaction."""
        other = self.con.execute("SELECT 1 FROM paths WHERE hash = ? AND path != ? LIMIT 1", (old, path)).fetchone()
        if other:
            return False
        self.con.execute("DELETE FROM results WHERE hash = ?", (old,))
        self.con.execute("DELETE FROM logs WHERE hash = ?", (old,))
        return True

    def status(self, h: str) -> str | None:
        r = self.con.execute("SELECT status FROM logs WHERE hash = ?", (h,)).fetchone()
        return r[0] if r else None

    def axes(self, h: str) -> set[str]:
        """The axes a log was analysed for (every analysed stream has a row per requested axis)."""
        return {a for (a,) in self.con.execute("SELECT DISTINCT axis FROM results WHERE hash = ?", (h,))}

    def statuses(self) -> dict[str, str]:
        return dict(self.con.execute("SELECT hash, status FROM logs"))

    def remember_path(self, path: str, h: str, size: int, mtime: float, replaces: str | None = None) -> None:
        """Record that ``path`` holds content ``h`` (already stored); ``replaces``: the earlier content it
        grew from, removed in the same transaction (:meth:`drop_superseded`)."""
        with self.con:
            if replaces and replaces != h:
                self.drop_superseded(replaces, path)
            self.con.execute("INSERT OR REPLACE INTO paths VALUES (?, ?, ?, ?)", (path, h, size, mtime))

    def counts(self) -> dict:
        c = dict(self.con.execute("SELECT status, COUNT(*) FROM logs GROUP BY status"))
        return {"ok": c.get("ok", 0), "failed": c.get("failed", 0)}

    # ---- the one writer ------------------------------------------------------------------------
    def record(self, h: str, result: dict, size: int | None = None, mtime: float | None = None) -> None:
        """Store one analysed log (a :func:`companion.fleet.task.analyze_log` result) in one transaction."""
        with self.con:
            self._write(h, result, size, mtime)

    def record_many(self, items) -> None:
        """Store several ``(hash, result, size, mtime[, replaces])`` in one transaction (a ``--batch`` task's
        logs); ``replaces``: the hash of the log's earlier, shorter content, removed in the same transaction
        (:meth:`drop_superseded`)."""
        with self.con:
            for item in items:
                self._write(*item)

    def _write(self, h: str, result: dict, size, mtime, replaces: str | None = None) -> None:
        from companion import __version__

        if replaces and replaces != h:
            self.drop_superseded(replaces, result["path"])

        log = result.get("log") or {}
        start, source = log.get("start_time"), "log"
        if start is None:
            start, source = mtime, "mtime"
        self.con.execute("DELETE FROM results WHERE hash = ?", (h,))
        self.con.execute(
            "INSERT OR REPLACE INTO logs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (h, result["path"], size, mtime, result.get("format"), log.get("sysid"), log.get("vehicle"),
             log.get("board_id"), json.dumps({str(k): v for k, v in (log.get("imu_ids") or {}).items()}),
             start, source if start is not None else None, log.get("duration_s"), log.get("streams"),
             result["status"], result.get("error"), time.time(), result.get("elapsed_s"), __version__))
        rows = []
        for r in result.get("rows", []):
            vals = [h] + [r.get(c) for c in RESULT_COLUMNS[1:]]
            vals[-2] = json.dumps(r["extra"]) if r.get("extra") else None
            vals[-1] = r.get("condition") or "still"
            rows.append(vals)
        if rows:
            self.con.executemany(f"INSERT INTO results VALUES ({', '.join('?' * len(RESULT_COLUMNS))})", rows)
        if size is not None:
            self.con.execute("INSERT OR REPLACE INTO paths VALUES (?, ?, ?, ?)", (result["path"], h, size, mtime))

    # ---- queries -------------------------------------------------------------------------------
    def imus(self) -> list[tuple]:
        """Every (vehicle, sysid, compid, message, imu) with results."""
        return self.con.execute("SELECT DISTINCT vehicle, sysid, compid, message, imu FROM results "
                                "ORDER BY vehicle, sysid, compid, message, imu").fetchall()

    def history(self, vehicle: str, imu: int, axis: str | None = None) -> list[dict]:
        """One IMU's results across flights, oldest first: dicts with the log's start time and path."""
        q = ("SELECT r.*, l.start_time, l.path FROM results r JOIN logs l ON l.hash = r.hash "
             "WHERE r.vehicle = ? AND r.imu = ?" + (" AND r.axis = ?" if axis else "") +
             " ORDER BY l.start_time, l.path, r.message, r.axis")
        cur = self.con.execute(q, (vehicle, imu, axis) if axis else (vehicle, imu))
        names = [d[0] for d in cur.description]
        return [dict(zip(names, row)) for row in cur]

    #: vehicles named by their folder (``--vehicle dir``) whose analysed logs come from more than one board
    _SPLIT = ("SELECT vehicle, board_id FROM logs WHERE status = 'ok' AND board_id IS NOT NULL "
              "AND vehicle != board_id AND vehicle != 'sys' || sysid AND vehicle IN ("
              "SELECT vehicle FROM logs WHERE status = 'ok' AND board_id IS NOT NULL AND vehicle != board_id "
              "GROUP BY vehicle HAVING COUNT(DISTINCT board_id) > 1) GROUP BY vehicle, board_id")

    def shared_folders(self) -> dict[str, list[str]]:
        """``{folder: [board ids]}``: vehicles named by a folder (``--vehicle dir``) that holds the logs of
        several boards. The report ranks each board's IMUs apart, as ``folder/board id``: one folder
        is not one vehicle when the logs say otherwise."""
        out: dict[str, list[str]] = {}
        for v, b in self.con.execute(self._SPLIT):
            out.setdefault(v, []).append(b)
        return out

    def all_results(self, condition: str | None = None):
        """Every analysed axis joined with its log, ordered by IMU then flight time (for the report).

        ``vehicle`` is ``folder/board id`` for the logs of a folder that holds several boards
        (:meth:`shared_folders`), ``folder`` the stored vehicle name. A generator: rows stream from SQLite,
        the report holds one IMU at a time. ``condition``: only that condition's rows (None: all, ordered by
        condition after the IMU)."""
        vehicle = ("CASE WHEN l.board_id IS NOT NULL AND r.vehicle = l.vehicle AND r.vehicle IN "
                   "(SELECT vehicle FROM split) THEN r.vehicle || '/' || l.board_id ELSE r.vehicle END")
        cur = self.con.execute(
            f"WITH split AS ({self._SPLIT}) "
            f"SELECT {vehicle} AS vehicle, r.vehicle AS folder, r.sysid, r.compid, r.message, r.imu, r.axis, "
            "r.status, r.hash, r.still_s, r.rate_hz, r.temp_min, r.temp_max, r.condition, "
            + ", ".join(f"r.{p}, r.{p}_lo, r.{p}_hi" for p in PARAMS)
            + ", l.start_time, l.start_source, l.board_id, l.path FROM results r JOIN logs l ON l.hash = r.hash WHERE l.status = 'ok' "
            + ("AND r.condition = ? " if condition else "")
            + "ORDER BY 1, r.sysid, r.compid, r.message, r.imu, r.condition DESC, l.start_time, l.path, r.axis",
            (condition,) if condition else ())
        names = [d[0] for d in cur.description]
        for row in cur:
            yield dict(zip(names, row))

    def failures(self) -> list[tuple[str, str]]:
        return self.con.execute("SELECT path, error FROM logs WHERE status = 'failed' ORDER BY path").fetchall()
