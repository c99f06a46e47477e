"""Motion gate of one IMU: is a block still? From the accelerometer and the agreement of IMUs and axes,
never from one gyro axis' own noise level (a gyro whose noise jumps while the accel and the other IMUs
stay quiet is faulty, not moving).

* accel: |accel| std above ``accel_std``, the mean accel vector ``accel_shift`` away from the still
  reference (a new attitude), or an accel axis' std above ``accel_std_factor`` x its still reference and
  above ``accel_std_min`` (handling, vibration);
* rotation: the block mean rate above ``gyro_mean`` and significant against the block's own noise
  (5 sigma), on the IMU agreeing most with "no rotation" when others exist (per axis the smaller |mean|
  of two, the median of three): one frozen or biased gyro cannot declare motion; with one IMU only the
  rotation about gravity counts (a rotation about a horizontal axis tilts the vehicle and shows in the
  accel shift test; a gyro drifting or frozen at a rate alone is not motion);
* vibration: with other IMUs, their gyros vibrating too (an axis above ``gyro_std_factor`` x its still
  noise on this and on another IMU); alone, two axes of this gyro above it and the accel axis std above
  1.5x its reference.

The references are learned from the blocks the gate calls still, so a vehicle vibrating from its first block
on (an engine running on the ground with no armed state to tell) teaches the gate that vibration is rest.
Vibration cannot make the accelerometer quieter than the sensor's own noise, so ``QUIET_BLOCKS`` blocks in a
row with an accel axis ``QUIETER`` x below its reference show that what was learned as rest on that axis was
not (vibration, or a first block taken with the vehicle in hand): the axis' reference becomes their level and
:attr:`MotionGate.mislearned` tells the caller to drop what it learned and fed under the old one. Sampling
alone cannot do it (the std of a 10-sample block is 4x below its truth with probability about 5e-5, three
blocks in a row about 1e-13 per axis; blocks of fewer than ``QUIET_MIN_SAMPLES`` samples do not count, nor
does an axis that stops (std exactly 0), and a quantised axis' smallest nonzero std, one sample of 10-50 off
the others, is 0.14-0.3 LSB, not 4x below a reference of a noise that moves it).

Inputs: the block (rows ``t, gyro, accel``), its BlockStats, this IMU's noise ratios and the other IMUs'
(:class:`Peer`); output: still or not. State: the still accel reference (mean and per-axis std).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from companion.health.block_stats import BlockStats

REF_WEIGHT = 0.05  # EWMA weight of a still block in the accel reference
QUIETER = 4.0  # an accel axis this many times quieter than its reference ...
QUIET_BLOCKS = 3  # ... in this many blocks in a row: the reference was learned under vibration
QUIET_MIN_SAMPLES = 8  # a block's std from fewer samples is too loose for that test
GLITCH_K = 10.0  # robust sigmas: an isolated accelerometer sample this far off is a glitch, not motion


@dataclass
class Peer:
    """What the gate needs of another IMU's latest block: its statistics and noise ratios v2 / sigma0^2."""

    stats: BlockStats
    noise_ratio: np.ndarray | None


def without_glitches(a: np.ndarray) -> np.ndarray:
    """The accelerometer block with isolated one-sample outliers (beyond ``GLITCH_K`` robust sigmas of the
    distance to the median of the sample and its four neighbours, neither neighbour beyond half of that)
    set to that median. A glitch of the IMU (a corrupted sample, often in gyro and accelerometer at once)
    would lift the block's accel std, the gate would call the block motion and the gyro glitch would be
    weighed as vibration, never named as spikes. A knock or a handling moves several samples in a row and
    stays."""
    n = a.shape[0]
    if n < 5 or not np.all(np.isfinite(a)):
        return a
    pad = np.concatenate([a[:1], a[:1], a, a[-1:], a[-1:]])
    win = np.lib.stride_tricks.sliding_window_view(pad, 5, axis=0)  # (n, 3, 5)
    med = np.median(win, axis=-1)
    dev = np.abs(a - med)
    s = 1.4826 * np.median(dev, axis=0)
    if not np.all(s > 0):
        return a
    big = dev > GLITCH_K * s
    half = dev > 0.5 * GLITCH_K * s
    nb = np.zeros_like(half)
    nb[1:] |= half[:-1]
    nb[:-1] |= half[1:]
    glitch = big & ~nb
    if not glitch.any():
        return a
    return np.where(glitch, med, a)


def rotation(st: BlockStats) -> np.ndarray:
    """Block means that are significant rotation (5 sigma of the block's white noise), else 0."""
    sig = np.sqrt(np.nan_to_num(st.v2, nan=0.0) / max(st.n, 1))
    return np.where(np.abs(st.mean) > 5.0 * sig, st.mean, 0.0)


