"""The look-ahead of one IMU's still blocks: a still block is fed only once the block after it is still
too (the start of a handling never leaks into the estimators) and the vehicle has been still for
``settle_s`` before it."""

from __future__ import annotations

import numpy as np

from companion.health.block_stats import BlockStats


class StillSettler:
    """The pending still block (with its statistics) and how long the vehicle has been still."""

    def __init__(self, settle_s: float):
        self.settle_s = float(settle_s)
        self.pending: np.ndarray | None = None  # still block waiting for the look-ahead
        self.pending_stats: BlockStats | None = None
        self.still_run_s = 0.0

    @property
    def settling(self) -> bool:
        """Nothing still so far: the motion gate is at the start of a still stretch."""
        return self.still_run_s == 0.0 and self.pending is None

    def settle(self, data: np.ndarray, st: BlockStats, still: bool,
               rate_hz: float) -> tuple[np.ndarray | None, BlockStats | None]:
        """The pending still block (and its statistics) to test and feed now that this block is still too,
        or (None, None); this block stays pending once the vehicle has been still for ``settle_s``. A moving
        block drops the pending one."""
        if not still:
            self.restart()
            return None, None
        out = (self.pending, self.pending_stats)
        settled = self.still_run_s >= self.settle_s
        self.pending = data if settled else None
        self.pending_stats = st if settled else None
        self.still_run_s += data.shape[0] / rate_hz
        return out

    def restart(self) -> None:
        """Motion or a time discontinuity: drop the look-ahead and settle again."""
        self.pending, self.pending_stats, self.still_run_s = None, None, 0.0

    def drop_lookahead(self) -> None:
        """A rate change: the look-ahead block belongs to the other rate and is dropped, but the vehicle has
        not moved, so the still time counts on (settling again at each change leaves no still data under a
        router that sets the stream rates every 15 s)."""
        self.pending, self.pending_stats = None, None
