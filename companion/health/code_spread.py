"""How a block's samples spread over the codes of a quantised gyro: the statistics that tell a value frozen
near a code boundary (it flips between two adjacent codes) from healthy noise (it also lands beyond them).
Used by :class:`companion.health.stuck.StuckDetector`; the derivations are in the docstrings below.

Only numpy and the standard library: the live pipeline loads no scipy (seconds of start-up and tens of MB on a
small board), so the normal CDF is built from ``math.erfc`` and its inverse from :class:`statistics.NormalDist`.
"""

from __future__ import annotations

import functools
import math
from statistics import NormalDist

import numpy as np

Q_RATIO = 20.0  #: the frozen hypothesis' rate of samples beyond two codes: 1/20 of the healthy one
MAX_CODES = 64  #: a block spread over more codes than this is no frozen value
LEVEL_STEP = 0.005  #: LSB: the grid the healthy level is profiled on (fine against the noise of 0.3 LSB and up)


def two_code_outside(y: np.ndarray, lsb: float) -> int:
    """Samples of a block beyond the two adjacent codes that hold the most of them (0: at most two codes)."""
    c = np.round(np.asarray(y, dtype=float) / lsb)
    lo = c.min()
    if c.max() - lo > MAX_CODES:
        return int(c.shape[0])
    cnt = np.bincount((c - lo).astype(np.int64), minlength=2)
    return int(c.shape[0] - (cnt[:-1] + cnt[1:]).max())


def two_code_llr(k: float, n: float, q0: float) -> float:
    """Evidence (nats) of a block's ``k`` samples beyond its two best adjacent codes among ``n``: a value
    frozen with a dither far below the step (rate q0 / ``Q_RATIO``) against a healthy gyro (rate q0). What
    clears a stuck axis (each sample beyond two codes is -3 nats); :func:`codes_glr` names it.

    A frozen value with a dither d << LSB rounds to one code, or flips between two adjacent codes when it
    lies near their boundary; then its repeated codes and its variance look like a healthy gyro's of
    ~0.5 LSB, and only the spread over codes tells them apart: healthy noise s (LSB) also lands beyond two
    codes, least often when its level sits on a boundary: q0 = 2 Phi(-1 / s) (0.005 at s = 0.36 LSB), the
    rate used, so that at any level a healthy gyro's expected LLR is negative. The SPRT LLR
    k ln(q1 / q0) + (n - k) ln((1 - q1) / (1 - q0)) is about n q0 for a block within two codes (0.26 nats
    for 50 samples at s = 0.36: the information is thin, a value frozen right on a boundary takes over a
    minute) and -3 nats for each sample beyond. Off a boundary a frozen value repeats one code and the
    repeated-codes evidence names it at once."""
    if n <= 0 or not (0.0 < q0 < 0.5):
        return 0.0
    q1 = q0 / Q_RATIO
    return k * math.log(q1 / q0) + (n - k) * math.log((1.0 - q1) / (1.0 - q0))


def codes_glr(lo: int, counts: np.ndarray, s: float, q1: float) -> float:
    """Evidence (nats) of the counts of codes ``lo``, ``lo`` + 1, ... (samples) for a value frozen near a
    code boundary against a healthy gyro of noise ``s`` (LSB), each at its most likely parameter.

    The samples are read as three counts: in the two adjacent codes k, k + 1 that hold the most of them,
    and beyond them. Frozen: they flip between k and k + 1 with some probability p (any p: the dither and
    the distance to the boundary are unknown) and land beyond them at a rate ``q1``. Healthy: a level mu
    plus noise s puts P_k(mu), P_k+1(mu) (P_c = Phi((c + 1/2 - mu) / s) - Phi((c - 1/2 - mu) / s)) and the
    rest, Q(mu), beyond them. The split between the two codes tells where a healthy level would be, and
    there its share beyond them (least on the boundary: 2 Phi(-1/s), more off it) is what the frozen
    value lacks: a split of 23:77 puts a healthy level of 0.47 LSB noise 0.35 LSB off the boundary, where
    8.6 % of its samples leave the two codes (3.3 % on the boundary). About ln((1 - q1) / (1 - q0)) per
    sample on a boundary, as the count beyond two codes alone gives; n ln(1 / P_k) for a single code (a
    healthy level at the code's centre). Which codes the samples beyond the pair hit is not used: a block
    the healthy model does not fit (motion starting, a noisier period) must not count as frozen."""
    if s <= 0 or not (0.0 < q1 < 1.0):
        return 0.0
    return float(_glr(np.asarray([_three_counts(np.asarray(counts, dtype=float))]), s, q1)[0])


