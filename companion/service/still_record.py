"""The still samples one IMU fed to its online estimators, kept for the run's final report.

``companion run`` reports live what its online estimators give (NAMED_VALUE_FLOAT). At the end of the run its
summary gives, beside those, the figure ``companion analyze`` computes: the same analysis function
(:func:`companion.analysis.stream.pieces_entry`) over the still samples the run fed its estimators, pooled over
the still stretches as ``analyze`` pools its still segments (a junction of the estimators starts a new piece).

Why the samples and not accumulated Allan points: the offline fit needs the pooled overlapping AVAR at every
octave up to half the longest piece, with the pieces' lengths for the points' covariance; the overlapping AVAR
of the longest cluster times needs the whole stretch anyway, so a streaming form keeps as much as the samples
and would still not be the same computation. The samples of the analysed axes are kept as float64 (the values
the estimators saw, so the figure is exactly that of ``analyze`` on the same samples): 3 gyro axes at 400 Hz are
9.6 kB per still second, 35 MB per IMU-hour (benchmarks/bench_still_record.py measures a 3 IMU x 400 Hz x 1 h
run). Beyond :data:`MAX_KEPT_BYTES` per IMU the oldest still blocks are dropped (the figure then covers the
latest still data, and the summary says how much was left out).

The record follows the estimators: blocks taken back out after a transient fault are taken out here too
(:meth:`StillRecord.mark` / :meth:`StillRecord.trim`), and fresh estimators (a rate change, rest found to be
vibration) start a fresh record. A state file keeps the estimators, not the samples: after a restart the record
holds the still data since the restart only, and the summary says so.
"""

from __future__ import annotations

import uuid

import numpy as np

#: the still samples kept per IMU (bytes): 1.5 h of time and 3 gyro axes at 400 Hz, 5.8 h at 100 Hz
MAX_KEPT_BYTES = 64 * 2**20


class StillRecord:
    """Still blocks of the analysed axes, grouped in pieces (a junction starts a new one)."""

    def __init__(self, columns: dict[str, int], max_bytes: int = MAX_KEPT_BYTES):
        self.columns = dict(columns)  # "t" and each axis -> its column of a block row
        self.max_bytes = int(max_bytes)
        # per piece its blocks: (first time, last time, samples x axes, seconds)
        self.pieces: list[list[tuple[float, float, np.ndarray, float]]] = []
        self.token = uuid.uuid4().hex[:12]  # names this record in a mark (a state file's mark is of another)
        self.kept_s = 0.0  # still seconds held
        self.dropped_s = 0.0  # still seconds dropped for the memory budget (the oldest)
        self.nbytes = 0
        self.added = 0  # blocks added and not trimmed (those dropped for the budget included): a mark's position
        self.changes = 0  # every add and trim (the version of what is kept)

    def add(self, data: np.ndarray, duration: float, junction: bool) -> None:
        """One still block (rows of time and axes) of ``duration`` seconds; ``junction``: it does not follow the
        last one."""
        cols = [self.columns[a] for a in self.columns]
        block = np.array(data[:, cols], dtype=np.float64)
        if junction or not self.pieces:
            self.pieces.append([])
        self.pieces[-1].append((float(data[0, 0]), float(data[-1, 0]), block, float(duration)))
        self.kept_s += duration
        self.added += 1
        self.changes += 1
        self.nbytes += block.nbytes
        while self.nbytes > self.max_bytes and self.pieces:
            self._drop_oldest()

    def _drop_oldest(self) -> None:
        _, _, block, duration = self.pieces[0].pop(0)
        if not self.pieces[0]:
            self.pieces.pop(0)
        self.nbytes -= block.nbytes
        self.kept_s -= duration
        self.dropped_s += duration

    def mark(self, unfed_blocks: int = 0) -> list:
        """Where the record stands, its last ``unfed_blocks`` excluded (the queue a snapshot of the estimators
        leaves out): for :meth:`trim`."""
        return [self.token, self.added - int(unfed_blocks)]

    def trim(self, mark) -> None:
        """Drop every block added after ``mark`` (the estimators were put back to that point); a mark of another
        record (taken before a restart) drops everything, all of it came after."""
        token, added = mark
        if token != self.token:
            added = 0
        while self.added > added and self.pieces:
            _, _, block, duration = self.pieces[-1].pop()
            if not self.pieces[-1]:
                self.pieces.pop()
            self.nbytes -= block.nbytes
            self.kept_s -= duration
            self.added -= 1
            self.changes += 1

    def axis_pieces(self, axis: str) -> list[np.ndarray]:
        """The kept samples of one axis ("t": their times), one array per piece."""
        j = list(self.columns).index(axis)
        return [np.concatenate([b[:, j] for _, _, b, _ in p]) for p in self.pieces if p]

    @property
    def axes(self) -> list[str]:
        return [a for a in self.columns if a != "t"]

    def ranges_s(self) -> list[tuple[float, float]]:
        """(first, last) sample time of every piece (message time, s)."""
        return [(p[0][0], p[-1][1]) for p in self.pieces if p]

    @property
    def version(self) -> tuple:
        """Changes whenever the kept samples do (the summary computes the analysis once per version)."""
        return (self.token, self.changes)
