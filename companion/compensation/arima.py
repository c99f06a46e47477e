"""ARIMA(1,1,1) model of gyro random error (Shi et al., eq. (1)-(6)) and its least-squares initialisation.

Model (Shi et al. eq. (1)-(2)), with a_k ~ N(0, 1) white::

    x_k = (1 + phi) x_{k-1} - phi x_{k-2} + delta1 a_k - delta2 a_{k-1}          (2)

i.e. the first difference w_k = x_k - x_{k-1} is ARMA(1,1): w_k = phi w_{k-1} + delta1 a_k - delta2 a_{k-1}
(MA coefficient theta = delta2 / delta1, innovation standard deviation delta1 in eq. (1)). The gyro output
is Z_k = x_k + V_k with V_k white, variance R (eq. (4)).

Model L (eq. (3)-(4)): state X_k = [x_k, x_{k-1}]^T, F = [[1 + phi, -phi], [1, 0]], noise matrix
G = [[delta1, -delta2], [0, 0]] acting on W_{k-1} = [a_k, a_{k-1}]^T with covariance Q = I (a_k ~ N(0, 1)).
Like the paper, the filters treat W_{k-1} as white from step to step (the a_{k-1} that reappears in
W_{k-2} is ignored): the MA(1) term then acts as extra process-noise variance delta2^2.

Model NL (eq. (5)-(6)): state X_k = [x_k, x_{k-1}, phi_k, delta1_k, delta2_k]^T with the parameters as
(constant) states; see :func:`f_nl`.

Least-squares initialisation (:func:`fit_arima111`). The differenced output dZ_k = w_k + V_k - V_{k-1} has
the autocovariances (Box & Jenkins, ARMA(1,1) autocovariance; sigma^2 = delta1^2, theta = delta2 / delta1)::

    c_0 = sigma^2 (1 + theta^2 - 2 phi theta) / (1 - phi^2) + 2 R
    c_1 = sigma^2 (1 - phi theta)(phi - theta) / (1 - phi^2) - R
    c_j = phi^(j-1) sigma^2 (1 - phi theta)(phi - theta) / (1 - phi^2),   j >= 2

and (phi, theta, sigma, R) are fitted by nonlinear least squares to the sample autocovariances at lags
0..L. All numbers are in internal units: the data are divided by ``scale`` (about the standard deviation
of the white measurement noise) after removing ``offset``, so that the filters' square roots work on
numbers of order one whatever the physical unit (rad/s, deg/h, ...).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.linalg import solve_discrete_are
from scipy.optimize import least_squares
from scipy.signal import lfilter

from companion.errors import CompanionError

#: Fewest samples an ARIMA(1,1,1) + noise fit is attempted with.
MIN_FIT_SAMPLES = 200


@dataclass
class ArimaParams:
    """ARIMA(1,1,1) + white-noise parameters; phi, delta1, delta2, R in internal (scaled) units.

    Physical value = offset + scale * internal value. ``R`` is the measurement-noise variance of eq. (4)
    in internal units (physical variance = R * scale^2).
    """

    phi: float
    delta1: float
    delta2: float
    R: float
    scale: float = 1.0
    offset: float = 0.0
    split: str = "free"  # how the fit shared white noise between x and V (see fit_arima111)
    free_white_share: float | None = None  # white share of x in the free fit (see white_share); None: no free fit

    @property
    def theta(self) -> float:
        return self.delta2 / self.delta1 if self.delta1 != 0.0 else 0.0

    def to_internal(self, z):
        return (np.asarray(z, dtype=float) - self.offset) / self.scale

    def to_physical(self, x):
        return self.offset + self.scale * np.asarray(x, dtype=float)

    def as_dict(self) -> dict:
        return asdict(self)


def diff_autocovariance(dz: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocovariances c_0..c_max_lag of a (differenced) series, biased (1/n) estimator."""
    dz = np.asarray(dz, dtype=float)
    dz = dz - dz.mean()
    n = dz.shape[0]
    return np.array([np.dot(dz[: n - j], dz[j:]) / n for j in range(max_lag + 1)])


