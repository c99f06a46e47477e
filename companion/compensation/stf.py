"""Strong tracking Kalman filter (STF) on model L (Shi et al. method 1, eq. (3)-(4)).

Shi et al. cite the STF without writing it out; this is the single suboptimal fading factor formulation
of D. H. Zhou, Y. G. Xi and Z. J. Zhang (1991) and D. H. Zhou & P. M. Frank, "Strong tracking filtering
of nonlinear time-varying stochastic systems with coloured noise", Int. J. Control 65(2), 1996, 295-307:

    X_{k|k-1} = F X_{k-1},    gamma_k = Z_k - H X_{k|k-1}                      (innovation)
    V_k = gamma_1 gamma_1^T (k = 1),  V_k = (rho V_{k-1} + gamma_k gamma_k^T) / (1 + rho)   (k > 1)
    N_k = V_k - H Q' H^T - beta R,    M_k = H F P_{k-1} F^T H^T,    Q' = G Q G^T
    c_k = tr(N_k) / tr(M_k),          lambda_k = max(1, c_k)                   (fading factor)
    P_{k|k-1} = lambda_k F P_{k-1} F^T + Q'
    K_k = P_{k|k-1} H^T (H P_{k|k-1} H^T + R)^{-1}
    X_k = X_{k|k-1} + K_k gamma_k,    P_k = (I - K_k H) P_{k|k-1} (I - K_k H)^T + K_k R K_k^T   (Joseph form)

with model L: X = [x_k, x_{k-1}]^T, F = [[1 + phi, -phi], [1, 0]], G = [[delta1, -delta2], [0, 0]], Q = I,
H = [1, 0] (eq. (3)-(4)); so Q' = diag(delta1^2 + delta2^2, 0). rho = 0.95 is the forgetting factor and
beta >= 1 the softening factor. With beta large the fading factor stays 1 and the filter is the ordinary
Kalman filter. The state is 2-dimensional, written out in scalars for speed.
"""

from __future__ import annotations

import math

import numpy as np

from companion.compensation.scaled_filter import ScaledFilter
from companion.compensation.arima import ArimaParams


class STF(ScaledFilter):
    """Strong tracking Kalman filter with a fading factor, on the linear ARIMA model L."""

    progress_every = 100_000

    name = "stf"
    label = "STF, model L"

    def __init__(self, params: ArimaParams, rho: float = 0.95, beta: float = 1.0):
        self.params = params
        self.phi = float(params.phi)
        self.q = float(params.delta1**2 + params.delta2**2)  # Q' = G Q G^T, only the (0, 0) element
        self.R = float(params.R)
        self.rho = float(rho)
        self.beta = float(beta)
        self.x = None  # [x_k, x_{k-1}] internal units
        self.P = None  # [[P00, P01], [P01, P11]]
        self.V = None
        self.lam = 1.0
        self.steps = 0
        self.fading_steps = 0  # steps with lambda_k > 1
        self.min_diag = math.inf
        self.finite = True

    def _initialise(self, z: float) -> None:
        self.x = [z, z]
        p0 = 1.0 + self.R
        self.P = [p0, 0.0, p0]  # P00, P01, P11

    def step_internal(self, z: float) -> float:
        if self.x is None:
            self._initialise(z)
        a = 1.0 + self.phi
        b = -self.phi
        x0, x1 = self.x
        P00, P01, P11 = self.P
        # F P F^T with F = [[a, b], [1, 0]]
        FP00 = a * a * P00 + 2.0 * a * b * P01 + b * b * P11
        FP01 = a * P00 + b * P01
        FP11 = P00
        xp0 = a * x0 + b * x1
        xp1 = x0
        g = z - xp0  # innovation gamma_k
        g2 = g * g
        self.V = g2 if self.V is None else (self.rho * self.V + g2) / (1.0 + self.rho)
        N = self.V - self.q - self.beta * self.R
        M = FP00
        lam = N / M if M > 0.0 else 1.0
        if lam > 1.0:
            self.fading_steps += 1
        else:
            lam = 1.0
        self.lam = lam
        Pp00 = lam * FP00 + self.q
        Pp01 = lam * FP01
        Pp11 = lam * FP11
        s = Pp00 + self.R
        k0 = Pp00 / s
        k1 = Pp01 / s
        x0 = xp0 + k0 * g
        x1 = xp1 + k1 * g
        # Joseph form with (I - K H) = [[1 - k0, 0], [-k1, 1]]
        c = 1.0 - k0
        P00 = c * c * Pp00 + k0 * k0 * self.R
        P01 = c * (Pp01 - k1 * Pp00) + k0 * k1 * self.R
        P11 = Pp11 - 2.0 * k1 * Pp01 + k1 * k1 * Pp00 + k1 * k1 * self.R
        self.x = [x0, x1]
        self.P = [P00, P01, P11]
        self.steps += 1
        d = P00 if P00 < P11 else P11
        if d < self.min_diag:
            self.min_diag = d
        if not (math.isfinite(x0) and math.isfinite(d)):
            self.finite = False
        return x0

    def covariance(self) -> np.ndarray:
        P00, P01, P11 = self.P
        return np.array([[P00, P01], [P01, P11]])

    def factor_valid(self) -> bool:
        """No NaN so far and a strictly positive diagonal of P at every step (P is its own factor here)."""
        return self.finite and self.min_diag > 0.0
