"""The online Allan estimators of one IMU at one stream rate, and the still data queued for them.

Per axis three estimators (companion.estimators.make_estimator): a *fast* one (exponential memory
``forgetting_fast_s``) for Q and N, a *slow* one (``forgetting_slow_s``) for B, K and R, and while the
baseline is learned a third one without forgetting (``learn``) whose terms become the baseline. Still
blocks are queued and handed over in batches (:meth:`EstimatorBank.flush`): the estimators' block updates
are split-invariant, so the result is that of one update per block with far fewer calls. A queued block
marked as a junction starts a new segment of the estimators (no Allan cluster straddles it).

The bank also holds :attr:`EstimatorBank.held`, its own state as it stood at the onset of a transient
fault (:meth:`snapshot`), put back when the fault clears (:meth:`put_back`).
"""

from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from companion.estimators import from_state_dict as estimator_from_state
from companion.health.baseline import check_params
from companion.samples import ACCEL_AXES, GYRO_AXES
from companion.service.still_record import StillRecord

COLUMNS = {ax: 1 + i for i, ax in enumerate(GYRO_AXES + ACCEL_AXES)}  # column of each axis in a block row
FAST_EFFECTS = ("quantization", "white_noise")  # reported from the fast estimator, the rest from the slow one

#: ``make(axis, forgetting_s)``: a new estimator of one axis (None: no forgetting)
MakeEstimator = Callable[[str, "float | None"], object]


def _terms(est, full: bool = False) -> list[dict]:
    """An estimator's terms; only the octave bank has a full (all-effects) model selection."""
    return est.terms(full=full) if est.kind == "octave" else est.terms()