def _three_counts(counts: np.ndarray) -> tuple[float, float, float]:
    """(in code k, in code k + 1, beyond them) for the two adjacent codes holding the most samples."""
    return _pair_counts(counts)[1:]


def _pair_counts(counts: np.ndarray) -> tuple[int, float, float, float]:
    """(k, in code k, in code k + 1, beyond them), k the index of the two adjacent codes holding the most."""
    if counts.shape[0] < 2:
        return 0, float(counts.sum()), 0.0, 0.0
    j = int(np.argmax(counts[:-1] + counts[1:]))
    n_a, n_b = float(counts[j]), float(counts[j + 1])
    return j, n_a, n_b, float(counts.sum()) - n_a - n_b


_STD_NORMAL = NormalDist()
_ERFC = np.frompyfunc(math.erfc, 1, 1)


def _ndtr(x: np.ndarray) -> np.ndarray:
    """Standard normal CDF, elementwise: erfc(-x / sqrt 2) / 2."""
    return 0.5 * _ERFC(-np.asarray(x, dtype=float) / math.sqrt(2.0)).astype(float)


@functools.lru_cache(maxsize=64)
def _level_logs(s: float) -> np.ndarray:
    """ln P_k, ln P_k+1 and ln of the rest for a healthy level on the grid of :func:`_glr` (3, levels): the
    noise is learned slowly, so the same few values recur (rounded to 0.001 LSB)."""
    mu = np.arange(-1.0, 2.0 + 1e-9, LEVEL_STEP)
    pa = _ndtr((0.5 - mu) / s) - _ndtr((-0.5 - mu) / s)
    pb = _ndtr((1.5 - mu) / s) - _ndtr((0.5 - mu) / s)
    logs = np.log(np.maximum(np.vstack([pa, pb, 1.0 - pa - pb]), 1e-300))
    logs.flags.writeable = False
    return logs


def _glr(n: np.ndarray, s: float, q1: float) -> np.ndarray:
    """:func:`codes_glr` of rows of three counts (n_k, n_k+1, beyond). The healthy level is profiled on a
    grid relative to code k (0.005 LSB from 1 LSB below it to 2 above: where the pair can be the most
    likely; off the grid the healthy shares only fall), the same grid for every row."""
    healthy = np.max(n @ _level_logs(round(s, 3)), axis=1)
    n2 = n[:, 0] + n[:, 1]
    frozen = n[:, 2] * math.log(q1) + n2 * math.log(1.0 - q1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for col in (0, 1):
            frozen = frozen + np.where(n[:, col] > 0, n[:, col] * np.log(n[:, col] / np.maximum(n2, 1e-300)), 0.0)
    return np.where(n.sum(axis=1) > 0, frozen - healthy, 0.0)


@functools.lru_cache(maxsize=64)
def _jitter_kernel(tau: float) -> np.ndarray:
    """A normal density of sd ``tau`` (LSB) on the level grid of :func:`_level_logs` (weights summing to 1)."""
    h = max(1, int(math.ceil(4.0 * tau / LEVEL_STEP)))
    x = np.arange(-h, h + 1) * LEVEL_STEP
    w = np.exp(-0.5 * (x / tau) ** 2)
    w = w / w.sum()
    w.flags.writeable = False
    return w


def _block_level_logs(row: np.ndarray, s: float, f: float, tau: float) -> np.ndarray:
    """ln of one block's likelihood (three counts ``row`` relative to a pair of codes) at each level of the grid
    of :func:`_level_logs`, its samples worth ``f`` independent ones each, its level spread around the grid's
    by a normal jitter of sd ``tau`` (LSB) of its own (a healthy level moves from block to block)."""
    ll = f * (row @ _level_logs(round(s, 3)))
    if tau <= 0.0:
        return ll
    top = float(ll.max())
    conv = np.convolve(np.exp(ll - top), _jitter_kernel(round(tau, 3)), mode="same")
    return np.log(np.maximum(conv, 1e-300)) + top
