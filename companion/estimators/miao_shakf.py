"""Paper-faithful online estimator: Miao et al. 2014 (JINST 9 P09001), Sage-Husa adaptive EKF.

State (3.5): x = a configurable subset of [Q N B K R] (SI), random walk x_{k+1} = x_k + zeta_k.
Measurement (3.6)/(3.7): the recursive Allan variance at tau0 (M = 1, eq. (3.3)/(3.4), see
:mod:`companion.estimators.recursive_avar`)

    z_k = (k-2)/(k-1) sigma_{k-1}^2 + (w_k - w_{k-1})^2 / (2 (k-1))
        = h(x) = 3 Q^2/tau0^2 + N^2/tau0 + (2 ln2/pi) B^2 + K^2 tau0/3 + R^2 tau0^2/2,

Jacobian H = [6 Q/tau0^2, 2 N/tau0, 4 ln2 B/pi, 2 K tau0/3, R tau0^2] (restricted to the chosen states).
Sage-Husa adaptive filter, eq. (3.8)-(3.19), with forgetting factor b:

    x_{k|k-1} = x_{k-1} + q_{k-1}                                           (3.8)
    P_{k|k-1} = P_{k-1} + Q_{k-1}                                           (3.9)
    K_k = P_{k|k-1} H^T (H P_{k|k-1} H^T + R_{k-1})^-1                      (3.10)
    eps_k = z_k - h(x_{k|k-1}) - r_{k-1}                                    (3.11)
    x_k = x_{k|k-1} + K_k eps_k                                             (3.12)
    P_k = (I - K_k H) P_{k|k-1}                                             (3.13)
    D_k = H^T (H P_{k|k-1} H^T + R_{k-1})^-1                                (3.14)
    gamma_k = (1 - b) / (1 - b^(k+1))                                       (3.15)
    q_k = q_{k-1} + gamma_k Q_{k-1} D_k eps_k                               (3.16)
    Q_k = Q_{k-1} + gamma_k Q_{k-1} D_k (eps_k^2 - H P_{k|k-1} H^T - R_{k-1}) D_k^T Q_{k-1}   (3.17)
    r_k = (1 - gamma_k) r_{k-1} + gamma_k (z_k - h(x_k))                    (3.18)
    R_k = (1 - gamma_k) R_{k-1} + gamma_k [(1 - H K_k)^2 eps_k^2 + H P_k H^T]  (3.19)

Readings of the printed equations (../shared/REFERENCE.md): (3.11) uses r_{k-1} (r_k is computed after it,
in (3.18)); gamma in (3.18)/(3.19) is gamma_k of (3.15); (3.14) uses R_{k-1} (R_k does not exist yet);
(3.16) as printed (Q_{k-1} eps_k) is dimensionally inconsistent and is read Q_{k-1} D_k eps_k, like
(3.17); "H_k x" in (3.11)/(3.18) is the EKF's h(x) (the measurement is quadratic: literally H x = 2 h(x)).
Safeguards that the paper does not have, needed for a filter that runs for hours: the rank-one
downdate of (3.17) (when eps^2 < H P H^T + R) is limited so that Q_k stays positive semi-definite
(Q + a v v^T, v = Q D, is PSD iff 1 + a D^T Q D >= 0); R_k is kept positive. ``noise_mean=False`` drops
the noise-mean estimates q, r of (3.16)/(3.18) (they are the paper's; with a single measurement the mean
r_k is not separable from h(x) and absorbs part of the signal, see docs/online.md). Coefficients are reported as |x| (h is even in each).

What it can observe: one number, the Allan variance at tau0, dominated by N^2/tau0. The filter cannot
separate B or K from N with it; they move only along the Jacobian direction from their initial values
(from config ``x0``, as the paper takes them off an Allan plot). Without ``x0`` every state starts so
that it explains a share of the first ``init_samples`` samples' AVAR(tau0) (white noise 1 - 1 % per
other state, each other state 1 %).
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.terms import LINEAR_PARAM, linear_basis
from companion.allan.terms import LINEAR_EFFECTS
from companion.estimators.octave_bank import check_effects

DEFAULT_EFFECTS = LINEAR_EFFECTS
from companion.estimators.recursive_avar import RecursiveAllanVariance


class MiaoSHAKF:
    """Sage-Husa adaptive EKF on the single-tau recursive Allan variance (Miao et al. 2014, eq. (3.3)-(3.19)).

    ``x0``: initial coefficients {param: SI value} (e.g. {"N": 1e-4, "B": 1e-4, "K": 3e-6}); missing ones
    start from the first ``init_samples``. ``p0_rel``: initial 1-sigma of each state relative to its x0;
    ``q0_rel``: initial process-noise 1-sigma per step relative to x0 (Q_0 of (3.9)); ``b``: forgetting
    factor of (3.15); ``forgetting_s``: optional exponential memory of the measurement (3.4), an extension.
    """

    kind = "miao"

    def __init__(self, rate_hz, effects=DEFAULT_EFFECTS, forgetting_s=None, b=0.99, x0=None, p0_rel=1.0,
                 q0_rel=1e-4, r0=None, init_samples=100, noise_mean=True):
        rate_hz = float(rate_hz)
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ValueError(f"rate_hz must be a positive number, got {rate_hz!r}")
        if not 0.0 <= float(b) < 1.0:
            raise ValueError(f"forgetting factor b must be in [0, 1), got {b}")
        if forgetting_s is not None and not float(forgetting_s) > 0:
            raise ValueError(f"forgetting_s must be positive (or null), got {forgetting_s}")
        self.rate_hz = rate_hz
        self.tau0 = 1.0 / rate_hz
        self.effects = tuple(e for e in check_effects(effects) if e in LINEAR_EFFECTS)  # the paper's x = [Q N B K R]
        self.params = [LINEAR_PARAM[e] for e in self.effects]
        x0 = dict(x0 or {})
        bad = sorted(set(x0) - set(self.params))
        if bad:
            raise ValueError(f"x0 has {', '.join(bad)} which is not among the estimated parameters {self.params}")
        self.x0 = {k: float(v) for k, v in x0.items()}
        self.forgetting_s = None if forgetting_s is None else float(forgetting_s)
        self.b = float(b)
        self.p0_rel, self.q0_rel = float(p0_rel), float(q0_rel)
        self.r0 = None if r0 is None else float(r0)
        self.init_samples = max(2, int(init_samples))
        self.noise_mean = bool(noise_mean)
        self._c = linear_basis([self.tau0], self.effects)[0]  # h(x) = sum c_i x_i^2, eq. (3.6) at tau0
        alpha_min = 0.0 if self.forgetting_s is None else 1.0 / (self.forgetting_s * rate_hz)
        self._ravar = RecursiveAllanVariance(1, alpha_min)
        self._pre: list[float] | None = []  # first samples, until the filter is initialised
        self._n = 0
        self.n_rejected = 0
        self.k = 0  # filter steps
        n = len(self.effects)
        self.x = np.zeros(n)
        self.P = np.zeros((n, n))
        self.Qn = np.zeros((n, n))
        self.q = np.zeros(n)
        self.r = 0.0
        self.R = 0.0

    @property
    def n_samples(self) -> int:
        return self._n

    # ------------------------------------------------------------------ filter
    def _initialise(self, first: np.ndarray) -> None:
        d = np.diff(first)
        v = 0.5 * float(np.mean(d * d)) if d.size else 0.0  # AVAR(tau0) of the first samples
        n = len(self.effects)
        shares = {p: (v / n) for p in self.params}
        if "N" in shares and n > 1:  # white noise dominates AVAR(tau0): it takes 1 - 1 % per other state
            shares = {p: (v * (1.0 - 0.01 * (n - 1)) if p == "N" else 0.01 * v) for p in self.params}
        x = np.array([self.x0[p] if p in self.x0 else math.sqrt(shares[p] / c) if c > 0 else 0.0
                      for p, c in zip(self.params, self._c)])
        scale = np.where(x > 0, x, 1e-12)
        self.x = x
        self.P = np.diag((self.p0_rel * scale) ** 2)
        self.Qn = np.diag((self.q0_rel * scale) ** 2)
        self.R = self.r0 if self.r0 is not None else max(v * v, 1e-300)

    def _step(self, z: float) -> None:
        self.k += 1
        k = self.k
        c = self._c
        x_pred = self.x + self.q  # (3.8)
        P_pred = self.P + self.Qn  # (3.9)
        H = 2.0 * c * x_pred  # Jacobian of (3.6)
        PHt = P_pred @ H
        HPH = float(H @ PHt)
        S = HPH + self.R
        Kk = PHt / S  # (3.10)
        eps = z - float(c @ (x_pred * x_pred)) - self.r  # (3.11), r_{k-1}
        self.x = x_pred + Kk * eps  # (3.12)
        self.P = P_pred - np.outer(Kk, H @ P_pred)  # (3.13)
        D = H / S  # (3.14) with R_{k-1}
        gamma = (1.0 - self.b) / (1.0 - self.b ** (k + 1))  # (3.15)
        QD = self.Qn @ D
        if self.noise_mean:
            self.q = self.q + gamma * QD * eps  # (3.16) read as Q D eps
        alpha = gamma * (eps * eps - HPH - self.R)
        DQD = float(D @ QD)
        if alpha * DQD < -1.0:  # Q + alpha (QD)(QD)^T is PSD iff 1 + alpha D^T Q D >= 0: limit the downdate
            alpha = -1.0 / DQD
        self.Qn = self.Qn + alpha * np.outer(QD, QD)  # (3.17)
        if self.noise_mean:
            self.r = (1.0 - gamma) * self.r + gamma * (z - float(c @ (self.x * self.x)))  # (3.18)
        HK = float(H @ Kk)
        HPkH = float(H @ self.P @ H)
        self.R = max((1.0 - gamma) * self.R + gamma * ((1.0 - HK) ** 2 * eps * eps + HPkH), 1e-300)  # (3.19)

    def _sample(self, w: float) -> None:
        if self._ravar.update(w):
            self._step(self._ravar.avar)

    # ------------------------------------------------------------------ interface
    def update(self, y) -> None:
        """Add one rate sample or a 1-D block (SI). Sample-by-sample either way: identical results."""
        ys = [float(y)] if np.ndim(y) == 0 else np.asarray(y, dtype=float).ravel().tolist()
        for w in ys:
            if not math.isfinite(w):
                self.n_rejected += 1
                continue
            self._n += 1
            if self._pre is not None:
                self._pre.append(w)
                if len(self._pre) >= self.init_samples:
                    pre, self._pre = self._pre, None
                    self._initialise(np.array(pre))
                    for v in pre:
                        self._sample(v)
                continue
            self._sample(w)

    def terms(self) -> list[dict]:
        """Current coefficients [{"effect", param: |x|, "std": {param: sqrt(P_ii)}}] (SI)."""
        out = []
        init = self._pre is None
        for i, (e, p) in enumerate(zip(self.effects, self.params)):
            val = abs(float(self.x[i])) if init else 0.0
            std = math.sqrt(max(float(self.P[i, i]), 0.0)) if init else float("inf")
            out.append({"effect": e, p: val, "std": {p: std}})
        return out

    def state_dict(self) -> dict:
        return {
            "kind": self.kind,
            "version": 1,
            "config": {"rate_hz": self.rate_hz, "effects": list(self.effects), "forgetting_s": self.forgetting_s,
                       "b": self.b, "x0": self.x0, "p0_rel": self.p0_rel, "q0_rel": self.q0_rel, "r0": self.r0,
                       "init_samples": self.init_samples, "noise_mean": self.noise_mean},
            "n": self._n, "n_rejected": self.n_rejected, "k": self.k,
            "pre": self._pre,
            "ravar": self._ravar.state_dict(),
            "x": self.x.tolist(), "P": self.P.tolist(), "Qn": self.Qn.tolist(), "q": self.q.tolist(),
            "r": self.r, "R": self.R,
        }

    @classmethod
    def from_state_dict(cls, d: dict) -> "MiaoSHAKF":
        if d.get("kind") != cls.kind:
            raise ValueError(f"state is for estimator kind {d.get('kind')!r}, not {cls.kind!r}")
        est = cls(**d["config"])
        est._n, est.n_rejected, est.k = int(d["n"]), int(d["n_rejected"]), int(d["k"])
        est._pre = None if d["pre"] is None else [float(v) for v in d["pre"]]
        est._ravar = RecursiveAllanVariance.from_state_dict(d["ravar"])
        est.x, est.P, est.Qn, est.q = (np.asarray(d[k], dtype=float) for k in ("x", "P", "Qn", "q"))
        est.r, est.R = float(d["r"]), float(d["R"])
        return est
