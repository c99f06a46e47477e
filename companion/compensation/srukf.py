"""Square-root unscented Kalman filter on model NL (Shi et al. method 2; Van der Merwe & Wan 2001).

Augmented state (Shi et al. eq. (11)): X = [x_k, x_{k-1}, phi, delta1, delta2 | a_k, a_{k-1}]^T, real
part of dimension nr = 5 and the two non-additive noise items of eq. (5) with covariance Q = I (a ~ N(0, 1)).
The measurement noise V (variance R, eq. (6)) is additive and enters through sqrt(R) in eq. (18).

One step, k = 1, 2, ... (equation numbers of Shi et al.; Van der Merwe & Wan's Algorithm 3.1):

- (12) sigma points  chi = [X, X + gamma S, X - gamma S],  gamma = sqrt(n + lambda),
  lambda = alpha^2 (n + kappa) - n, W0m = lambda / gamma^2, W0c = W0m + 1 - alpha^2 + beta,
  Wim = Wic = 1 / (2 gamma^2);
- (13) chi_{k|k-1} = F(chi) with F of eq. (5) (:func:`companion.compensation.arima.f_nl`);
- (14) X_{k|k-1} = sum Wim chi_i;  S_{k|k-1} = qr(sqrt(W1c) [chi_{1:2n} - X_{k|k-1}]),
  S_{k|k-1} = cholupdate(S_{k|k-1}, sqrt|W0c| (chi_0 - X_{k|k-1}), sign W0c);
- (15) risk-sensitive step: none here (see :mod:`companion.compensation.srrsukf`);
- (16)-(17) sigma points redrawn from X_{k|k-1}, S_{k|k-1}; Z_i = H(chi_i) = chi_i[0] (eq. (6));
- (18) Zhat = sum Wim Z_i;  S_Z = qr([sqrt(W1c)(Z_{1:2n} - Zhat), sqrt(R)]), cholupdate with Z_0, W0c
  (the measurement is scalar, so qr() of the 1 x (2n+1) row is its Euclidean norm);
  P_XZ = sum Wic (chi_i - X_{k|k-1})(Z_i - Zhat);
- (19) K = P_XZ / S_Z^T / S_Z;
- (20) X_k = X_{k|k-1} + K (Z_k - Zhat);  U = K S_Z;  S_k = cholupdate(S_{k|k-1}, U, -1)
  (Van der Merwe & Wan: U = K S_y; the paper's "U = P_XZ S_Z" is a misprint, not dimensionally right);
- (21) noise states reset: X_k = [X_{1:nr,k}, 0], S_k = chol(diag(P_{1:nr,1:nr,k}, Q)). With the real
  states first and S lower triangular, rows 1..nr of S have no entries in the noise columns, so
  chol(P_{1:nr,1:nr}) is exactly S_{1:nr,1:nr}: the reset keeps that block and puts sqrt(Q) below it.

Defaults alpha = 1, beta = 2, kappa = 0 give lambda = 0, W0m = 0 and W0c = 2 > 0, so eq. (14) is an update,
never a fragile downdate. The autoregressive state phi is kept inside (-1, 1) after each update (the
difference process of eq. (1) is stationary only there). The delta states multiply zero-mean noise items,
so the unscented transform gives them zero cross-covariance with x: like in the paper's model NL they keep
their initial values (only phi is re-estimated online).
"""

from __future__ import annotations

import math

import numpy as np

from companion.compensation.scaled_filter import ScaledFilter
from companion.compensation.arima import ArimaParams, f_nl
from companion.compensation.sqrt_ops import cholupdate, tria

NR = 5  # real state: x_k, x_{k-1}, phi, delta1, delta2
NQ = 2  # augmented noise items: a_k, a_{k-1}
PHI_MAX = 0.9999  #: |phi| is held below 1: the AR(1) part of the model stays stationary


