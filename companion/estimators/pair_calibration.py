"""Running relative calibration of two gyros on one body, and their calibrated difference (numpy only).

Two IMUs bolted to one rigid body see the same rotation rate ``w``; each reads it through its own scale
factors and mounting (``C_i w``), plus its own bias and noise. Written as the first IMU against the second,
per axis a:

    g_i,a(t) = m_a . g_j(t) + b_a + d_a dg_j,a/dt (t) + e_a(t)                                       (1)

``m_a`` the row of the 3x3 relative scale/misalignment ``C_i C_j^-1``, ``b_a`` the relative bias, ``d_a``
the time offset of the two streams (first-order: g_j(t + d) = g_j(t) + d dg_j/dt), ``e_a`` what is left:
each IMU's own noise (common vibration and the true rotation cancel), the difference of their biases'
wander, and second-order motion terms. Samples are compared at the slower stream's instants (the caller
interpolates the faster one there).

The fit is made on means over ``fit_s`` (0.1 s) of both sides, where the motion dominates (see
:meth:`PairCalibration._means`), by recursive least squares in information form with exponential forgetting: per axis the 5x5
normal matrix and its right-hand side decay by ``exp(-dt / memory_s)`` and gain each chunk's sums, then
(1) is solved. So the calibration follows slow changes (temperature, warm-up) and costs O(n) per chunk,
independent of the flight's length. The residual of a chunk uses the fit including that chunk: with five
parameters per axis over ``memory_s`` of samples the variance it removes from ``e`` is a fraction
5 / (2 memory_s rate) (0.08 % at 50 Hz and 60 s), below what any noise figure resolves.
"""

from __future__ import annotations

import math

import numpy as np

N_PARAMS = 5  # three of the 3x3 matrix row, the bias, the time offset
RIDGE = 1e-12  # relative ridge of the normal matrix: a hover (little rotation) leaves m, d weakly determined


class PairCalibration:
    """Recursive fit of (1) for one pair; :meth:`update` gives the calibrated difference of each chunk."""

    def __init__(self, memory_s: float = 60.0, min_s: float = 10.0, fit_s: float = 0.1):
        if not (memory_s > 0 and math.isfinite(memory_s)):
            raise ValueError(f"memory_s must be positive, got {memory_s!r}")
        self.memory_s = float(memory_s)
        self.min_s = float(min_s)  # data behind the fit before residuals are given
        self.fit_s = float(fit_s)  # the fit is made on means over this span (_means)
        self.info = np.zeros((3, N_PARAMS, N_PARAMS))
        self.rhs = np.zeros((3, N_PARAMS))
        self.weight_s = 0.0  # forgotten seconds of data behind the fit
        self.theta = np.zeros((3, N_PARAMS))
        self.theta[:, :3] = np.eye(3)
        self.t_last: float | None = None

    @staticmethod
    def regressors(t: np.ndarray, gj: np.ndarray) -> np.ndarray:
        """(3, n, 5): per axis [g_j (3), 1, dg_j,a/dt] at the instants ``t``."""
        n = t.shape[0]
        X = np.empty((3, n, N_PARAMS))
        X[:, :, :3] = gj[None, :, :]
        X[:, :, 3] = 1.0
        dg = np.gradient(gj, t, axis=0) if n > 1 else np.zeros_like(gj)
        X[:, :, 4] = dg.T
        return X

    def update(self, t: np.ndarray, gi: np.ndarray, gj: np.ndarray) -> np.ndarray | None:
        """One chunk of aligned samples (t (n,), gi, gj (n, 3)) in time order, following the last chunk;
        returns the calibrated difference e (n, 3), or None while the fit has less than ``min_s`` behind it."""
        t = np.asarray(t, dtype=float)
        if t.shape[0] < 3:
            return None
        if self.t_last is not None:
            lam = math.exp(-max(float(t[-1]) - self.t_last, 0.0) / self.memory_s)
            self.info *= lam
            self.rhs *= lam
            self.weight_s *= lam
        self.t_last = float(t[-1])
        X = self.regressors(t, gj)
        y = gi.T  # (3, n)
        Xm, ym = self._means(t, X, y)
        self.info += np.einsum("anp,anq->apq", Xm, Xm)
        self.rhs += np.einsum("anp,an->ap", Xm, ym)
        self.weight_s += float(t[-1] - t[0]) + float(np.median(np.diff(t)))
        self._solve()
        if self.weight_s < self.min_s:
            return None
        return (y - np.einsum("anp,ap->an", X, self.theta)).T

    def _means(self, t: np.ndarray, X: np.ndarray, y: np.ndarray):
        """The chunk's regressors and outputs as means over ``fit_s`` (weighted by their sample counts): the
        fit sees the motion, not the noise and vibration each IMU picks up on its own, which in the regressor
        would bias it (errors in variables: a vibration the two IMUs pick up with different gains would be
        partly taken for a scale factor and vanish from the difference)."""
        k = max(1, int(round(self.fit_s * (t.shape[0] - 1) / max(float(t[-1] - t[0]), 1e-9))))
        m = t.shape[0] // k
        if m < 1:
            return X * 0.0, y * 0.0
        Xm = X[:, : m * k].reshape(3, m, k, N_PARAMS).mean(axis=2) * math.sqrt(k)
        ym = y[:, : m * k].reshape(3, m, k).mean(axis=2) * math.sqrt(k)
        return Xm, ym

    def _solve(self) -> None:
        for a in range(3):
            A = self.info[a]
            scale = np.sqrt(np.maximum(np.diag(A), 1e-300))
            An = A / np.outer(scale, scale) + RIDGE * np.eye(N_PARAMS)
            try:
                self.theta[a] = np.linalg.solve(An, self.rhs[a] / scale) / scale
            except np.linalg.LinAlgError:
                pass

    def restart(self) -> None:
        """A gap in the data: the next chunk does not follow (the fit is kept)."""
        self.t_last = None

    @property
    def matrix(self) -> np.ndarray:
        """The relative scale/misalignment (3x3, rows per axis of the first IMU)."""
        return self.theta[:, :3].copy()

    @property
    def bias(self) -> np.ndarray:
        return self.theta[:, 3].copy()

    @property
    def time_offset(self) -> np.ndarray:
        """Per axis, s: the first IMU's sample at t matches the second's at t + d."""
        return self.theta[:, 4].copy()