def noise_ratio(st: BlockStats | None, sigma2: Sequence[float] | None) -> np.ndarray | None:
    """v2 / sigma0^2 per axis, None without a block or before every axis' still reference is learned."""
    if st is None or sigma2 is None:
        return None
    return np.nan_to_num(st.v2, nan=0.0) / np.asarray(sigma2, dtype=float)


class MotionGate:
    def __init__(self, cfg):
        self.cfg = cfg
        self.ref_accel: np.ndarray | None = None
        self.ref_accel_std: np.ndarray | None = None
        self._quiet: list[list] = [[], [], []]  # per accel axis: its stds in the blocks in a row far quieter than its reference
        self.mislearned = False  # set when the reference was found learned under vibration (the caller resets it)
        self.ratio = 1.0  # by how much the reference was too high, when it was

    def still(self, data: np.ndarray, st: BlockStats, mine: np.ndarray | None, peers: Sequence[Peer],
              settling: bool) -> bool:
        """One block; ``mine`` this IMU's noise ratios, ``peers`` the other IMUs' latest blocks,
        ``settling``: no still time yet (a new attitude then becomes the accel reference)."""
        cfg = self.cfg
        a = without_glitches(data[:, 4:7])
        a_mean = a.mean(axis=0)
        a_std = a.std(axis=0)
        if np.linalg.norm(a, axis=1).std() > cfg.accel_std:
            return False
        if self.ref_accel is not None and np.linalg.norm(a_mean - self.ref_accel) > cfg.accel_shift:
            # moved to a new attitude; it becomes the reference once still for settle_s
            self.ref_accel = a_mean if settling else self.ref_accel
            return False
        accel_up = 1.0
        if self.ref_accel_std is not None:
            ratio = a_std / np.maximum(self.ref_accel_std, 1e-9)
            if np.any((ratio > cfg.accel_std_factor) & (a_std > cfg.accel_std_min)):
                return False
            accel_up = float(ratio.max())
            # per axis: a log that starts with the vehicle in hand can teach one axis a reference many times
            # its rest level while the others are near theirs; tested on all axes at once, the gate would
            # take knocks on that axis for rest (tests/service/test_motion_engine.py)
            moves = np.ptp(a, axis=0) > 0  # an axis that stops (every value equal) says nothing of its noise
            quieter = moves & (a_std * QUIETER < self.ref_accel_std)
            if a.shape[0] < QUIET_MIN_SAMPLES:
                quieter[:] = False
            for k, q in enumerate(quieter):
                self._quiet[k] = self._quiet[k] + [float(a_std[k])] if q else []
            done = [k for k in range(3) if len(self._quiet[k]) >= QUIET_BLOCKS]
            if done:
                ref = self.ref_accel_std.copy()
                for k in done:
                    ref[k] = float(np.mean(self._quiet[k]))
                self.ratio = float(np.max(self.ref_accel_std[done] / ref[done]))
                self.ref_accel_std, self.mislearned = ref, True
                self._quiet = [[], [], []]
                return False  # the break: what follows settles and is fed under the new reference
        # rotation, by consensus of the IMUs
        means = [rotation(st)] + [rotation(p.stats) for p in peers]
        rot = np.array(means)
        if len(means) == 1:
            w = rot[0]
        elif len(means) == 2:  # the IMU claiming less rotation, per axis
            w = np.where(np.abs(rot[0]) <= np.abs(rot[1]), rot[0], rot[1])
        else:
            w = np.median(rot, axis=0)
        # A rotation about a horizontal axis tilts the vehicle: the accelerometer sees it (the shift test
        # above) within the block. Unseen by the accel, only a rotation about gravity (yaw) is physical;
        # a lone gyro drifting or frozen at a rate is not motion.
        g_dir = a_mean / max(float(np.linalg.norm(a_mean)), 1e-9)
        yaw = abs(float(np.dot(w, g_dir)))
        if yaw > cfg.gyro_mean or (len(means) > 1 and np.any(np.abs(w) > cfg.gyro_mean)):
            return False
        # vibration, by agreement of IMUs / axes
        k2 = cfg.gyro_std_factor ** 2
        if mine is not None:
            if peers:
                if np.any(mine > k2) and any(p.noise_ratio is not None and np.any(p.noise_ratio > k2) for p in peers):
                    return False
            elif np.count_nonzero(mine > k2) >= 2 and accel_up > 1.5:
                return False
        w = REF_WEIGHT
        self.ref_accel = a_mean if self.ref_accel is None else (1 - w) * self.ref_accel + w * a_mean
        self.ref_accel_std = a_std if self.ref_accel_std is None else (1 - w) * self.ref_accel_std + w * a_std
        return True