def model_autocovariance(phi: float, theta: float, sigma: float, R: float, max_lag: int) -> np.ndarray:
    """Autocovariances c_0..c_max_lag of dZ = ARMA(1,1) + V_k - V_{k-1} (formulas in the module docstring)."""
    s2 = sigma * sigma
    den = 1.0 - phi * phi
    g0 = s2 * (1.0 + theta * theta - 2.0 * phi * theta) / den
    g1 = s2 * (1.0 - phi * theta) * (phi - theta) / den
    c = np.empty(max_lag + 1)
    c[0] = g0 + 2.0 * R
    if max_lag >= 1:
        c[1] = g1 - R
    if max_lag >= 2:
        c[2:] = g1 * phi ** np.arange(1, max_lag)
    return c


def white_share(phi: float, theta: float, sigma: float, R: float, grid: int = 4096) -> float:
    """Share of the white noise that the model leaves inside x instead of in V: W_x / (W_x + R).

    The pseudo-spectrum of x (eq. (2)) is f_x(w) = sigma^2 |1 - theta e^{-iw}|^2 / (|1 - e^{-iw}|^2
    |1 - phi e^{-iw}|^2); its minimum W_x over 0 < w <= pi is the variance of the largest white component
    x contains (the part the canonical decomposition moves into V). A filter cannot remove white noise the
    model calls signal, so a large share means the fit has hidden the measurement noise in x.
    """
    w = np.linspace(0.0, np.pi, grid + 1)[1:]
    c = np.cos(w)
    f = sigma * sigma * (1.0 + theta * theta - 2.0 * theta * c) / ((2.0 - 2.0 * c) * (1.0 + phi * phi - 2.0 * phi * c))
    wx = float(f.min())
    total = wx + R
    return wx / total if total > 0.0 else 0.0


#: ``split="auto"`` refits with the canonical split when the free fit leaves more than this share of the
#: white noise in x. On Gauss-Markov + white data (benchmarks/bench_compensation.py --gauss-markov 20) the
#: free fits that filtered nothing had shares of 0.93-1.0, those near the optimal filter 0.0-0.16.
WHITE_SHARE_MAX = 0.2


def _least_squares_fit(c: np.ndarray, max_lag: int, theta_fixed: float | None):
    """Best (cost, phi, theta, sigma, R) fit of :func:`model_autocovariance` to ``c`` over several starts."""

    def residuals(p):
        phi, theta, sigma, sqrt_r = p
        if theta_fixed is not None:
            theta = theta_fixed
        return model_autocovariance(phi, theta, sigma, sqrt_r * sqrt_r, max_lag) - c

    best = None
    for phi0 in (-0.5, 0.0, 0.5, 0.9, 0.99):
        for frac in (0.1, 0.5, 0.9):  # share of c_0 given to the ARMA part
            sol = least_squares(
                residuals,
                x0=[phi0, 0.0 if theta_fixed is None else theta_fixed, np.sqrt(frac * c[0]),
                    np.sqrt((1.0 - frac) * c[0] / 2.0)],
                bounds=([-0.999, -1.0, 0.0, 0.0], [0.9999, 1.0, np.inf, np.inf]),
                x_scale=[0.1, 0.1, 0.1, 0.1],
                max_nfev=300,
            )
            if best is None or sol.cost < best.cost:
                best = sol
    phi, theta, sigma, sqrt_r = (float(v) for v in best.x)
    if theta_fixed is not None:
        theta = theta_fixed
    return float(best.cost), phi, theta, sigma, sqrt_r * sqrt_r


