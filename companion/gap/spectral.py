"""Spectral check of a sinusoid named from the Allan curve: is there a line in the periodogram?

The Allan curve of a sinusoid (IEEE 952 C.7) is a bump near tau = 0.371 / f0; other shapes (the roll-off of
a low-pass filter, a band of vibration) can produce a similar bump, so a sinusoid named from the Allan
curve alone is checked against the data's power spectral density.

* PSD: Welch's method (Hann window, 50 % overlap, scipy.signal.welch), one-sided, segments of at least
  16 periods of f0 (so the line falls in one or two bins) and at most the record.
* Local level: a parabola fitted in log-log to the PSD over [f0/2, 2 f0] without the band f0 (1 +- 10 %),
  shifted by its median residual (robust to a neighbouring peak), so that a sloping or bending noise floor
  (a filter's roll-off) is not mistaken for a peak.
* Peak ratio: the largest PSD bin in the band over the local level there. Under noise alone each Welch
  bin is level * chi^2_nu / nu with nu ~ 1.8 x (number of segments) (Hann, 50 % overlap; Percival & Walden
  1993 sec. 6.17 give 2K/(1 + 2 c^2), c ~ 0.17), so the peak is significant when above
  chi^2_nu(1 - 1e-3 / bins) / nu.
* Line amplitude: A_spec = sqrt(2 x excess power in the band) (a sinusoid of amplitude A carries A^2/2).

The line is *confirmed* when the peak is significant and A_spec >= 0.5 A, i.e. the periodogram holds at
least a quarter of the power that the Allan fit gave the sinusoid.

The line is *ruled out* when the peak is not significant although the periodogram had the resolution to
show it: a line of 0.5 A (a quarter of the fitted power) anywhere in the band would make the peak
significant with probability >= 1 - 1e-3 (``power``). A Hann-windowed line of amplitude a adds
(a^2/2) / (1.5 df) to its bin, x0.72 at the worst placement between two bins (scalloping, 1.42 dB); the
Welch average is then level x noncentral chi^2_nu(lambda) / nu with lambda = nu x that excess / level.
A short record (few segments at the line's frequency) has little power and rules nothing out: an
unconfirmed line there still stands on the Allan curve alone.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats
from scipy.signal import welch

#: half-width of the band searched around f0, relative
REL_BAND = 0.10
#: the share of the Allan-fitted amplitude the periodogram must hold (0.5 in amplitude = 25 % in power)
MIN_AMPLITUDE_SHARE = 0.5
#: level of the periodogram's line test over the band's bins (Bonferroni), and 1 - the power to rule one out
ALPHA = 1e-3
#: Hann window: equivalent noise bandwidth in bins, and the worst-case power loss between two bins
HANN_ENBW = 1.5
HANN_SCALLOP = 10 ** (-1.42 / 10)


def line_evidence(y, rate_hz: float, freq_hz: float, amplitude: float) -> dict | None:
    """Periodogram evidence for a sinusoid of ``amplitude`` at ``freq_hz`` in rate samples ``y``.

    Returns {f_peak, peak_ratio, threshold, amplitude_psd, confirmed, power, ruled_out, segments} or None
    when the record is too short to resolve the band (fewer than 4 background bins)."""
    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    if n < 256 or not (0 < freq_hz < rate_hz / 2):
        return None
    seg = 1 << int(math.ceil(math.log2(max(256.0, 16.0 * rate_hz / freq_hz))))
    seg = min(seg, 1 << int(math.floor(math.log2(n))))
    f, P = welch(y - y.mean(), fs=rate_hz, nperseg=seg)
    df = f[1]
    segments = max(1, 2 * n // seg - 1)
    band = (f >= freq_hz * (1 - REL_BAND) - df) & (f <= freq_hz * (1 + REL_BAND) + df) & (f > 0)
    # the Nyquist bin is not doubled in a one-sided estimate (half the level): kept out of the background fit
    outer = (f >= freq_hz / 2) & (f <= 2 * freq_hz) & (f < rate_hz / 2) & ~band & (f > 0) & (P > 0)
    if band.sum() == 0 or outer.sum() < 4:
        return None
    lf, lp = np.log(f[outer]), np.log(P[outer])
    coef = np.polyfit(lf, lp, 2)
    coef[-1] += float(np.median(lp - np.polyval(coef, lf)))  # median residual: robust to a neighbouring peak
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # only the band's bins are used; the
        # parabola extrapolated far from [f0/2, 2 f0] may overflow or underflow there
        level = np.exp(np.polyval(coef, np.log(np.where(f > 0, f, df))))
        k = int(np.argmax(np.where(band, P / level, -np.inf)))
    peak_ratio = float(P[k] / level[k])
    nu = 1.8 * segments
    threshold = float(stats.chi2.isf(ALPHA / band.sum(), nu) / nu)
    excess = float(np.sum(np.maximum(P[band] - level[band], 0.0)) * df)
    amp_psd = math.sqrt(2.0 * excess)
    significant = peak_ratio > threshold
    # power against a line carrying a quarter of the fitted power, at the band's highest local level
    line_bin = HANN_SCALLOP * (MIN_AMPLITUDE_SHARE * amplitude) ** 2 / 2.0 / (HANN_ENBW * df)
    lam = nu * line_bin / float(np.max(level[band]))
    power = float(stats.ncx2.sf(threshold * nu, nu, lam))
    return {"f_peak": float(f[k]), "peak_ratio": peak_ratio, "threshold": threshold, "amplitude_psd": amp_psd,
            "confirmed": bool(significant and amp_psd >= MIN_AMPLITUDE_SHARE * amplitude),
            "power": power, "ruled_out": bool(not significant and power >= 1.0 - ALPHA),
            "segments": segments}


#: at most this many lines are offered as candidates (the strongest peaks first)
MAX_LINES = 3
#: running-median width (bins) of the periodogram's background level, and the bins either side of a peak
#: that hold a Hann-windowed line's power
MEDIAN_BINS, LINE_BINS = 21, 2
#: a line is offered only at or above this many bins (its frequency then known within 1/32, 3 %, the
#: resolution line_evidence asks for: segments of at least 16 periods); a slower line is left to the Allan
#: curve's search (a 0.5 Hz line at 50 Hz falls between bins 0.2 Hz apart)
MIN_PERIODS = 16


def significant_lines(y, rate_hz: float, max_lines: int = MAX_LINES) -> tuple:
    """The vibration lines the periodogram of ``y`` shows: ((f_peak Hz, amplitude), ...), strongest first.

    Welch periodogram (Hann, 50 % overlap) of segments of 256 samples (at most an eighth of the record,
    at least 64); background level: the running median of MEDIAN_BINS bins, over the median of
    chi^2_nu / nu (Wilson-Hilferty, (1 - 2/(9 nu))^3), reflected at the Nyquist frequency (a sampled
    process's spectrum is even about it; a fit from below alone extrapolates, and named noise near Nyquist
    a line in a third of filtered records). A local maximum is a line when above chi^2_nu(1 - 1e-3 / bins)
    / nu of that level, the level over *all* the periodogram's bins, since its frequency is searched. The
    amplitude: sqrt(2 x the excess power of the peak bin and LINE_BINS either side). The Nyquist bin (half
    the level in a one-sided estimate, and where a line cannot be told from its alias) is left out.
    Lines below MIN_PERIODS bins are left out (the bin too wide for the frequency). The Allan curve
    places a line near the Nyquist frequency only to within tens of percent (its octave cluster times see
    it at tau0 alone); the periodogram resolves it to a bin."""
    from scipy.ndimage import median_filter

    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    if n < 512:
        return ()
    seg = int(min(256, max(64, 1 << int(math.floor(math.log2(n / 8))))))
    f, P = welch(y - y.mean(), fs=rate_hz, nperseg=seg)
    if seg % 2 == 0:  # the Nyquist bin
        f, P = f[:-1], P[:-1]
    if P.shape[0] < MEDIAN_BINS + 4:
        return ()
    segments = max(1, 2 * n // seg - 1)
    nu = 1.8 * segments
    level = median_filter(P, size=MEDIAN_BINS, mode="reflect") / (1.0 - 2.0 / (9.0 * nu)) ** 3
    ratio = P / np.maximum(level, 1e-300)
    threshold = float(stats.chi2.isf(ALPHA / P.shape[0], nu) / nu)
    k = np.arange(1, P.shape[0])
    right = np.append(P[2:], P[-2])  # reflected at the top
    peaks = k[(P[k] > P[k - 1]) & (P[k] >= right) & (ratio[k] > threshold)]
    peaks = peaks[np.argsort(-ratio[peaks])]
    df = float(f[1])
    out = []
    for i in peaks:
        if len(out) >= max_lines:
            break
        fp = float(f[i])
        if fp < MIN_PERIODS * df:  # the bin is too wide to place the line better than the Allan curve does
            continue
        if any(abs(fp - g) <= REL_BAND * g for g, _ in out):
            continue
        sl = slice(max(i - LINE_BINS, 1), min(i + LINE_BINS + 1, P.shape[0]))
        excess = float(np.sum(np.maximum(P[sl] - level[sl], 0.0)) * df)
        out.append((fp, math.sqrt(2.0 * excess)))
    return tuple(out)