class EstimatorBank:
    """Fast, slow and (while learning) baseline estimators per axis, their still seconds and the queue."""

    def __init__(self, fast: dict | None = None, slow: dict | None = None, learn: dict | None = None):
        self.fast: dict = fast or {}
        self.slow: dict = slow or {}
        self.learn: dict = learn or {}
        self.fed_s = 0.0  # still seconds queued or fed to the fast and slow estimators
        self.learned_s = 0.0  # of those, seconds fed while learning the baseline
        self.queue_s = 0.0  # still seconds queued, not yet handed over
        self._queue: list[np.ndarray] = []
        self._junctions: set[int] = set()  # queue indices whose block starts a new segment
        self.held: dict | None = None  # the snapshot taken at the onset of a transient fault
        # the still samples fed, for the run's final analysis (companion.service.still_record)
        self.record = StillRecord({"t": 0, **{a: COLUMNS[a] for a in self.fast}})
        self.final_cache: tuple | None = None  # (record version, its final analysis): service.final_analysis

    @classmethod
    def create(cls, axes, make: MakeEstimator, fast_s: float, slow_s: float, learning: bool) -> "EstimatorBank":
        """Fresh estimators for ``axes`` with the fast and slow memories, and the learning ones when asked."""
        return cls({a: make(a, fast_s) for a in axes}, {a: make(a, slow_s) for a in axes},
                   {a: make(a, None) for a in axes} if learning else {})

    # ------------------------------------------------------------------ feeding
    def queue_block(self, data: np.ndarray, duration: float, junction: bool) -> None:
        """Queue one still block of ``duration`` seconds; ``junction``: it does not follow the last one."""
        if junction:
            self._junctions.add(len(self._queue))
        self._queue.append(data)
        self.record.add(data, duration, junction)
        self.fed_s += duration
        self.queue_s += duration
        if self.learn:
            self.learned_s += duration

    def clear_queue(self) -> None:
        """Drop the queued blocks unfed (the estimators' state is replaced, they belong to the old one)."""
        self._queue, self.queue_s, self._junctions = [], 0.0, set()

    def flush(self) -> None:
        """Hand the queued still blocks to the estimators, one update per segment and axis."""
        if not self._queue:
            return
        cuts = sorted(self._junctions | {0, len(self._queue)})
        queue, junctions = self._queue, self._junctions
        self.clear_queue()
        banks = [self.fast, self.slow] + ([self.learn] if self.learn else [])
        for a, b in zip(cuts[:-1], cuts[1:]):
            data = np.concatenate(queue[a:b]) if b - a > 1 else queue[a]
            for ax in self.fast:
                y = np.ascontiguousarray(data[:, COLUMNS[ax]])
                for bank in banks:
                    est = bank[ax]
                    if a in junctions and hasattr(est, "new_segment"):
                        est.new_segment()
                    est.update(y)

    # ------------------------------------------------------------------ learning
    def relearn(self, axes, make: MakeEstimator) -> None:
        """Learn the baseline afresh (estimators without forgetting from now on)."""
        self.learn = {a: make(a, None) for a in axes}
        self.learned_s = 0.0
        if self.held is not None:
            self.held["learn"] = None

    def stop_learning(self) -> None:
        self.learn = {}
        if self.held is not None:
            self.held["learn"] = None

    def take_baseline(self) -> tuple[dict[str, dict[str, tuple[float, float]]], dict]:
        """The learned baseline per axis ``{param: (value, std)}`` and the Allan levels behind it (a later
        rise is compared only where the measured curve shows it); learning stops."""
        self.flush()
        terms = {ax: check_params(_terms(est, full=True), side="baseline") for ax, est in self.learn.items()}
        levels = {ax: est.avar() for ax, est in self.learn.items() if hasattr(est, "avar")}
        self.learn = {}
        return terms, levels

    def set_filters(self, filters: Mapping[str, float]) -> None:
        """Model the autopilot's low-pass cut-offs ({"gyro": Hz, "accel": Hz}) from the next report on."""
        for bank in (self.fast, self.slow, self.learn):
            for a, est in bank.items():
                if hasattr(est, "filter_hz"):
                    est.filter_hz = filters.get("gyro" if a in GYRO_AXES else "accel")

    # ------------------------------------------------------------------ reports
    def report_terms(self, ax: str, full: bool = False) -> list[dict]:
        """The reported terms of one axis: Q and N from the fast estimator, the others from the slow one."""
        fast = [t for t in _terms(self.fast[ax], full) if t["effect"] in FAST_EFFECTS]
        slow = [t for t in _terms(self.slow[ax], full) if t["effect"] not in FAST_EFFECTS]
        return fast + slow

    def per_estimator(self, ax: str, params: dict[str, tuple[float, float]], test) -> dict[str, tuple[float, float]]:
        """``params`` filtered by ``test(sub, (tau, avar, edf))`` per estimator: Q and N with the fast
        estimator's Allan levels, B, K and R with the slow one's."""
        out = {}
        for bank, ps in ((self.fast, ("Q", "N")), (self.slow, ("B", "K", "R"))):
            sub = {p: params[p] for p in ps if p in params}
            est = bank.get(ax)
            if sub and est is not None and hasattr(est, "avar"):
                sub = test(sub, est.avar())
            out.update(sub)
        return out

    # ------------------------------------------------------------------ transient faults
    def snapshot(self) -> dict:
        """The estimators as they stand, without the still blocks queued since the last hand-over."""
        learning = bool(self.learn)
        return {"fast": {a: e.state_dict() for a, e in self.fast.items()},
                "slow": {a: e.state_dict() for a, e in self.slow.items()},
                "learn": {a: e.state_dict() for a, e in self.learn.items()} if learning else None,
                "fed_s": self.fed_s - self.queue_s,
                "learned_s": max(0.0, self.learned_s - self.queue_s) if learning else self.learned_s,
                "record": self.record.mark(len(self._queue))}

    def put_back(self, snap: Mapping) -> float:
        """Restore :meth:`snapshot`; the queue is dropped. Returns the still seconds taken back out."""
        dropped = self.fed_s - float(snap["fed_s"])
        self.fast = {a: estimator_from_state(s) for a, s in snap["fast"].items()}
        self.slow = {a: estimator_from_state(s) for a, s in snap["slow"].items()}
        # a baseline learning that started afresh meanwhile (relearn) keeps its own estimators
        if self.learn and snap.get("learn") is not None:
            self.learn = {a: estimator_from_state(s) for a, s in snap["learn"].items()}
            self.learned_s = float(snap["learned_s"])
        self.fed_s = float(snap["fed_s"])
        self.clear_queue()
        self.record.trim(snap.get("record") or ["", 0])
        return max(0.0, dropped)

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        """The flushed estimators; the caller places the keys in its state record."""
        self.flush()
        return {"fed_s": self.fed_s, "learned_s": self.learned_s,
                "fast": {a: e.state_dict() for a, e in self.fast.items()},
                "slow": {a: e.state_dict() for a, e in self.slow.items()},
                "learn": {a: e.state_dict() for a, e in self.learn.items()},
                "before_fault": self.held}

    @classmethod
    def from_state(cls, c: Mapping, axes) -> "EstimatorBank":
        """A bank restored from :meth:`state_dict`; ValueError when it holds other axes than ``axes``."""
        bank = cls({a: estimator_from_state(s) for a, s in c["fast"].items()},
                   {a: estimator_from_state(s) for a, s in c["slow"].items()},
                   {a: estimator_from_state(s) for a, s in c["learn"].items()})
        axes = set(axes)
        if set(bank.fast) != axes or set(bank.slow) != axes or (bank.learn and set(bank.learn) != axes):
            raise ValueError("state holds other axes than configured")
        bank.fed_s, bank.learned_s = float(c["fed_s"]), float(c["learned_s"])
        snap = c.get("before_fault")
        if snap is not None:
            if set(snap["fast"]) != axes or set(snap["slow"]) != axes:
                raise ValueError("state holds other axes than configured")
            bank.held = dict(snap)
        return bank