class SRUKF(ScaledFilter):
    """Square-root UKF on model NL with an augmented state for the non-additive noise (eq. (11)-(14), (16)-(21))."""

    name = "srukf"
    label = "SR-UKF, model NL"

    def __init__(self, params: ArimaParams, alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0,
                 phi_std: float = 0.05, delta_rel_std: float = 0.1):
        self.params = params
        n = NR + NQ
        self.n = n
        lam = alpha**2 * (n + kappa) - n
        self.gamma = math.sqrt(n + lam)
        self.Wm = np.full(2 * n + 1, 1.0 / (2.0 * self.gamma**2))
        self.Wc = self.Wm.copy()
        self.Wm[0] = lam / self.gamma**2
        self.Wc[0] = self.Wm[0] + (1.0 - alpha**2 + beta)
        self.R = float(params.R)
        self.Q = np.eye(NQ)  # a_k ~ N(0, 1), eq. (1)-(2)
        self.sqrtQ = np.linalg.cholesky(self.Q)
        self.x = None  # augmented state X (internal units), set by the first measurement
        self.S = None
        self._p0 = np.array([1.0 + self.R, 1.0 + self.R, phi_std**2,
                             (delta_rel_std * params.delta1) ** 2 + 1e-12,
                             (delta_rel_std * max(abs(params.delta2), 1e-3 * params.delta1)) ** 2 + 1e-12])
        self.steps = 0
        self.min_diag = math.inf  # smallest diagonal element of S seen so far (validity monitor)
        self.finite = True

    # -- eq. (11)
    def _initialise(self, z: float) -> None:
        p = self.params
        self.x = np.array([z, z, p.phi, p.delta1, p.delta2, 0.0, 0.0])
        P0 = np.zeros((self.n, self.n))
        P0[:NR, :NR] = np.diag(self._p0)
        P0[NR:, NR:] = self.Q
        self.S = np.linalg.cholesky(P0)

    def _sigma_points(self, x: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Eq. (12)/(16): chi = [x, x + gamma S, x - gamma S]."""
        n = self.n
        chi = np.empty((n, 2 * n + 1))
        chi[:] = x[:, None]
        gS = self.gamma * S
        chi[:, 1:n + 1] += gS
        chi[:, n + 1:] -= gS
        return chi

    def _risk_sensitive(self, S: np.ndarray) -> np.ndarray:
        """Eq. (15); the identity for the risk-neutral SR-UKF."""
        return S

    def step_internal(self, z: float) -> float:
        """One filter cycle on a measurement in internal units; returns the filtered x_k (internal units)."""
        if self.x is None:
            self._initialise(z)
        Wm, Wc = self.Wm, self.Wc
        # time update, eq. (12)-(14)
        chi = f_nl(self._sigma_points(self.x, self.S))
        x_pred = chi @ Wm
        dev = chi - x_pred[:, None]
        S = tria(math.sqrt(Wc[1]) * dev[:, 1:])
        S = cholupdate(S, math.sqrt(abs(Wc[0])) * dev[:, 0], 1.0 if Wc[0] >= 0 else -1.0)
        S = self._risk_sensitive(S)
        # measurement update, eq. (16)-(20)
        chi = self._sigma_points(x_pred, S)
        Zs = chi[0]  # H = [1 0 0 0 0 | 0 0], eq. (6)
        z_pred = float(Zs @ Wm)
        dZ = Zs - z_pred
        Sz2 = Wc[1] * float(dZ[1:] @ dZ[1:]) + self.R  # qr of the row [sqrt(W1c) dZ_{1:2n}, sqrt(R)]
        Sz2 += Wc[0] * dZ[0] * dZ[0]  # cholupdate with Z_0, W0c
        Sz = math.sqrt(Sz2)
        Pxz = (chi - x_pred[:, None]) @ (Wc * dZ)
        K = Pxz / Sz2  # eq. (19)
        x = x_pred + K * (z - z_pred)  # eq. (20)
        S = cholupdate(S, K * Sz, -1.0)
        # noise states reset, eq. (21)
        x[NR:] = 0.0
        S[NR:, :] = 0.0
        S[NR:, NR:] = self.sqrtQ
        if x[2] > PHI_MAX:
            x[2] = PHI_MAX
        elif x[2] < -PHI_MAX:
            x[2] = -PHI_MAX
        self.x, self.S = x, S
        self.steps += 1
        d = S.diagonal()
        dmin = float(d.min())
        if dmin < self.min_diag:
            self.min_diag = dmin
        if not math.isfinite(x[0]) or not math.isfinite(dmin):
            self.finite = False
        return float(x[0])

    @property
    def P(self) -> np.ndarray:
        """Covariance of the real state P = S S^T (internal units)."""
        S = self.S[:NR, :NR]
        return S @ S.T

    def factor_valid(self) -> bool:
        """No NaN so far and a strictly positive diagonal of S at every step."""
        return self.finite and self.min_diag > 0.0

    def estimates(self) -> dict:
        """Current model parameters (phi dimensionless, delta1/delta2 in internal units)."""
        return {"phi": float(self.x[2]), "delta1": float(self.x[3]), "delta2": float(self.x[4])}
