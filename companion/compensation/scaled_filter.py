"""What every compensation filter shares: running on physical units around an internal, scaled model.

The ARIMA parameters are fitted on data scaled to unit size (``ArimaParams.to_internal``) so that
rad/s-sized numbers do not break the square roots; each filter implements ``step_internal`` on that
scale and inherits ``step`` and ``run`` in physical units from :class:`ScaledFilter`.
"""

from __future__ import annotations

import numpy as np


class ScaledFilter:
    """Mixin: ``step``/``run`` in physical units on top of the subclass's ``step_internal``."""

    params = None  # ArimaParams, set by the subclass
    progress_every = 10_000  # samples between progress callbacks in ``run``

    def step_internal(self, z: float) -> float:  # pragma: no cover - implemented by each filter
        raise NotImplementedError

    def step(self, z: float) -> float:
        """One cycle on a physical measurement (e.g. rad/s); returns the compensated value in the same unit."""
        p = self.params
        return p.offset + p.scale * self.step_internal((z - p.offset) / p.scale)

    def run(self, z, progress=None) -> np.ndarray:
        """Filter a whole series (physical units); ``progress(done, total)`` every ``progress_every`` samples."""
        z_int = self.params.to_internal(z)
        out = np.empty(z_int.shape[0])
        step = self.step_internal
        total = z_int.shape[0]
        every = self.progress_every
        for k, zk in enumerate(z_int.tolist()):
            out[k] = step(zk)
            if progress is not None and k % every == 0:
                progress(k, total)
        return self.params.to_physical(out)
