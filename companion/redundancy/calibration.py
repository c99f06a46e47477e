"""The relative calibration of two IMUs on one body, fitted on the flight itself (numpy and scipy only).

Both gyros see the same body rate w through their own mounting: w_a = C_a w + n_a, w_b = C_b w + n_b. So

    w_b(t) ~ M w_a(t) + b + dt dw_a/dt (+ c d2w_a/dt2),

with M = C_b C_a^-1 the 3x3 relative scale and misalignment, b the bias difference, dt the time offset of b
behind a (the first term of the Taylor series of w_a(t + dt)), and c the second-order term by which two
different low-pass filters differ. dt is fitted with dw_b/dt as its instrument (instrumental variables): the
derivative of a's own noise in the regressor would otherwise shrink dt by the noise's share of dw_a/dt (a few %
in calm flight), and the motion left by that shrinkage lands in r at 0.5-2 s; the central difference of b is
uncorrelated with b's noise at the same instant, so the instrument is valid; c likewise with a second
difference of b that leaves b(t) out. On streams already equalized (every IMU through every IMU's filter) c is
not fitted: the filters no longer differ, and a term fitted on a's second derivative, which a calm flight's
noise dominates, would trade a's noise for motion left in r. Where the log gives both cut-offs, each stream is filtered with the other's
filter instead (both then went through the same two filters; gain 1 at 0 Hz, so the white-noise level is
unchanged) and c is not fitted. The least-squares fit is per axis of b over all pieces.

What is left, r = w_b - (M w_a + b + ...), holds n_b - M n_a: the true rotation and every common-mode vibration
cancel. M is fitted only where the motion dominates the noise (:data:`MIN_EXCITATION`): regressing on a noisy
w_a shrinks M by noise/motion variance (errors in variables), which would take part of n_a out of r; with too
little motion M = I is kept and the result says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: the motion's variance must exceed the noise's by this factor on every axis before M is fitted: the
#: attenuation of the fitted M (noise / motion variance) then costs at most 1 % of n_a's variance in r
MIN_EXCITATION = 100.0
#: filters within this fraction of each other are the same filter (no cross-filtering)
SAME_FILTER = 0.02
#: a cut-off at or above this fraction of the rate cannot be run at the logged rate (not cross-filtered)
MAX_FILTER_FRACTION = 0.45


@dataclass
class PairCalibration:
    """w_b ~ M w_a + bias + dt dw_a/dt (+ second-order term per axis): ``matrix`` (3, 3), ``bias`` (3,) rad/s,
    ``dt_s`` (3,) per axis, ``second`` (3,) s^2 (0 when the filters were known), ``fitted_matrix`` whether M was
    fitted (False: identity, too little motion), ``cross_filtered`` whether the log's filters were applied
    crosswise, ``excitation`` (3,) motion/noise variance ratios, ``notes``, ``shift_s`` the part of the offset applied as a
    fractional delay of a (``dt_s`` includes it)."""

    matrix: np.ndarray
    bias: np.ndarray
    dt_s: np.ndarray
    second: np.ndarray
    fitted_matrix: bool
    cross_filtered: bool
    excitation: np.ndarray
    notes: list = field(default_factory=list)
    shift_s: float = 0.0

    def to_dict(self) -> dict:
        return {"matrix": self.matrix.tolist(), "bias_rad_s": self.bias.tolist(), "dt_s": self.dt_s.tolist(),
                "second_s2": self.second.tolist(), "fitted_matrix": self.fitted_matrix,
                "cross_filtered": self.cross_filtered, "excitation": self.excitation.tolist(), "shift_s": self.shift_s,
                "notes": list(self.notes)}


def _butter(fc: float, rate: float):
    from scipy import signal

    return signal.butter(2, fc, fs=rate)


def _lfilter(ba, x: np.ndarray) -> np.ndarray:
    from scipy import signal

    b, a = ba
    zi = signal.lfilter_zi(b, a)[:, None] * x[0][None, :]
    return signal.lfilter(b, a, x, axis=0, zi=zi)[0]


def cross_filter(pa: list, pb: list, fa, fb, rate: float):
    """Each stream's pieces filtered with the other's 2-pole low-pass where both cut-offs are known, differ
    and can run at ``rate``. Returns (pa, pb, applied)."""
    if not fa or not fb or abs(fa - fb) <= SAME_FILTER * max(fa, fb):
        return pa, pb, False
    if max(fa, fb) >= MAX_FILTER_FRACTION * rate:
        return pa, pb, False
    ba_a, ba_b = _butter(fa, rate), _butter(fb, rate)
    return [_lfilter(ba_b, x) for x in pa], [_lfilter(ba_a, x) for x in pb], True


def _derivatives(pieces: list, rate: float):
    d1 = [np.gradient(x, 1.0 / rate, axis=0) for x in pieces]
    d2 = [np.gradient(d, 1.0 / rate, axis=0) for d in d1]
    return np.vstack(d1), np.vstack(d2)


def _excitation(resid: np.ndarray, pieces_a: list) -> np.ndarray:
    """Per axis: variance of the motion (of w_a, each piece's mean removed) over the noise variance (half the
    residual variance of the full fit, at most: what the model leaves out counts too)."""
    centred = np.vstack([x - x.mean(axis=0) for x in pieces_a])
    noise = np.var(resid, axis=0) / 2.0
    return np.var(centred, axis=0) / np.maximum(noise, 1e-30)


def _solve(X: np.ndarray, y: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """Instrumental-variable least squares (Z'X) coef = Z'y, columns scaled to unit variance (the derivative
    columns are 10^3-10^6 larger)."""
    s = np.sqrt(np.mean(X * X, axis=0))
    s = np.where(s > 0, s, 1.0)
    sz = np.sqrt(np.mean(Z * Z, axis=0))
    sz = np.where(sz > 0, sz, 1.0)
    Xs, Zs = X / s, Z / sz
    coef = np.linalg.lstsq(Zs.T @ Xs, Zs.T @ y, rcond=None)[0]
    return coef / s


#: half-length (taps each side) of the windowed-sinc fractional delay; the shifted pieces lose this many
#: samples at each end
SHIFT_TAPS = 16
#: Kaiser window parameter of the fractional delay (flat within 0.1 % to 0.8 of the Nyquist frequency)
SHIFT_BETA = 6.0
#: rounds of shift-and-refit (the first-order term left after a shift is far below a sample)
SHIFT_ROUNDS = 2
#: an offset below this fraction of a sample is left to the first-order term (no shift)
MIN_SHIFT = 0.01


def fractional_delay(x: np.ndarray, delay: float) -> np.ndarray:
    """x(t + delay) per column, ``delay`` in samples (|delay| < SHIFT_TAPS), by a Kaiser-windowed sinc of gain 1
    at 0 Hz; the first and last SHIFT_TAPS samples are not valid (the caller trims them)."""
    k = np.arange(-SHIFT_TAPS, SHIFT_TAPS + 1, dtype=float)
    h = np.sinc(k - delay) * np.kaiser(k.shape[0], SHIFT_BETA)
    h /= h.sum()
    out = np.empty_like(x, dtype=float)
    for j in range(x.shape[1]):
        out[:, j] = np.convolve(x[:, j], h[::-1], mode="same")
    return out


def _trim(pieces: list) -> list:
    return [p[SHIFT_TAPS:-SHIFT_TAPS] for p in pieces]


def _second_instrument(pieces: list, rate: float) -> np.ndarray:
    """(b(t+2) + b(t-2) - b(t+1) - b(t-1)) / (3 tau0^2) per piece (~ b''; the ends 0): it leaves out b(t), so
    it is uncorrelated with white noise of b at t, which the plain second difference (weight -2 on b(t)) is
    not; a's own second derivative as its instrument would carry a's noise (errors in variables)."""
    out = []
    for x in pieces:
        y = np.zeros_like(x, dtype=float)
        if x.shape[0] > 4:
            y[2:-2] = (x[4:] + x[:-4] - x[3:-1] - x[1:-3]) * (rate * rate / 3.0)
        out.append(y)
    return np.vstack(out)


def _fit_once(pa: list, pb: list, rate: float, second: bool):
    """One instrumental-variable fit per axis: (M, bias, dt, c2, residual (n, 3)); c2 only with ``second``."""
    A, B = np.vstack(pa), np.vstack(pb)
    d1, d2 = _derivatives(pa, rate)
    e1, _ = _derivatives(pb, rate)
    e2 = _second_instrument(pb, rate) if second else None
    M, bias, dt, c2 = np.eye(3), np.zeros(3), np.zeros(3), np.zeros(3)
    ones = np.ones((A.shape[0], 1))
    for k in range(3):
        cols = [A, ones, d1[:, [k]]] + ([d2[:, [k]]] if second else [])
        inst = [A, ones, e1[:, [k]]] + ([e2[:, [k]]] if second else [])
        coef = _solve(np.hstack(cols), B[:, k], np.hstack(inst))
        M[k], bias[k], dt[k] = coef[:3], coef[3], coef[4]
        c2[k] = coef[5] if second else 0.0
    return M, bias, dt, c2, B - (A @ M.T + bias + d1 * dt + d2 * c2)


def _shifted(pa: list, pb: list, shift_s: float, rate: float):
    """a advanced by ``shift_s`` (fractional delay) and b, both trimmed to the valid samples."""
    if shift_s == 0.0:
        return pa, pb
    d = float(np.clip(shift_s * rate, -SHIFT_TAPS / 2, SHIFT_TAPS / 2))
    keep = [i for i, p in enumerate(pa) if p.shape[0] > 3 * SHIFT_TAPS]
    return _trim([fractional_delay(pa[i], d) for i in keep]), _trim([pb[i] for i in keep])


def fit_pair(pa: list, pb: list, rate: float, filters=(None, None), *, equalized: bool = False
             ) -> tuple[PairCalibration, list]:
    """The relative calibration of b on a over their aligned pieces (lists of (n, 3) arrays), and the
    residual pieces r = w_b - model(w_a). The time offset is applied as a fractional delay of a (one for the
    three axes: the median of the axes' first-order terms, SHIFT_ROUNDS rounds): the first-order term alone
    misses a delay's effect on vibration at tens of Hz. ``equalized``: the pieces already went through the
    same cascade of filters (no second-order term, no cross-filtering)."""
    pa, pb, crossed = cross_filter(pa, pb, filters[0], filters[1], rate)
    second = not (crossed or equalized)
    M, bias, dt, c2, resid = _fit_once(pa, pb, rate, second)
    shift = 0.0
    can_shift = any(p.shape[0] > 3 * SHIFT_TAPS for p in pa)  # else the shift would leave no piece
    for _ in range(SHIFT_ROUNDS):
        if abs(float(np.median(dt))) * rate < MIN_SHIFT or not can_shift:
            break  # far below a sample (slow telemetry): the first-order term carries it, no piece is trimmed
        shift += float(np.median(dt))
        sa, sb = _shifted(pa, pb, shift, rate)
        M, bias, dt, c2, resid = _fit_once(sa, sb, rate, second)
    exc = _excitation(resid, pa)
    fit_m = bool(np.all(exc >= MIN_EXCITATION))
    notes = []
    if not fit_m:
        notes.append(f"too little motion to fit the relative scale/misalignment (motion/noise variance "
                     f"{exc.min():.3g} < {MIN_EXCITATION:g}): identity assumed, no time offset fitted")
        M, dt, c2, shift = np.eye(3), np.zeros(3), np.zeros(3), 0.0
        bias = np.mean(np.vstack(pb) - np.vstack(pa), axis=0)
    if crossed:
        notes.append(f"the log's low-pass filters ({filters[0]:g} / {filters[1]:g} Hz) applied crosswise")
    cal = PairCalibration(M, bias, dt + shift, c2, fit_m, crossed, exc, notes, shift)
    return cal, residuals(cal, pa, pb, rate)


def residuals(cal: PairCalibration, pa: list, pb: list, rate: float) -> list:
    """r = w_b - (M w_a(t + shift) + bias + dt' dw_a/dt + c d2w_a/dt2) per piece (dt' = dt - shift, the part
    of the offset left after the shift; the pieces as :func:`fit_pair` saw them, i.e. after any
    cross-filtering; shifted pieces lose SHIFT_TAPS samples at each end)."""
    sa, sb = _shifted(pa, pb, cal.shift_s, rate)
    rest = cal.dt_s - cal.shift_s
    out = []
    for a, b in zip(sa, sb):
        d1 = np.gradient(a, 1.0 / rate, axis=0)
        d2 = np.gradient(d1, 1.0 / rate, axis=0)
        out.append(b - (a @ cal.matrix.T + cal.bias + d1 * rest + d2 * cal.second))
    return out
