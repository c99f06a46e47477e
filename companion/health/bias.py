"""Bias jump and bias drift of a gyro axis, from the means of still blocks.

Jump. x_k is the mean of still block k, r a slowly tracking reference (EWMA over ``REF_TAU_BLOCKS``
still blocks, frozen while evidence builds and during a fault) and sigma_m the block mean's uncertainty,
Allan-predicted: sigma_m^2 = max(sigma0^2, v2_k) / n (white noise; the larger of the reference and the
block's own, so a noisy block never looks like a jump) + 0.44 B^2 + K^2 T / 3 (flicker and random walk of
the baseline over the reference memory T), each with the 1-sigma of the baseline. Two CUSUMs
(faults eq. (1)) of the Gaussian mean-shift LLR for delta = +-0.2 deg/s:

    llr = (delta / sigma_m^2) (x_k - r - delta / 2)

A jump of 0.3 deg/s gives +2.6e-3 rad/s per block above the allowance delta / 2 = 0.1 deg/s: with the
ADIS16405-like noise (sigma_m = 6.7e-4 rad/s) 20 nats per block, flagged in 1-2 still blocks (plus the
motion gate's look-ahead). A cold-start warm-up (0.1 deg/s, exponential, 10 min) moves at most 5e-4 deg/s
per second: the reference lags it by <= 0.03 deg/s, far inside the allowance (benchmarks/bench_faults.py:
0 false alarms in 100 h with warm-ups).

Drift. e, an EWMA of x over ``DRIFT_TAU_BLOCKS``, against the bias mu0 of the reference period:
|e - mu0| - 4 sigma_e > ``DRIFT_TOL`` (0.3 deg/s: 3x the warm-up) for ``DRIFT_HOLD`` blocks flags a drift;
it clears below 0.7 x the tolerance. A drift of D deg/s per s is flagged about 0.3 / D s after it starts.

Restarts. A run restored from the state file compares the bias within the run only: the autopilot calibrates
the gyro offsets at boot (ArduPilot's INS_GYR_CAL) and the temperature at the next boot is not the last one's,
so the bias the last run ended on is no reference for the next (a public rover log's bias wandered 1.2 deg/s
in one run: its state, replayed on the same log, read as a 1.2 deg/s jump at the start). :meth:`BiasDetector.restart`
takes the mean of the first ``RESTART_BLOCKS`` still blocks of the new run as the jump's and the drift's
reference; an active bias fault stays as it was.

Temperature. Where the block carries the IMU temperature (``BlockStats.temperature``), every still-block
mean is first corrected by the bias the temperature explains (companion.health.bias_temperature: a slope learned
from pairs of still blocks that differ in temperature, at most ``FaultLimits.bias_temp_dps_per_k``): the
tests above see the residual, so a warm-up is not a drift while a drift at a steady temperature is.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Mapping

import numpy as np

from companion.health.axis_ref import AxisRef
from companion.health.faults import Cusum, FaultEvent, Observation
from companion.health.hold import FAULT, OK, debounce
from companion.health.evidence_rules import FaultLimits, capped, floored_mean_llr, wander_var
from companion.health.bias_temperature import LAG, ThermalBias

DEG = math.pi / 180.0
DELTA = 0.2 * DEG  #: rad/s, mean shift the jump CUSUMs are tuned to (allowance delta/2 above a warm-up's lag)
H_ON = 20.0  #: nats to flag a jump: ARL0 >= e^20 still blocks
H_OFF = 20.0  #: nats of evidence for healthy to clear it
REF_TAU_BLOCKS = 60.0  #: still blocks of the tracking reference's EWMA (lags a warm-up by <= 0.03 deg/s)
DRIFT_TAU_BLOCKS = 20.0  #: still blocks of the drift EWMA
DRIFT_TOL = 0.3 * DEG  #: rad/s the drift EWMA may leave the reference bias: 3x a cold start's warm-up
DRIFT_HOLD = 5  #: blocks beyond (within) the tolerance to flag (clear) a drift
DRIFT_SIGMAS = 4.0  #: the drift EWMA's own uncertainty allowed beyond the tolerance
DRIFT_CLEAR = 0.7  #: a drift clears below this share of the tolerance (hysteresis)
QUIET_SHARE = 0.25  #: share of H_ON below which neither jump CUSUM counts as building evidence (references learn)
HIST_BLOCKS = 90  #: recent still-block means kept for the step-or-ramp test and the measured wander
RESTART_BLOCKS = 10  #: still blocks whose mean is the bias reference after a restart
RAMP_NATS = 4.0  #: log-likelihood margin for naming a ramp (drift) rather than a step (jump)


class BiasDetector:
    """Two kinds in one module: ``bias_jump`` (state) and ``bias_drift`` (drift_state)."""

    kind = "bias_jump"

    def __init__(self, limits: FaultLimits | None = None):
        self.limits = limits or FaultLimits()
        self.wander = 0.0  # variance of the still-block means measured on this axis while quiet
        self.up = Cusum(H_ON, H_OFF)
        self.down = Cusum(H_ON, H_OFF)
        self.r = math.nan  # tracking reference (rad/s)
        self.e = math.nan  # drift EWMA
        self.run: list = []  # offsets x - r since the evidence started
        self.hist: deque = deque(maxlen=HIST_BLOCKS)  # recent still-block means (step or ramp?)
        self.hist_t: deque = deque(maxlen=HIST_BLOCKS)  # their temperatures (degC; nan: none)
        self.thermal = ThermalBias(self.limits.bias_temp)
        self.value = math.nan  # jump size (deg/s)
        self.post: list = []  # offsets x - r of the blocks after the jump was flagged (its size, refined)
        self.drift_state = OK
        self.drift_count = 0
        self.drift_value = math.nan
        self.drift_r = math.nan  # the reference when the drift was flagged
        self.mu0 = math.nan  # the drift's reference bias of this run after a restart (else the AxisRef's mu)
        self._restart: list | None = None  # means of the still blocks after a restart, until RESTART_BLOCKS

    def restart(self) -> None:
        """A new run restored from the state: the references are taken afresh from the next
        ``RESTART_BLOCKS`` still blocks (the module docstring, Restarts), unless a bias fault is active."""
        if self.state == FAULT or self.drift_state == FAULT:
            return
        self.r = self.e = self.mu0 = math.nan
        self.up.s = self.down.s = 0.0
        self.run, self.post = [], []
        self.drift_count = 0
        self.hist.clear()
        self.hist_t.clear()
        self._restart = []

    def _mu(self, ref: AxisRef) -> float:
        return self.mu0 if math.isfinite(self.mu0) else ref.mu

    @property
    def state(self) -> int:
        return FAULT if FAULT in (self.up.state, self.down.state) else OK

    def add_reference(self, x: float, temp: float = math.nan) -> None:
        """One still block of the reference period (before the tests start): its mean and temperature."""
        self.hist.append(x)
        self.hist_t.append(temp)
        self.thermal.add_reference(temp)

    def _hist_c(self) -> np.ndarray:
        """The recent still-block means less the bias their temperature explains (the current slope)."""
        x = np.asarray(self.hist, dtype=float)
        t = np.asarray(self.hist_t, dtype=float)
        s, t0 = self.thermal.slope, self.thermal.t0
        if s == 0.0 or not math.isfinite(t0) or t.shape != x.shape:
            return x
        return x - np.where(np.isfinite(t), s * (t - t0), 0.0)

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One still block of one axis (its mean and white variance; ``obs.extra_var`` the Allan-predicted
        wander of a block mean); the ``bias_jump`` and ``bias_drift`` changes, in that order."""
        st, j = obs.stats, obs.col
        out = []
        temp = float(getattr(st, "temperature", math.nan))
        for kind in self._step(obs.ref, float(st.mean[j]), float(st.v2[j]), st.n, obs.extra_var, temp):
            if kind == "bias_jump":
                out.append(obs.event(kind, self.state, self.value))
            else:
                out.append(obs.event(kind, self.drift_state, self.drift_value))
        return out

    def _step(self, ref: AxisRef, x_raw: float, v2: float, n: int, extra_var: float = 0.0,
              temp: float = math.nan) -> list[str]:
        """One still block; returns the kinds that changed state (``bias_jump``, ``bias_drift``)."""
        if not (ref.ready and math.isfinite(x_raw) and n > 0):
            return []
        x = x_raw - self.thermal.correction(temp)  # the residual the temperature does not explain
        if self._restart is not None:
            self._restart_block(x, x_raw, temp)
            return []
        mu = self._mu(ref)
        if math.isnan(self.r):
            self.r = mu
        if math.isnan(self.e):
            self.e = mu  # the reference period's mean (30 blocks), not one noisy block
        # the block mean's spread around the reference: white noise, the Allan-predicted wander, and the
        # wander measured on the vehicle (vibration, small real motion, temperature) while nothing was flagged
        white = max(ref.sigma2, v2 if math.isfinite(v2) else 0.0) / n
        sig = math.sqrt(max(white + max(extra_var, self.wander), 1e-18))
        out = self._jump_step(x, x_raw, temp, sig, mu)
        if self.state == OK and self.up.s < QUIET_SHARE * H_ON and self.down.s < QUIET_SHARE * H_ON:
            self._learn_quiet(x)
        return out + self._drift_step(x, mu, white + extra_var)

    def _restart_block(self, x: float, x_raw: float, temp: float) -> None:
        """A still block after a restart: collected until ``RESTART_BLOCKS``, whose mean becomes the reference."""
        self._restart.append(x)
        self.hist.append(x_raw)
        self.hist_t.append(temp)
        if len(self._restart) < RESTART_BLOCKS:
            return
        self.mu0 = float(np.mean(self._restart))
        self.r = self.e = self.mu0
        self._restart = None

    def _jump_step(self, x: float, x_raw: float, temp: float, sig: float, mu: float) -> list[str]:
        """The two jump CUSUMs on the offset from the tracking reference; a flagged change whose evidence grew
        like a ramp is named a drift instead."""
        lim = self.limits
        d = x - self.r
        was = self.state
        if was == OK and self.up.s == 0.0 and self.down.s == 0.0:
            self.run = []
        self.run.append(d)
        self.hist.append(x_raw)
        self.hist_t.append(temp)
        if self.drift_state == OK:  # a drift already flagged is not named again as jumps
            # a step below the floor is wander, not a fault; one knock is not a step (capped evidence)
            hold = lim.bias_hold_blocks
            self.up.step(capped(floored_mean_llr(d, sig, lim.bias_jump, DELTA), H_ON, hold))
            self.down.step(capped(floored_mean_llr(-d, sig, lim.bias_jump, DELTA), H_ON, hold))
        if self.state == was:
            if was == FAULT:
                # the size once confirmed: the blocks after the flag, all wholly after the step (the flagging
                # block may hold the step part-way and the run blocks before it), against the frozen reference
                self.post.append(d)
                self.value = float(np.median(self.post)) / DEG
            return []
        if self.state == OK:
            self.r = x  # back to normal: follow from here
            return ["bias_jump"]
        if not self._is_ramp(sig):
            self.value = sum(self.run) / len(self.run) / DEG
            self.post = []
            return ["bias_jump"]
        # the evidence grew like a ramp: a drift, not a step
        self.up.state = self.down.state = OK
        self.up.s = self.down.s = 0.0
        if self.drift_state != OK:
            return []
        self.drift_state, self.drift_count, self.drift_r = FAULT, 0, self.r
        self.drift_value = (x - mu) / DEG
        return ["bias_drift"]

    def _learn_quiet(self, x: float) -> None:
        """No evidence building: the temperature slope, the tracking reference and the measured wander learn."""
        if len(self.hist) > LAG and len(self.hist_t) == len(self.hist):
            self.thermal.add_pair(self.hist[-1] - self.hist[-1 - LAG], self.hist_t[-1] - self.hist_t[-1 - LAG])
        self.r += (x - self.r) / REF_TAU_BLOCKS
        self.wander = wander_var(self._hist_c())

    def _drift_step(self, x: float, mu: float, white: float) -> list[str]:
        """The drift EWMA against the reference period's bias; ``white`` the variance of one block mean that the
        EWMA averages down (a slow wander, correlated over tens of blocks, it does not)."""
        lim = self.limits
        self.e += (x - self.e) / DRIFT_TAU_BLOCKS
        sig_e = math.sqrt(white / (2.0 * DRIFT_TAU_BLOCKS) + self.wander)
        off = self.e - mu
        tol = max(DRIFT_TOL, lim.bias_drift)
        if self.drift_state == OK:
            self.drift_count = self.drift_count + 1 if abs(off) - DRIFT_SIGMAS * sig_e > tol else 0
            if self.drift_count >= DRIFT_HOLD and self.state == OK:  # not while a jump is flagged
                self.drift_state, self.drift_count, self.drift_value = FAULT, 0, off / DEG
                self.drift_r = mu
                return ["bias_drift"]
            return []
        last = list(self._hist_c())[-DRIFT_HOLD:]
        back = (abs(off) < DRIFT_CLEAR * tol
                and abs(sum(last) / len(last) - self.drift_r) < 0.5 * max(DELTA, lim.bias_jump))
        self.drift_state, self.drift_count, changed = debounce(self.drift_state, self.drift_count, False,
                                                               DRIFT_HOLD, DRIFT_HOLD, good=back)
        return ["bias_drift"] if changed else []

    def _is_ramp(self, sig: float) -> bool:
        """Step or ramp? Over the recent still-block means, the best single step (two constants) against
        the best hinge (a constant, then a ramp from some block on): a ramp when its Gaussian
        log-likelihood is ``RAMP_NATS`` better."""
        x = self._hist_c()
        n = x.size
        if n < 8:
            return False
        c1, c2 = np.cumsum(x), np.cumsum(x * x)
        best_step = math.inf
        for k in range(2, n):
            rss = (c2[k - 1] - c1[k - 1] ** 2 / k) + max((c2[-1] - c2[k - 1]) - (c1[-1] - c1[k - 1]) ** 2 / (n - k), 0.0)
            best_step = min(best_step, rss)
        i = np.arange(n, dtype=float)
        best_ramp = math.inf
        for k in range(0, n - 3):
            h = np.maximum(0.0, i - k)
            A = np.column_stack([np.ones(n), h])
            coef, res, *_ = np.linalg.lstsq(A, x, rcond=None)
            rss = float(res[0]) if res.size else float(np.sum((A @ coef - x) ** 2))
            best_ramp = min(best_ramp, rss)
        return (best_step - best_ramp) / (2.0 * sig * sig) > RAMP_NATS

    def state_dict(self) -> dict:
        f = lambda v: None if math.isnan(v) else v  # noqa: E731
        return {"up": self.up.state_dict(), "down": self.down.state_dict(), "r": f(self.r), "e": f(self.e),
                "value": f(self.value), "drift_state": self.drift_state, "drift_count": self.drift_count,
                "drift_value": f(self.drift_value), "drift_r": f(self.drift_r), "hist": list(self.hist),
                "hist_t": [f(v) for v in self.hist_t], "thermal": self.thermal.state_dict(), "wander": self.wander,
                "mu0": f(self.mu0), "restart": self._restart}

    def load_state_dict(self, d: Mapping) -> None:
        g = lambda k: math.nan if d.get(k) is None else float(d[k])  # noqa: E731
        self.up.load_state_dict(d.get("up", {}))
        self.down.load_state_dict(d.get("down", {}))
        self.r, self.e, self.value, self.drift_value = g("r"), g("e"), g("value"), g("drift_value")
        self.drift_state, self.drift_count = int(d.get("drift_state", OK)), int(d.get("drift_count", 0))
        self.drift_r = g("drift_r")
        self.wander = float(d.get("wander", 0.0))
        self.hist = deque((float(v) for v in d.get("hist") or []), maxlen=HIST_BLOCKS)
        temps = [math.nan if v is None else float(v) for v in d.get("hist_t") or []]
        if len(temps) != len(self.hist):  # a state saved without temperatures
            temps = [math.nan] * len(self.hist)
        self.hist_t = deque(temps, maxlen=HIST_BLOCKS)
        self.thermal.load_state_dict(d.get("thermal") or {})
        self.mu0 = g("mu0")
        self._restart = [float(v) for v in d["restart"]] if d.get("restart") is not None else None