def fit_arima111(z, max_lag: int = 30, max_samples: int | None = 200_000, split: str = "auto") -> ArimaParams:
    """Least-squares fit of ARIMA(1,1,1) + white measurement noise to a gyro series ``z``.

    Uses the first ``max_samples`` samples (all if None). Returns parameters in internal units with
    ``scale = sqrt(c_0 / 2)`` of the raw differenced series (the measurement-noise standard deviation when
    white noise dominates) and ``offset`` = mean of the first samples. The fit minimises
    sum_j (c_j - c_j(phi, theta, sigma, R))^2 (internal units, c_0 = 2) over |phi| < 1, |theta| <= 1,
    sigma, R >= 0, from several starting values of phi (the problem has local minima), keeping the best.

    ``split`` decides how white noise is shared between the error x and the measurement noise V:

    - ``"free"``: the unconstrained fit above;
    - ``"canonical"``: theta fixed to -1, which puts a zero at the Nyquist frequency into the spectrum of
      x, i.e. gives all the white noise to V (the canonical decomposition of Hillmer & Tiao, JASA 1982);
    - ``"auto"`` (default): the free fit, unless it hides white noise in x: the MA root on the unit circle
      (theta >= 0.98; (1 - theta B) cancels the difference (1 - B)), or more than ``WHITE_SHARE_MAX`` of the
      white noise left inside x (:func:`white_share`). Along that direction the autocovariances barely
      change (x's white component and V cannot be told apart), so the least-squares fit lands anywhere on
      it, often at R about 0, and then no filter removes anything: use the canonical split instead. Real
      gyros at rest (white noise plus slow drift or Gauss-Markov wander) usually land here.
    """
    if split not in ("auto", "free", "canonical"):
        raise CompanionError(f"unknown ARIMA split {split!r}; expected auto, free or canonical")
    z = np.asarray(z, dtype=float)
    z = z[np.isfinite(z)]
    if max_samples is not None:
        z = z[:max_samples]
    if z.shape[0] < MIN_FIT_SAMPLES:
        raise CompanionError(
            f"{z.shape[0]} samples are too few to fit the ARIMA(1,1,1) model (need at least {MIN_FIT_SAMPLES})"
        )
    dz = np.diff(z)
    max_lag = int(min(max_lag, dz.shape[0] // 10))
    c_raw = diff_autocovariance(dz, max_lag)
    if not c_raw[0] > 0.0:
        raise CompanionError("the series is constant: nothing to compensate")
    scale = float(np.sqrt(c_raw[0] / 2.0))
    c = c_raw / scale**2  # internal units: c_0 = 2
    offset = float(np.mean(z[: min(z.shape[0], 100)]))

    used = "canonical" if split == "canonical" else "free"
    _cost, phi, theta, sigma, R = _least_squares_fit(c, max_lag, -1.0 if used == "canonical" else None)
    share = white_share(phi, theta, sigma, R) if used == "free" else None
    if split == "auto" and (theta >= 0.98 or share > WHITE_SHARE_MAX):
        used = "canonical"
        _cost, phi, theta, sigma, R = _least_squares_fit(c, max_lag, -1.0)
    # A vanishing ARMA part would leave the filters with no process noise: keep a floor of 1e-3.
    sigma = max(sigma, 1e-3)
    return ArimaParams(phi=phi, delta1=sigma, delta2=theta * sigma, R=max(R, 1e-6),
                       scale=scale, offset=offset, split=used, free_white_share=share)


def simulate_arima111(n: int, phi: float, delta1: float, delta2: float, R: float, rng, x0: float = 0.0):
    """Simulate eq. (2) plus white measurement noise: returns (x, Z) with Z = x + V, V ~ N(0, R)."""
    a = rng.standard_normal(n + 1)
    e = delta1 * a[1:] - delta2 * a[:-1]
    w = lfilter([1.0], [1.0, -phi], e)  # w_k = phi w_{k-1} + e_k
    x = x0 + np.cumsum(w)
    return x, x + np.sqrt(R) * rng.standard_normal(n)


def optimal_error_std(phi: float, delta1: float, delta2: float, R: float) -> float:
    """Steady-state posterior std of the optimal Kalman filter on the exact ARIMA(1,1,1) model, eq. (1)-(4).

    The reference any compensation filter is measured against: state [x_k, x_{k-1}, a_k] with
    x_k = (1 + phi) x_{k-1} - phi x_{k-2} + delta1 a_k - delta2 a_{k-1}, a_k ~ N(0, 1), z_k = x_k + v_k,
    var(v_k) = R; P from the discrete algebraic Riccati equation.
    """
    A = np.array([[1 + phi, -phi, -delta2], [1.0, 0, 0], [0, 0, 0]])
    B = np.array([[delta1], [0.0], [1.0]])
    H = np.array([[1.0, 0, 0]])
    Pp = solve_discrete_are(A.T, H.T, B @ B.T, np.array([[R]]))
    P = Pp - Pp @ H.T @ H @ Pp / (H @ Pp @ H.T + R)
    return float(np.sqrt(P[0, 0]))


def f_nl(chi: np.ndarray) -> np.ndarray:
    """Process model NL, eq. (5), on augmented sigma points (columns).

    Rows: x_{k-1}, x_{k-2}, phi, delta1, delta2, a_k, a_{k-1} (the last two are the augmented noise
    states of eq. (11)); returns the propagated points with the same row layout (noise rows unchanged).
    """
    out = np.empty_like(chi)
    x1, x2, phi, d1, d2, a, a1 = chi
    out[0] = (1.0 + phi) * x1 - phi * x2 + d1 * a - d2 * a1
    out[1] = x1
    out[2:] = chi[2:]
    return out
