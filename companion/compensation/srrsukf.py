"""Square-root risk-sensitive UKF on model NL (Shi et al. method 3, eq. (11)-(21)).

Identical to :class:`companion.compensation.srukf.SRUKF` plus the risk-sensitive step of eq. (15) between
the time update (14) and the measurement update (16)-(20), with a diagonal risk-sensitive matrix
mu = diag(mu_1, ..., mu_n) (Acharya, Sadhu & Ghoshal 2010, non-scalar risk factor; Bhaumik, Sadhu & Ghoshal
2009, RSUKF).

What eq. (15) computes. The information-state recursion eq. (9) multiplies the Gaussian prior
exp(-1/2 e^T P^{-1} e) by exp(e^T mu e) (e = X - X_{k|k-1}), i.e. it replaces the prior covariance by

    P~_{k|k-1} = (P_{k|k-1}^{-1} - 2 mu)^{-1},

which exists while P^{-1} - 2 mu stays positive definite; mu > 0 inflates the prior, hence the gain, which
is what makes the filter less sensitive to model error. The printed eq. (15) is garbled in the seed text
("chol(S^T mu^-1 S^-1)"); its three lines are read here as the square-root form of the formula above:

    L   = chol(P^{-1})         = qr(S^{-T})       (S^{-1} by triangular inversion; L L^T = S^{-T} S^{-1})
    L   = cholupdate(L, chol{2 mu}, -1)           (one rank-1 downdate per non-zero mu_i, column sqrt(2 mu_i) e_i)
    S~  = chol((L L^T)^{-1})    = qr(L^{-T})

When a downdate would lose positive definiteness (mu too large for the current P) the step is skipped for
that sample and counted in ``rs_skipped``; the filter then behaves as the SR-UKF for that sample.
Default mu: 0.05 on the two x states (internal units, where the measurement-noise variance is about 1),
0 on the parameters and the noise items: a positive mu on a state that measurements do not inform (the
deltas) would inflate its variance without bound.
"""

from __future__ import annotations

import math

import numpy as np

from companion.compensation.arima import ArimaParams
from companion.compensation.sqrt_ops import DowndateError, cholupdate, tria, tril_inverse
from companion.compensation.srukf import NQ, NR, SRUKF

#: diagonal of the risk-sensitive matrix: risk on x_k and x_{k-1} only, none on the parameters or the noise
DEFAULT_MU = (0.05, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0)


class SRRSUKF(SRUKF):
    """Square-root risk-sensitive UKF: the SR-UKF cycle with the diagonal risk-sensitive matrix of eq. (15)."""

    name = "srrsukf"
    label = "SR-RSUKF, model NL"

    def __init__(self, params: ArimaParams, mu=DEFAULT_MU, **kwargs):
        super().__init__(params, **kwargs)
        mu = np.asarray(mu, dtype=float)
        if mu.shape != (NR + NQ,) or np.any(mu < 0.0) or not np.all(np.isfinite(mu)):
            raise ValueError(f"mu must be {NR + NQ} non-negative numbers (diagonal of the risk-sensitive matrix)")
        self.mu = mu
        self._downdates = [(i, math.sqrt(2.0 * m)) for i, m in enumerate(mu) if m > 0.0]
        self.rs_skipped = 0

    def _risk_sensitive(self, S: np.ndarray) -> np.ndarray:
        """Eq. (15): lower factor of (P^{-1} - 2 mu)^{-1} from the lower factor S of P."""
        if not self._downdates:
            return S
        n = self.n
        try:
            L = tria(tril_inverse(S).T)  # L L^T = S^{-T} S^{-1} = P^{-1}
            for i, c in self._downdates:
                e = np.zeros(n)
                e[i] = c
                L = cholupdate(L, e, -1.0)
            return tria(tril_inverse(L).T)  # S~ S~^T = L^{-T} L^{-1}
        except DowndateError:
            self.rs_skipped += 1
            return S
