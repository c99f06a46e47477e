"""Disagreement between two IMUs' gyros, valid at rest and in flight (the difference cancels the motion).

For a pair (i, j) the model is y_i = (I + E)^T-free form  y_i = y_j + y_j E + c + noise: E (3x3) the small
scale-factor and misalignment difference, c the bias difference. E is fitted by ridge regression on the
block-demeaned samples of blocks with motion (rms above 5x IMU j's noise; the regressor's noise, which
would shrink E towards -1 on still data, is corrected for: errors in variables), a Bayesian prior
E ~ N(0, 0.03^2) per entry, exponential
memory ``FIT_TAU_BLOCKS``; entries clipped to +-0.1 so that a frozen gyro can never be "explained" as a
scale factor of -1); blocks with evidence of a fault are not fitted. c is a slowly tracking reference
(EWMA over ``REF_TAU_BLOCKS`` blocks, frozen while evidence builds and during a fault).

Statistics per block and axis: the mean residual d = mean(y_i) - mean(y_j)(I + E) - c and its
uncertainty sigma_d^2 = 2 var_w(r) / n (var_w: the white variance of the residual from its second
differences, doubled for colour) + sigma_n^2 m^T (S + lambda I)^-1 m
(the predictive variance of the fitted E at the block's mean rate m: the regression's own uncertainty, so
the first seconds of a flight, before E is known, are tested with the 3 % prior and not falsely).
Two CUSUMs (faults eq. (1)) of a mean-shift LLR with a floor (limits.floored_mean_llr), h = 15: no evidence
below ``disagree_dps`` (5 deg/s, ArduPilot's gyro consistency limit) plus ``disagree_rel`` (10 %) of the
block's rms rate, and each block's evidence capped at h / ``disagree_hold_blocks`` (3 blocks at least):
healthy IMUs in fast manoeuvres differ by a few deg/s and ~10 % of the rate (each sampled at its own
instants and filtered on its own; log171's 1 s means: p99 4.6 deg/s, max 14 deg/s at the crash). The
residual's variance is not used: in flight each IMU vibrates its own way, and at rest each IMU's own noise
detector singles out a noisy one. A gyro frozen in flight shows its whole mean rate in d (and stuck.py
flags it anyway); a biased one above the floor about 10+ nats per block.

Clearing is a separate, explicit rule (PX4 DataValidator style), not the CUSUMs' reverse statistic: an axis in
FAULT clears after ``CLEAR_BLOCKS`` consecutive blocks whose residual is within the allowance both ways
(|d| <= 0.75 floor, no evidence in either direction), and never while the caller holds it (another fault on
that axis of either IMU that moves a mean rate: service/imu_group.py). The reverse CUSUM would clear in one
block: an agreeing block's LLR is -(delta / sigma_d^2) 0.75 floor, hundreds of nats with sigma_d ~ 0.25
deg/s, while h is 15. A gyro frozen in flight agrees for a block whenever the vehicle's mean rate over
that second passes near the frozen value, so the fault would be named and cleared every few seconds (9
named/cleared pairs in 106 s of a frozen gyro in flight), and each clear would re-anchor the bias reference c
at that block, until c had absorbed the offset and the frozen gyro "agreed" for good.

With three IMUs the odd one out is the IMU whose two pairs disagree while the third pair agrees
(service/imu_group.py names it: ``IMU1 gyro X disagrees with IMU0/IMU2``).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from companion.health.evidence_rules import FaultLimits, capped, floored_mean_llr
from companion.health.faults import AXES, Cusum, FaultEvent, Observation
from companion.health.hold import FAULT, OK

DEG = math.pi / 180.0
DELTA = 0.5 * DEG  # rad/s, mean shift of the residual the CUSUMs are tuned to (above the floor)
H_ON = 15.0  # nats to flag a disagreement (with each block's evidence capped at h / disagree_hold_blocks)
H_OFF = 15.0  # nats of the reverse CUSUM (clearing is CLEAR_BLOCKS' rule)
PRIOR_STD = 0.03  # expected scale/misalignment difference between two IMUs
E_CLIP = 0.1  # largest |E| entry: a frozen gyro is never "explained" as a scale factor of -1
FIT_TAU_BLOCKS = 600.0  # blocks of memory of the E fit (10 min of 1-s blocks: the mounting does not change)
REF_TAU_BLOCKS = 60.0  # blocks of the bias-difference reference's EWMA (follows a warm-up, not a fault)
MOTION_RMS = 0.02  # rad/s: a block with this much (demeaned) rotation is fitted
WARM_BLOCKS = 5  # blocks of a pair before it is tested (the reference c settles)
#: consecutive agreeing blocks (1 s each) before a disagreement clears. A gyro frozen in flight agrees by
#: chance for up to 6 blocks in a row in manoeuvres (true rate near the frozen value); a
#: hover at that value lasts longer, which the caller's hold covers while the stuck detector names it
CLEAR_BLOCKS = 30


class PairDisagreement:
    kind = "disagree"

    def __init__(self, i: int, j: int, limits: FaultLimits | None = None):
        self.i, self.j = i, j
        self.limits = limits or FaultLimits()
        self.S = np.zeros((3, 3))
        self.T = np.zeros((3, 3))
        self.E = np.zeros((3, 3))
        self.n_fit = 0.0  # samples in S and T (with the same forgetting)
        self.c = np.full(3, np.nan)
        self.blocks = 0
        self.up = [Cusum(H_ON, H_OFF) for _ in range(3)]
        self.down = [Cusum(H_ON, H_OFF) for _ in range(3)]
        self.value = np.full(3, np.nan)  # residual at the transition (deg/s)
        self.agree = [0, 0, 0]  # consecutive agreeing blocks of an axis in FAULT
        self.agree_sum = np.zeros(3)  # their d0 summed: the bias reference after a clear is their mean

    def axis_state(self, a: int) -> int:
        return FAULT if FAULT in (self.up[a].state, self.down[a].state) else OK

    def evidence(self) -> bool:
        """Any axis in FAULT or with a CUSUM a quarter of the way to it."""
        return any(self.axis_state(a) == FAULT or max(self.up[a].s, self.down[a].s) > 0.25 * H_ON for a in range(3))

    @property
    def state(self) -> int:
        return FAULT if any(self.axis_state(a) == FAULT for a in range(3)) else OK

    def update(self, obs: Observation, held: Sequence[bool] = (False, False, False)) -> list[FaultEvent]:
        """Aligned samples (m, 3) of both IMUs: ``obs.y`` of IMU i, ``obs.other`` of IMU j; ``obs.noise_var``
        the white variance expected of the residual (both IMUs' still references summed), ``obs.noise_other``
        IMU j's own (the regressor's noise, corrected for in the fit); ``held[a]``: axis a in FAULT does not
        clear in this block (its cause persists). Returns the pair's state changes per axis as events of
        IMU i with ``detail`` "IMU{j}" (which IMU is at fault is decided by the group)."""
        changed = self._step(obs.y, obs.other, obs.noise_var, obs.noise_other, held)
        return [FaultEvent(self.i, AXES[a], self.kind, self.axis_state(a), float(self.value[a]), f"IMU{self.j}")
                for a in changed]

    def _step(self, yi: np.ndarray, yj: np.ndarray, noise_var: float | None = None,
              noise_j: float | None = None, held: Sequence[bool] = (False, False, False)) -> list[int]:
        m = yi.shape[0]
        if m < 10:
            return []
        mi, mj = yi.mean(axis=0), yj.mean(axis=0)
        xi, xj = yi - mi, yj - mj
        r = (yi - yj - yj @ self.E)
        d0 = r.mean(axis=0)
        var_r = _white_var(r)  # the white part: a healthy residual is white; a disagreement is not
        sig_n2 = float(noise_var) if noise_var else float(np.max(var_r))
        sig_n2 = max(sig_n2, 1e-14)
        lam = sig_n2 / PRIOR_STD ** 2
        P = np.linalg.inv(self.S + lam * np.eye(3))
        var_pred = sig_n2 * float(mj @ P @ mj)
        var_d = 2.0 * var_r / m + var_pred + 1e-14
        if np.isnan(self.c).any():
            self.c = d0.copy()
        d = d0 - self.c
        changed = []
        evidence = False
        self.blocks += 1
        lim = self.limits
        # two healthy IMUs differ by up to a few deg/s plus ~10 % of the rate in fast manoeuvres (own
        # sampling instants and filters, percent-level scale factors): below that floor no evidence at all
        floor = lim.disagree + lim.disagree_rel * np.sqrt(np.mean(yj * yj, axis=0))
        for a in range(3):
            if self.blocks <= WARM_BLOCKS:
                break
            was = self.axis_state(a)
            s = math.sqrt(var_d[a])
            # only the mean offset counts: a residual variance rise is each IMU's own vibration (in flight)
            # or noise (still: the IMU's own noise detector singles it out); one violent second is not a
            # disagreement (evidence capped: ``disagree_hold_blocks`` blocks at least)
            hold = lim.disagree_hold_blocks
            llr_up = floored_mean_llr(d[a], s, float(floor[a]), DELTA)
            llr_down = floored_mean_llr(-d[a], s, float(floor[a]), DELTA)
            if was == OK:
                self.up[a].step(capped(llr_up, H_ON, hold))
                self.down[a].step(capped(llr_down, H_ON, hold))
            elif llr_up <= 0.0 and llr_down <= 0.0 and not held[a]:
                # one agreeing block is no evidence that the pair agrees again (the true rate of a turn
                # passes near a frozen value for a second): only a run of them, and none while held
                self.agree[a] += 1
                self.agree_sum[a] += d0[a]
                if self.agree[a] >= CLEAR_BLOCKS:
                    for cu in (self.up[a], self.down[a]):
                        cu.state, cu.s = OK, 0.0
                    self.c[a] = self.agree_sum[a] / self.agree[a]
            else:
                self.agree[a], self.agree_sum[a] = 0, 0.0
            if self.axis_state(a) != was:
                changed.append(a)
                self.value[a] = d[a] / DEG
                self.agree[a], self.agree_sum[a] = 0, 0.0
            if self.axis_state(a) == FAULT or self.up[a].s > 0.25 * H_ON or self.down[a].s > 0.25 * H_ON:
                evidence = True
        if not evidence:
            self.c += (d0 - self.c) / (REF_TAU_BLOCKS if self.blocks > WARM_BLOCKS else self.blocks)
            # fit only on real motion (the regressor well above its own noise), with the errors-in-variables
            # correction: S = S_true + n sigma_j^2 I and T = S_true E - n sigma_j^2 I
            if noise_j is not None and np.sqrt(np.mean(xj * xj, axis=0)).max() > max(MOTION_RMS, 5.0 * math.sqrt(noise_j)):
                g = math.exp(-1.0 / FIT_TAU_BLOCKS)
                self.S = g * self.S + xj.T @ xj
                self.T = g * self.T + xj.T @ (xi - xj)
                self.n_fit = g * self.n_fit + m
                corr = self.n_fit * noise_j * np.eye(3)
                A = self.S - corr + lam * np.eye(3)
                if np.all(np.linalg.eigvalsh(A) > 0):
                    self.E = np.clip(np.linalg.solve(A, self.T + corr), -E_CLIP, E_CLIP)
        return changed

    def state_dict(self) -> dict:
        return {"i": self.i, "j": self.j, "S": self.S.tolist(), "T": self.T.tolist(), "E": self.E.tolist(),
                "n_fit": self.n_fit,
                "c": [None if np.isnan(v) else float(v) for v in self.c], "blocks": self.blocks,
                "up": [c.state_dict() for c in self.up], "down": [c.state_dict() for c in self.down],
                "agree": list(self.agree), "agree_sum": [float(v) for v in self.agree_sum]}

    def load_state_dict(self, d: Mapping) -> None:
        self.S, self.T, self.E = (np.asarray(d[k], dtype=float).reshape(3, 3) for k in ("S", "T", "E"))
        self.c = np.array([np.nan if v is None else float(v) for v in d["c"]])
        self.blocks = int(d.get("blocks", 0))
        self.n_fit = float(d.get("n_fit", 0.0))
        self.agree = [int(v) for v in d.get("agree", [0, 0, 0])]
        self.agree_sum = np.array([float(v) for v in d.get("agree_sum", [0.0, 0.0, 0.0])])
        for c, s in zip(self.up, d.get("up", [])):
            c.load_state_dict(s)
        for c, s in zip(self.down, d.get("down", [])):
            c.load_state_dict(s)


def _white_var(r: np.ndarray) -> np.ndarray:
    dd = r[2:] - 2.0 * r[1:-1] + r[:-2]
    return np.mean(dd * dd, axis=0) / 6.0
