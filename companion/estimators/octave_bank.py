"""Octave bank of recursive Allan accumulators with staggered phases: the default online estimator.

Why: Miao et al. 2014 measure only the Allan variance at tau0 (their eq. (3.7), M = 1), one number
dominated by N^2/tau0, so B and K are hardly observable from it (see docs/online.md). Here the whole
Allan curve is tracked recursively at the octave cluster sizes m_j = 2^j (j = 0 .. levels-1) and the
coefficients are solved from it.

Accumulators (per level j, bounded memory). Cluster sums are built as a pyramid of aligned pair sums
(level-u block = sum of two level-(u-1) blocks; this is eq. (3.3), cluster mean = block sum / m, kept as a
sum so that the arithmetic is exact-order and chunk-independent). Level j uses ``P_j = min(phases, m_j)``
staggered phases: blocks of step s_j = m_j / P_j samples; a cluster sum ending at block i is
c_i = b_{i-P_j+1} + ... + b_i, and each new block closes one cluster of one phase, whose Allan
difference with the previous cluster of the same phase is d_i = c_i - c_{i-P_j}. Each phase alone is the
classic non-overlapping estimator; all P_j phases together are the overlapping estimator decimated by s_j
(P_j = m_j: fully overlapping, levels 0..log2(phases)). The Allan variance is the recursion of eq. (3.4)
written on sums, with optional exponential forgetting lambda_j = exp(-s_j / (forgetting_s rate_hz)) per
difference:

    S_j <- lambda_j S_j + d_i^2 / (2 m_j^2),   W_j <- lambda_j W_j + 1,   sigma_j^2 = S_j / W_j

(lambda = 1 gives exactly eq. (3.4): sigma_k^2 = (k-2)/(k-1) sigma_{k-1}^2 + d_k^2 / (2 (k-1)), per phase
pooled). Memory: ``levels x (2 phases - 1)`` block sums, independent of run length.

Coefficients: the Allan variance is linear in theta = [Q^2, N^2, B^2, K^2, R^2] (Miao eq. (3.6);
:func:`companion.allan.terms.linear_basis`), sigma_j^2 = A_j theta, solved with theta >= 0 from the levels
with edf_j >= ``min_edf`` (edf_j = effective number of differences / P_j, about the number of
non-overlapping clusters; Kish's n_eff = W^2 / sum(w^2) under forgetting). ``fit``:

- ``"fit_avar"`` (used by ``companion analyze --online``): the project's offline fit :func:`companion.allan.fit.fit_avar` on the bank's
  Allan variances: generalised NNLS with the full model covariance of the Allan estimates (neighbouring
  cluster times are strongly correlated), iterated from measured weights. Same procedure as
  ``companion analyze`` (including its model-error floor for misfit), so online and offline differ only by
  the accumulators. 0.3-5 s per call: for reports, not for a loop.
- ``"gls"``: the same kind of GLS (:func:`fit_theta_gls`), covariance from the model rounded to sqrt(2)
  steps and cached: a few ms per call when the model is stable; for a slow companion computer.
- ``"diag"`` (default; 2-13 ms per call, for ``companion run``): weighted NNLS with var(sigma_j^2) =
  2 (A_j theta)^2 / edf_j (chi-square), iterated with weights from the model (not from the noisy
  measurement, to avoid the low bias of self-weighting), plus the offline fit's model-error floor when the
  five-term model does not fit (:func:`fit_theta`).

Because S_j, W_j are sufficient statistics of the whole (forgotten) history, re-solving from them at each
report is the information-form filter of the constant state theta with those measurement covariances,
without counting any data twice. 1-sigma of theta from the inverse information matrix (for parameters at
the zero bound: the marginal of the problem with that parameter freed), propagated to p = sqrt(theta) as
sqrt(theta + s) - sqrt(theta) (= s / (2 p) when s << theta, sqrt(s) at the bound); with ``fit_avar`` the
1-sigma of p is its 95 % interval width / 3.92.

Streaming and block updates give bit-identical results: scalar samples are buffered (at most
``_BUF`` of them) and every path runs the same chunk-independent block code (element-wise operations in
a fixed order, sequential recursions summed in closed form, :func:`companion.allan.lsq.exp_sum`).
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.confidence import edf_simple
from companion.allan.lsq import exp_sum  # numpy-only: the live pipeline loads no scipy (seconds of start-up, tens of MB on a small board)
from companion.allan.terms import EFFECTS, LINEAR_EFFECTS, LINEAR_PARAM
from companion.estimators.coefficient_fit import fit_theta, fit_theta_gls

#: every effect of the offline model (the candidates of the model selection, companion.estimators.online_report)
DEFAULT_EFFECTS = EFFECTS
_BUF = 2048  # scalar samples buffered before a block update (the same result as one array update)
#: coefficient fits: ``model`` (default: model chosen from the data, resolved values and 95 % bounds,
#: companion.estimators.online_report), diagonal weighted NNLS, a cached GLS, the offline fit_avar (linear effects only)
FITS = ("model", "fit_avar", "gls", "diag")


def check_effects(effects) -> tuple[str, ...]:
    effects = tuple(effects)
    bad = [e for e in effects if e not in EFFECTS]
    if bad or not any(e in LINEAR_EFFECTS for e in effects):
        raise ValueError(
            f"online estimator effects must be a subset of {', '.join(EFFECTS)} with at least one of "
            f"{', '.join(LINEAR_EFFECTS)}; got {list(effects)}"
        )
    return tuple(e for e in EFFECTS if e in effects)  # canonical order


class OctaveBankEstimator:
    """Online Allan coefficients from octave accumulators with staggered phases (see module docstring).

    Parameters: ``rate_hz`` sample rate; ``effects`` subset of the five linear effects; ``forgetting_s``
    exponential memory in seconds (None: infinite memory); ``phases`` staggered phases per level (power of
    2); ``max_tau_s`` largest cluster time kept (fixes the number of levels, hence the state size);
    ``min_edf`` smallest degrees of freedom for a level to enter the fit; ``filter_hz`` the 2-pole low-pass
    cut-off of the logged data (INS_GYRO_FILTER, IMU_GYRO_CUTOFF) and ``sampling`` ("point": latest filtered
    value logged; "average": delta angle / dt) for the report's white-noise term (``fit="model"``).
    """

    kind = "octave"

    def __init__(self, rate_hz, effects=DEFAULT_EFFECTS, forgetting_s=None, phases=16, max_tau_s=20000.0,
                 min_edf=1.0, fit="model", gls_max_ratio=256, filter_hz=None, sampling="point"):
        rate_hz = float(rate_hz)
        if filter_hz is not None and not (float(filter_hz) > 0 and math.isfinite(float(filter_hz))):
            raise ValueError(f"filter_hz must be a positive number (or null), got {filter_hz!r}")
        if sampling not in ("point", "average"):
            raise ValueError(f"sampling must be 'point' or 'average', got {sampling!r}")
        # the low-pass filter of the logged data (as the offline fit models it): its cut-off when the log
        # gives it, and how the samples were taken from the filtered signal; a roll-off is also looked for
        # in the data (companion.allan.fit.fit_avar detect_filter)
        self.filter_hz = None if filter_hz is None else float(filter_hz)
        self.sampling = sampling
        if not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ValueError(f"rate_hz must be a positive number, got {rate_hz!r}")
        phases = int(phases)
        if phases < 1 or phases & (phases - 1):
            raise ValueError(f"phases must be a power of 2 (1, 2, 4, 8, ...), got {phases}")
        if forgetting_s is not None:
            forgetting_s = float(forgetting_s)
            if not forgetting_s > 0:
                raise ValueError(f"forgetting_s must be positive (or null for no forgetting), got {forgetting_s}")
        max_tau_s = float(max_tau_s)
        if not max_tau_s > 0:
            raise ValueError(f"max_tau_s must be positive, got {max_tau_s}")
        self.rate_hz = rate_hz
        self.effects = check_effects(effects)
        self.forgetting_s = forgetting_s
        self.phases = phases
        self.max_tau_s = max_tau_s
        self.min_edf = float(min_edf)
        if fit not in FITS:
            raise ValueError(f"fit must be one of {', '.join(FITS)}, got {fit!r}")
        self.fit = fit
        self.gls_max_ratio = int(gls_max_ratio)
        self.levels = max(1, int(math.floor(math.log2(max(max_tau_s * rate_hz, 1.0)))) + 1)
        j = np.arange(self.levels)
        self._m = 2.0 ** j
        self._P = np.minimum(phases, 2 ** j).astype(np.int64)  # phases per level
        self._u = j - np.log2(self._P).astype(np.int64)  # pyramid level of the step blocks
        self._s = 2 ** self._u  # step in samples
        if forgetting_s is None:
            self._lam = np.ones(self.levels)
        else:
            self._lam = np.exp(-self._s / (forgetting_s * rate_hz))
        self._n = 0  # samples processed (not counting the buffer)
        self._y_ref = None  # first sample, subtracted from all (a constant does not change AVAR)
        self._pending = [None] * (int(self._u.max()) + 1)  # unpaired block per pyramid level (index u: level-u block)
        self._hist = [np.zeros(0) for _ in range(self.levels)]
        self._S = np.zeros(self.levels)
        self._cnt = np.zeros(self.levels, dtype=np.int64)  # Allan differences seen per level
        self._segs: list[int] = []  # lengths (samples) of the segments closed by new_segment()
        self._seg_base = 0  # samples of the closed segments no longer listed (forgotten: see new_segment)
        self._buf: list[float] = []
        self._cache: dict = {}  # Cholesky factors of the GLS covariance (derived data, not state)
        self._structure = None  # selected model (companion.estimators.online_report.Structure; derived, not state)
        self._report_cache = None  # the last report and what it was made from (derived, not state)
        self.n_rejected = 0

    # ------------------------------------------------------------------ updates
    @property
    def n_samples(self) -> int:
        return self._n + len(self._buf)

    def update(self, y) -> None:
        """Add one rate sample (float) or a 1-D block (SI, at ``rate_hz``). Non-finite samples are skipped
        and counted in ``n_rejected``. Identical results for any split of the same sequence."""
        if np.ndim(y) == 0:
            v = float(y)
            if math.isfinite(v):
                self._buf.append(v)
                if len(self._buf) >= _BUF:
                    self._flush()
            else:
                self.n_rejected += 1
            return
        y = np.asarray(y, dtype=float).ravel()
        self._flush()
        self._process(y)

    def new_segment(self) -> None:
        """The next samples do not follow the previous ones (another still piece of a log): no cluster
        straddles the junction; the accumulated levels are kept, so the estimates pool the pieces as the
        offline analysis does (companion.allan.pooled), and the report's covariance is the pooled one."""
        self._flush()
        done = self._n - self._seg_base - sum(self._segs)
        if done <= 0:
            return
        self._segs.append(int(done))
        if self.forgetting_s is not None:
            # with forgetting the list stays bounded: a segment followed by 20 memories of samples weighs e^-20
            old = 20.0 * self.forgetting_s * self.rate_hz
            while len(self._segs) > 1 and sum(self._segs[1:]) > old:
                self._seg_base += self._segs.pop(0)
        self._pending = [None] * len(self._pending)
        self._hist = [np.zeros(0) for _ in range(self.levels)]

    def segments(self) -> list[int]:
        """Sample counts of the pieces behind the estimates (one entry: one continuous record)."""
        self._flush()
        last = self._n - self._seg_base - sum(self._segs)
        return self._segs + ([int(last)] if last > 0 else [])

    def _flush(self) -> None:
        if self._buf:
            buf = np.array(self._buf)
            self._buf = []
            self._process(buf)

    def _process(self, y: np.ndarray) -> None:
        ok = np.isfinite(y)
        if not ok.all():
            self.n_rejected += int(y.size - ok.sum())
            y = y[ok]
        if y.size == 0:
            return
        if self._y_ref is None:
            self._y_ref = float(y[0])
        blocks = [y - self._y_ref]  # level-0 blocks are the samples
        for u in range(1, len(self._pending)):
            prev = blocks[u - 1]
            if self._pending[u] is not None:
                prev = np.concatenate(([self._pending[u]], prev))
            k = prev.size // 2
            blocks.append(prev[0:2 * k:2] + prev[1:2 * k:2])
            self._pending[u] = float(prev[-1]) if prev.size % 2 else None
        self._n += y.size
        for j in range(self.levels):
            P = int(self._P[j])
            new = blocks[self._u[j]]
            if new.size == 0:
                continue
            ext = np.concatenate((self._hist[j], new)) if self._hist[j].size else new
            h = self._hist[j].size
            keep = min(2 * P - 1, ext.size)
            self._hist[j] = ext[ext.size - keep:].copy()
            if ext.size < 2 * P:
                continue
            # cluster sums ending at local index k >= P-1, summed in a fixed order
            L = ext.size - P + 1
            c = ext[0:L].copy()
            for q in range(1, P):
                c += ext[q:q + L]
            # differences at local end index k >= 2P-1 and k >= h (new blocks only); c index = k - (P-1)
            k = np.arange(max(2 * P - 1, h), ext.size)
            if k.size == 0:
                continue
            d = c[k - (P - 1)] - c[k - (2 * P - 1)]
            self._cnt[j] += k.size
            x = d * d / (2.0 * self._m[j] ** 2)
            lam = self._lam[j]
            self._S[j] = exp_sum(x, lam, self._S[j])

    # ------------------------------------------------------------------ read-out
    def _events(self) -> np.ndarray:
        """Number of Allan differences seen per level."""
        return self._cnt

    def avar(self):
        """Current Allan variance per level: ``(tau, avar, edf)`` for levels with at least one difference."""
        self._flush()
        e = self._events()
        ok = e > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.forgetting_s is None:
                W = e.astype(float)
                n_eff = W
            else:
                r = self._s / (self.forgetting_s * self.rate_hz)
                W = np.expm1(-e * r) / np.expm1(-r)
                W2 = np.expm1(-2 * e * r) / np.expm1(-2 * r)
                n_eff = W * W / W2
            avar = self._S / W
        edf = n_eff / self._P
        tau = self._m / self.rate_hz
        return tau[ok], avar[ok], edf[ok]

    def n_effective(self) -> float:
        """Effective number of samples behind the estimates: n, or Kish's (1+l)/(1-l) ~ 2 T fs with forgetting."""
        n = float(self._n)
        if self.forgetting_s is None:
            return n
        r = 1.0 / (self.forgetting_s * self.rate_hz)
        return min(n, (1.0 + math.exp(-r)) / -math.expm1(-r))

    def terms(self, full: bool = False) -> list[dict]:
        """Current coefficients in SI units.

        ``fit="model"``: the model chosen from the data, each linear term resolved (value, ``std``, ``ci95``,
        ``"bound": False``) or as its 95 % upper bound (``"bound": True``), Gauss-Markov and sinusoid terms
        when selected (:func:`companion.estimators.online_report.estimator_report`; ``full`` forces a fresh model
        selection). Other fits: one term per configured linear effect (0 when not supported by the data),
        ``[{"effect": "white_noise", "N": v, "std": {"N": one_sigma}}, ...]``."""
        if self.fit == "model":
            from companion.estimators.online_report import estimator_report

            return estimator_report(self, full=full)
        effects = tuple(e for e in self.effects if e in LINEAR_EFFECTS)
        tau, avar, edf = self.avar()
        use = edf >= self.min_edf
        theta, s_theta, floor = fit_theta(tau[use], avar[use], edf[use], effects, return_floor=True)
        if self.fit == "fit_avar" and use.sum() > len(effects):
            theta, s_theta = self._fit_avar(tau[use], avar[use], edf[use], theta, s_theta)
        elif self.fit == "gls" and use.sum() > len(effects):
            theta, s_theta = fit_theta_gls(tau[use], avar[use], theta, effects, self.n_effective(),
                                           self.rate_hz, self.gls_max_ratio, cache=self._cache, floor=floor)
        out = []
        for e, th, st in zip(effects, theta, s_theta):
            p = LINEAR_PARAM[e]
            val = math.sqrt(max(th, 0.0))
            std = math.sqrt(max(th, 0.0) + st) - val if math.isfinite(st) else float("inf")
            out.append({"effect": e, p: val, "std": {p: std}})
        return out

    def _fit_avar(self, tau, avar, edf, theta_diag, std_diag):
        """The offline fit, :func:`companion.allan.fit.fit_avar` (GLS with the full model covariance of the
        Allan estimates, iterated from measured weights), on this bank's Allan variances; 1-sigma from its
        95 % interval as (hi - lo) / 3.92. Effects it sets to zero keep the diagonal fit's bound."""
        from companion.allan.fit import fit_avar

        m = np.round(tau * self.rate_hz).astype(np.int64)
        n = max(int(self.n_effective()), int(2 * m.max() + 2))
        # first weights as in `companion analyze`: white-noise EDF of the overlapping estimator (NIST SP 1065)
        edf0 = np.maximum(edf_simple(n + 1, m, 0), 0.5)
        effects = [e for e in self.effects if e in LINEAR_EFFECTS]
        fr = fit_avar(tau, avar, edf0, effects=effects, n=n, rate_hz=self.rate_hz, m=m,
                      max_ratio=self.gls_max_ratio)
        theta = np.zeros(len(effects))
        std = np.asarray(std_diag, float).copy()
        for i, e in enumerate(effects):
            t = next((t for t in fr.terms if t["effect"] == e), None)
            if t is None:
                continue
            p = LINEAR_PARAM[e]
            theta[i] = t[p] ** 2
            lo, hi = t["ci95"][p]
            sp = (hi - lo) / 3.92  # 1-sigma of p; back to theta = p^2 for the common read-out below
            std[i] = (t[p] + sp) ** 2 - t[p] ** 2
        return theta, std

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        """JSON-serialisable state; its size depends on the configuration only, not on the run length (but for
        one count per still segment: without forgetting all of them, with forgetting those of the last 20 memories)."""
        self._flush()
        return {
            "kind": self.kind,
            "version": 1,
            "config": {"rate_hz": self.rate_hz, "effects": list(self.effects), "forgetting_s": self.forgetting_s,
                       "phases": self.phases, "max_tau_s": self.max_tau_s, "min_edf": self.min_edf,
                       "fit": self.fit, "gls_max_ratio": self.gls_max_ratio, "filter_hz": self.filter_hz,
                       "sampling": self.sampling},
            "n": self._n,
            "n_rejected": self.n_rejected,
            "y_ref": self._y_ref,
            "pending": list(self._pending),
            "hist": [h.tolist() for h in self._hist],
            "S": self._S.tolist(),
            "cnt": self._cnt.tolist(),
            "segments": list(self._segs),
            "segments_base": self._seg_base,
        }

    @classmethod
    def from_state_dict(cls, d: dict) -> "OctaveBankEstimator":
        if d.get("kind") != cls.kind:
            raise ValueError(f"state is for estimator kind {d.get('kind')!r}, not {cls.kind!r}")
        est = cls(**d["config"])
        if len(d["S"]) != est.levels or len(d["pending"]) != len(est._pending):
            raise ValueError("estimator state does not match its configuration")
        est._n = int(d["n"])
        est.n_rejected = int(d.get("n_rejected", 0))
        est._y_ref = d["y_ref"]
        est._pending = [None if v is None else float(v) for v in d["pending"]]
        est._hist = [np.asarray(h, dtype=float) for h in d["hist"]]
        est._S = np.asarray(d["S"], dtype=float)
        if "cnt" in d:
            est._cnt = np.asarray(d["cnt"], dtype=np.int64)
        else:  # a state without the count: one continuous record
            est._cnt = np.maximum(est._n // est._s - (2 * est._P - 1), 0).astype(np.int64)
        est._segs = [int(x) for x in d.get("segments", [])]
        est._seg_base = int(d.get("segments_base", 0))
        return est
