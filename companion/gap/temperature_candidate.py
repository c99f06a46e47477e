"""A temperature-driven rate: the candidate built from the log's own temperature channel, and its check.

A MEMS gyro's bias follows its temperature (a few deg/h per K is common). When the log carries the IMU
temperature T(t), the effect "the rate contains coef x T(t)" has a known shape: its Allan variance is
coef^2 x AVAR[T](tau), the Allan variance of the temperature record itself (pooled over the same still
segments, at the same cluster sizes). That makes it one more candidate with one magnitude (coef^2 enters
linearly) to weigh head to head with a ramp, a random walk, a Gauss-Markov term: a drift that follows
the temperature curve is named "temperature", one that does not is not.

The temperature channel is smoothed first (a centred moving average over 2 s): the temperature sensor's
own quantisation and noise are not in the gyro, and the thermal response of the bias is slow.

Check against the channel (:func:`regression_check`): the least-squares slope of the rate on T with a
linear ramp beside it (each segment's means removed; a warm-up that only rises is no evidence against a
plain drift) with its standard error from the residual's lag-1 autocorrelation; the Allan-fitted |coef| is
"confirmed" when it lies within a factor 2 of |slope| and the slope is significant (|t| > 3).
"""

from __future__ import annotations

import math

import numpy as np

from companion.allan.pooled import pooled_oavar

#: span of the centred moving average on the temperature channel, s: longer than the sensor's own noise and
#: quantisation steps, shorter than the bias's thermal response
SMOOTH_S = 2.0


def _smooth(t, rate_hz):
    k = max(1, int(round(SMOOTH_S * rate_hz)))
    if t.shape[0] <= k:
        return t - t.mean()
    c = np.convolve(t, np.ones(k) / k, mode="same")
    # the edges average fewer samples: leave them at the nearest full average
    h = k // 2
    c[:h] = c[h]
    c[-h:] = c[-h - 1]
    return c


def thermal_term(temp_segments, rate_hz: float, tau) -> tuple[dict | None, list]:
    """The unit temperature term (coef 1 rad/s per K) at the cluster times ``tau``, and the smoothed
    temperature segments; (None, []) when the channel is missing, not finite or flat (range < 0.05 K)."""
    if temp_segments is None:
        return None, []
    segs = [np.asarray(s, dtype=float) for s in temp_segments]
    if not segs or any(s.size == 0 or not np.all(np.isfinite(s)) for s in segs):
        return None, []
    if max(float(np.ptp(s)) for s in segs) < 0.05:
        return None, []
    smooth = [_smooth(s, rate_hz) for s in segs]
    m = np.maximum(np.rint(np.asarray(tau) * rate_hz).astype(np.int64), 1)
    t_tau, t_avar, _, _ = pooled_oavar(smooth, rate_hz, m=m)
    ok = np.isfinite(t_avar) & (t_avar > 0)
    if ok.sum() < 2:
        return None, []
    return {"effect": "temperature", "coef": 1.0, "unit_tau": t_tau[ok].tolist(),
            "unit_avar": t_avar[ok].tolist()}, smooth


def regression_check(y_segments, temp_smooth, coef: float, rate_hz: float = 1.0) -> dict:
    """Slope of the rate on the (smoothed) temperature, with a linear ramp in time beside it (each
    segment's means removed), its standard error (residual variance inflated by (1 + rho)/(1 - rho), rho
    the residual's lag-1 autocorrelation), and whether the Allan-fitted ``coef`` agrees with it. With the
    ramp in the regression a warm-up that only rises cannot pass for a temperature effect: the channel
    must explain the rate beyond a straight drift (the part of T that is not a ramp)."""
    ys, ts, xs = [], [], []
    for y, t in zip(y_segments, temp_smooth):
        y = np.asarray(y, dtype=float)
        t = np.asarray(t, dtype=float)
        x = np.arange(y.shape[0], dtype=float) / rate_hz
        ys.append(y - y.mean())
        ts.append(t - t.mean())
        xs.append(x - x.mean())
    ys, ts, xs = np.concatenate(ys), np.concatenate(ts), np.concatenate(xs)
    X = np.column_stack([ts, xs])
    XtX = X.T @ X
    try:
        inv = np.linalg.inv(XtX)
    except np.linalg.LinAlgError:
        return {"slope": 0.0, "se": math.inf, "t": 0.0, "confirmed": False, "coef": coef, "ratio": math.inf}
    beta = inv @ (X.T @ ys)
    slope = float(beta[0])
    res = ys - X @ beta
    rho = float(np.clip(np.dot(res[1:], res[:-1]) / max(np.dot(res, res), 1e-300), -0.99, 0.999))
    se = math.sqrt(max(float(np.var(res)) * inv[0, 0] * (1 + rho) / (1 - rho), 0.0))
    tval = slope / se if se > 0 else 0.0
    ratio = abs(coef) / abs(slope) if slope != 0 else math.inf
    return {"slope": slope, "se": se, "t": tval, "coef": coef, "ratio": ratio,
            "confirmed": bool(abs(tval) > 3 and 0.5 <= ratio <= 2.0)}
