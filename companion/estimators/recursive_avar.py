"""Recursive cluster mean and Allan variance of Miao et al. 2014, eq. (3.3) and (3.4), for one cluster size M.

    wbar_k(m)   = (m-1)/m wbar_k(m-1) + w_km / m,             1 <= m <= M, wbar_k(0) = 0      (3.3)
    sigma_k^2   = (k-2)/(k-1) sigma_{k-1}^2 + (wbar_k - wbar_{k-1})^2 / (2 (k-1)),  k >= 2       (3.4)

with sigma_1^2 = 0; after K clusters sigma_K^2 equals the non-overlapping Allan variance of eq. (3.2).
Optional exponential forgetting (an extension, not in the paper): the weight 1/(k-1) of the newest
difference is floored at ``alpha_min`` so that old differences fade with time constant 1/alpha_min
clusters.
"""

from __future__ import annotations


class RecursiveAllanVariance:
    """Sample-by-sample eq. (3.3)/(3.4) for cluster size ``M`` (M = 1: the Allan variance at tau0)."""

    def __init__(self, M: int = 1, alpha_min: float = 0.0):
        if int(M) < 1:
            raise ValueError(f"cluster size M must be >= 1, got {M}")
        self.M = int(M)
        self.alpha_min = float(alpha_min)
        self.m = 0  # samples in the current cluster
        self.wbar = 0.0  # wbar_k(m), eq. (3.3)
        self.wbar_prev = 0.0  # wbar_{k-1}(M)
        self.k = 0  # completed clusters
        self.avar = 0.0  # sigma_k^2, eq. (3.4)

    def update(self, w: float) -> bool:
        """Add one sample; True when a cluster closed and ``avar`` (sigma_k^2, k >= 2) was updated."""
        self.m += 1
        self.wbar = (self.m - 1) / self.m * self.wbar + w / self.m  # (3.3)
        if self.m < self.M:
            return False
        self.k += 1
        k = self.k
        updated = False
        if k >= 2:
            alpha = 1.0 / (k - 1)
            if alpha < self.alpha_min:
                alpha = self.alpha_min
            d = self.wbar - self.wbar_prev
            self.avar = (1.0 - alpha) * self.avar + alpha * 0.5 * d * d  # (3.4): (k-2)/(k-1) = 1 - 1/(k-1)
            updated = True
        self.wbar_prev = self.wbar
        self.wbar = 0.0
        self.m = 0
        return updated

    def state_dict(self) -> dict:
        return {"M": self.M, "alpha_min": self.alpha_min, "m": self.m, "wbar": self.wbar,
                "wbar_prev": self.wbar_prev, "k": self.k, "avar": self.avar}

    @classmethod
    def from_state_dict(cls, d: dict) -> "RecursiveAllanVariance":
        r = cls(d["M"], d.get("alpha_min", 0.0))
        r.m, r.wbar, r.wbar_prev, r.k, r.avar = int(d["m"]), float(d["wbar"]), float(d["wbar_prev"]), int(d["k"]), float(d["avar"])
        return r
