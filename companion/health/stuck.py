"""Stuck (frozen) gyro axis: the output repeats its value (codes) and its variance collapses.

Statistic: u = v2 / sigma0^2, the block's white-noise variance from second differences (block_stats.BlockStats)
over the reference sigma0^2 learned from still data, its rest level (a knock among the reference blocks
left out: axis_ref.AxisRef.rest); nu v2 / sigma^2 ~ chi2(nu) (nu from the reference, smaller under coarse
rounding). The CUSUM (faults eq. (1)) of the LLR of a variance
collapse by ``r1`` = 1/10

    llr = (nu / 2) * (ln 10 - 9 u)

is positive only while u < ln(10) / 9 = 0.256. A frozen output (u = 0) gives nu/2 * 2.30 = 58 nats per
100-sample block against h = 20: flagged after one block; a frozen value with dither of std d is caught
while d^2 < 0.256 sigma0^2 (d < 0.5 sigma0). Motion only adds variance, so this runs on every block
(still, handled, armed, flying). Figure: benchmarks/bench_faults.py (stuck delay 1-2 s, 0 false alarms in
100 h including 0.7 LSB int16 rounding, where healthy blocks never came below u = 0.4).

A variance drop alone is no evidence of a frozen gyro: a plane's gyro whose noise falls 5x when the engine
stops keeps giving distinct values (150 distinct 10 Hz samples in 15 s, benchmarks/bench_reallogs.py). So
the per-block evidence is the smaller of the variance LLR and the evidence of repeated codes
(limits.equal_codes_llr): the number of successive equal samples against the rate p0 a healthy gyro
repeats its code by nature, predicted from its noise-to-LSB ratio (limits.p_equal_codes: 0.37 at 0.7 LSB
of white noise, so a healthy coarse gyro's runs of equal codes are not a fault; about 0 for float logs,
whose codes always change). The LSB is the smallest non-zero step seen on the axis. A frozen value
(every code equal) gives ~ n ln(1 / p0) nats: flagged in one block.

A value frozen near a code boundary with a dither far below the step flips between two adjacent codes
about as often as a healthy gyro of ~0.5 LSB changes code, and its variance is that of the flips: neither
test sees it. What a frozen value lacks is spread: healthy noise also lands beyond two adjacent codes, and
how often depends on where its level sits, which the split between the two codes tells. A second CUSUM
weighs the codes of its run (since it last stood at 0; the largest over the run's last 1, 2, ..., 32,
48, 64, ... blocks) by :func:`codes_glr`: the best split between two adjacent codes against the best healthy level
(its rate beyond two codes is least on the boundary, 2 Phi(-1/s), and grows off it). It is thin where the
frozen value sits right on a boundary (about 0.9 nats per 50-sample block at the copter preset's 0.43 LSB
of noise: 15-30 s at rest); the other evidence there is small (the low-pass correlation of the healthy flips, ~0.1 nats a block
on the copter; the bias wander, less); in motion a live gyro spreads over many codes at once.

The healthy noise comes from the samples' own spread at rest (a gyro low-passed well below its logged rate
spreads its samples far beyond its sample-to-sample noise, the rover's 5 Hz at 50 Hz), over the block's
equivalent independent samples (both figures from the same still samples). The healthy level is not free
from block to block: it jitters around the window's level by what successive still blocks' means showed
beyond their samples' noise (a frozen value's split holds still), and a window's level far from where the
still blocks before the run put it (their error at rest learned 1 and 16 blocks ahead) costs up to 3 nats
(a value frozen at one sample of the noise sits about a sample's sd from the level it froze from).

A gyro whose codes do not repeat (floats) has a third CUSUM: its variance collapse, counted while the same
IMU's accelerometer vibrates at least half as much as at the reference (:meth:`StuckDetector._vibration_llr`):
a parked plane's engine stop lowers both, a frozen gyro only its own.

Before a reference exists (the first seconds of still data) the PX4-like rule applies: ``equal_blocks``
consecutive blocks of at least 50 samples with every value equal (no change at all).

Exactly 0 is named for what it is (kind ``dead``, its own code): a float message (HIGHRES_IMU, DataFlash,
ULog) never reads exactly 0.0 from a live gyro, so that is a dead (absent, never started) sensor. On an
integer message (RAW_IMU, SCALED_IMU*: int16 mrad/s, ``coded_lsb``) a gyro whose noise is below the
1 mrad/s step (0.057 deg/s; ArduPilot SITL, a quiet MEMS part) also reads 0 on every axis at rest: the
plain truth is "dead or below resolution" (WARNING; HIGHRES_IMU carries float rad/s). It becomes
"reads 0 while moving: dead" (CRITICAL) when the motion gate (accelerometer, other IMUs) sees the vehicle
move while the axis still reads 0. An axis that changed codes in motion is alive; at rest again it reads 0
by resolution, so it is named again only after ``ZERO_ALIVE_BLOCKS`` blocks of zeros (one per landing or
handling otherwise). A value frozen at 0 after a learned reference showed codes changing at rest is
``stuck``, as a frozen non-zero value is.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from companion.health.code_spread import (_STD_NORMAL, LEVEL_STEP, MAX_CODES, Q_RATIO, _block_level_logs, _pair_counts,
                                          two_code_llr, two_code_outside)
from companion.health.faults import Cusum, FaultEvent, Observation, chi2_llr
from companion.health.hold import FAULT, OK
from companion.health.evidence_rules import equal_codes_llr, p_equal_codes
from companion.health.rest_tally import CodeTally, JitterTally, LeadErrors

R1 = 0.1  # variance collapse the CUSUM is tuned to
MIN_OUTSIDE = 10  # samples beyond two codes seen at rest before that evidence counts (a quiet gyro never does)
H_ON = 20.0  # nats: ARL0 >= e^20 = 5e8 blocks (1 s) = 15 years per axis
H_OFF = 10.0  # nats of evidence for healthy that clear a stuck fault
EQUAL_BLOCKS = 2  # blocks with no change at all (>= 100 equal values at 100 Hz), PX4's rule doubled
#: samples of one full block of the equal-values rule; a block of fewer counts as that share of one (a 10 Hz
#: block as a fifth), so that a float
#: gyro reading exactly 0.0 at 10 or 25 Hz (a tlog's HIGHRES_IMU, a DataFlash log's 25 Hz IMU), whose blocks never
#: hold 50 equal values, is named after 100 equal values as a fast one is (10 s at 10 Hz)
EQUAL_MIN_SAMPLES = 50
VIB_KEEP = 0.5  # the accelerometer's vibration at least this share of its still reference: it did not fall
RUN_BLOCKS = 256  # blocks of a run of codes kept (the windows of its evidence end there)
WINDOWS = tuple(range(1, 33)) + (48, 64, 96, 128, 192, 256, 1 << 30)  # the run's last blocks weighed
PRIOR_BLOCKS = 8  # still blocks before a run whose mean level is where a healthy level is expected
PRIOR_LEAD = 16  # blocks: the second lead at which that expectation's error is learned
PRIOR_CAP = 3.0  # nats: the most a healthy level away from the expected one is penalised (a level may step)
JITTER_MIN = 30  # pairs of successive still blocks before the level's block-to-block jitter is used
ZERO_ALIVE_BLOCKS = 60  # integer-coded zeros of an axis seen alive (changing in motion): "for long" = 1 min


class StuckDetector:
    """``coded_lsb``: the message's resolution (rad/s) for integer messages (RAW_IMU, SCALED_IMU*), None for
    float messages; it only decides how an axis reading exactly 0 is named."""

    def __init__(self, coded_lsb: float | None = None):
        self.coded_lsb = coded_lsb
        self.kind = "stuck"  # the kind named for the current fault: "stuck", or "dead" (exactly 0)
        self.detail = ""  # of a "dead" fault: "" (integer message, at rest), "float", "moving"
        self.alive = False  # the axis changed codes in a moving block (a live gyro; its zeros at rest are resolution)
        self.codes = CodeTally()  # still blocks while healthy: their codes and spread
        self.pend = CodeTally()  # the same of the current run of codes (kept if it ends healthy)
        self.jitter = JitterTally()  # successive still blocks' levels while healthy
        self.jpend = JitterTally()  # the same of the current run
        self.prev_level: tuple[float, float] | None = None  # the last still block's mean and variance of its mean
        self.recent: list[tuple[int, float]] = []  # (block number, mean level in LSB) of the last still blocks kept
        self.lpend: list[tuple[int, float]] = []  # the same of the current run
        self.lead_err = LeadErrors()  # of the expected level 1 and PRIOR_LEAD blocks ahead
        self.nblk = 0
        # each block's codes (lowest, counts, its healthy likelihoods by pair) since the two-code CUSUM stood at 0
        self.run: list[tuple[int, np.ndarray, dict]] = []
        self.cusum = Cusum(H_ON, H_OFF)
        self.two = Cusum(H_ON, H_OFF)  # the spread over codes (two_code_llr)
        self.vib = Cusum(H_ON, H_OFF)  # the variance collapse while the accelerometer's vibration did not fall
        self.equal_run = 0
        self.value = math.nan
        self.lsb = math.inf  # smallest non-zero step seen (the sensor's resolution, or finer)
        self.quantised = False  # a healthy block repeated a code: the data are quantised near the noise level

    @property
    def spread(self) -> list:
        """The still blocks' spread: [variance times samples, samples, squared second differences, their count]."""
        return self.codes.spread

    @property
    def state(self) -> int:
        return FAULT if FAULT in (self.cusum.state, self.two.state, self.vib.state) else OK

    @property
    def critical(self) -> bool:
        """The fault's severity: critical, except an integer axis reading 0 at rest (below resolution or dead)."""
        return not (self.kind == "dead" and self.detail == "")

    def update(self, obs: Observation) -> list[FaultEvent]:
        """One block of one axis (any motion state); the state change, if any (critical, except an integer
        axis reading 0 at rest), or the escalation of such an axis to "dead" when it reads 0 in motion."""
        st, j = obs.stats, obs.col
        zero = int(st.changes[j]) == 0 and float(st.top[j]) == 0.0 and st.n >= 2
        if not self._step(obs):
            if (self.state == FAULT and self.kind == "dead" and self.detail == "" and zero and not obs.still):
                self.detail = "moving"
                return [obs.event("dead", FAULT, detail="moving", critical=True)]
            return []
        if self.state == FAULT:
            self.kind, self.detail = "stuck", ""
            if zero and (self.coded_lsb is None or not (obs.ref is not None and obs.ref.ready)):
                self.kind = "dead"
                self.detail = "float" if self.coded_lsb is None else ("" if obs.still else "moving")
            return [obs.event(self.kind, FAULT, detail=self.detail, critical=self.critical)]
        kind, detail = self.kind, self.detail
        self.kind, self.detail = "stuck", ""
        return [obs.event(kind, OK, detail=detail, critical=True)]

    def _step(self, obs: Observation) -> bool:
        # judged against the rest level (the reference with knocks left out: axis_ref.AxisRef.rest)
        j, st, ref = obs.col, obs.stats, obs.ref.rest
        v2, changes, n = float(st.v2[j]), int(st.changes[j]), st.n
        # in samples, at most EQUAL_MIN_SAMPLES per block: a block of 50 or more counts as one, a smaller one as
        # its share
        self.equal_run = self.equal_run + min(n, EQUAL_MIN_SAMPLES) if (changes == 0 and n >= 2) else 0
        if not obs.still and n >= 2 and changes >= (n - 1) // 2:
            self.alive = True
        # an integer axis seen alive reads 0 at rest by resolution: named again only after a long run
        zero_coded = self.coded_lsb is not None and changes == 0 and float(st.top[j]) == 0.0
        equal_blocks = ZERO_ALIVE_BLOCKS if (zero_coded and self.alive) else EQUAL_BLOCKS
        step = float(st.step[j])
        if ref.ready and ref.sigma2 > 0 and math.isfinite(v2):
            u = v2 / ref.sigma2
            self.value = u
            llr = chi2_llr(u, ref.nu, R1)
            # frozen values, not just a quiet gyro: the codes must repeat more than the noise explains.
            # Differences far below the resolution count as repeats (a frozen value with a little dither):
            # the block's repeat rate is at least what its own white noise would give at that resolution.
            # (only for data seen to repeat codes when healthy: the smallest step of a float log is no resolution)
            if math.isfinite(self.lsb):
                p0 = p_equal_codes(math.sqrt(ref.sigma2) / self.lsb)
                pairs = n - 1
                p_hat = (pairs - changes) / max(pairs, 1)
                if self.quantised:
                    p_hat = max(p_hat, p_equal_codes(math.sqrt(max(v2, 0.0)) / self.lsb))
                llr = min(llr, equal_codes_llr(int(round(p_hat * pairs)), pairs, p0))
                if self.quantised and changes == 0:
                    llr = min(llr, self._quiet_cap(ref, n))
            else:
                llr = min(llr, 0.0)
            if llr <= 0.0 and self.cusum.state == OK and math.isfinite(step) and step > 0:
                self.lsb = min(self.lsb, step)  # the resolution, learned from blocks without evidence
                self.quantised = self.quantised or changes < n - 1
            if self.equal_run >= equal_blocks * EQUAL_MIN_SAMPLES and self.cusum.state == OK:
                llr = max(llr, 2.0 * H_ON)
            before = self.state
            self.cusum.step(llr)
            # the spread over codes has its own CUSUM (another alternative: a sum of the two LLRs, or their
            # larger, would let one's excursions ride on the other's evidence); stuck while either says so
            two = self._two_codes(obs, ref) if (self.quantised and obs.y is not None) else None
            if two is not None:
                self.two.step(two)
            elif self.two.state == FAULT and self.cusum.state == OK:
                self.two.state, self.two.s = OK, 0.0
            vib = self._vibration_llr(obs, ref, u)
            if vib is not None:
                self.vib.step(vib)
            return self.state != before
        # no reference yet: only the equal-values rule
        if self.cusum.state == OK and self.equal_run >= equal_blocks * EQUAL_MIN_SAMPLES:
            self.cusum.state, self.cusum.s = FAULT, 0.0
            return True
        if self.cusum.state == FAULT and changes > 0.5 * n:
            self.cusum.state, self.cusum.s = OK, 0.0
            return True
        return False

    def _vibration_llr(self, obs: Observation, ref, u: float) -> float | None:
        """The variance collapse of a gyro whose codes do not repeat (floats: DataFlash, ULog, HIGHRES_IMU, or
        noise far above the step) judged against what the rest of the IMU sees: the chi-square LLR of u,
        counted while the accelerometer's vibration is at least ``VIB_KEEP`` of its still reference; while it
        fell (an engine stopped: a healthy gyro's noise falls with it, as on real parked planes) only its
        evidence for healthy counts. None before the accelerometer's reference, or without one, and for
        quantised data, where a healthy quiet gyro at a code's centre gives blocks of one code (u = 0) by
        nature: there the repeated-codes evidence above is the honest one (at 10 Hz and 0.36 LSB a block of
        one code is worth at most 1.8 nats, not the 5 of the chi-square)."""
        if self.quantised or not math.isfinite(obs.vibration):
            return None
        llr = chi2_llr(u, ref.nu, R1)
        return llr if obs.vibration >= VIB_KEEP else min(llr, 0.0)

    def _noise_lsb(self, ref) -> float:
        """The reference noise in LSB with the rounding's LSB^2 / 12 taken out (Sheppard's correction)."""
        return math.sqrt(max(ref.sigma2 - self.lsb * self.lsb / 12.0, 0.0)) / self.lsb

    def _quiet_cap(self, ref, n: int) -> float:
        """The most evidence a block of one code can give: a healthy gyro whose level sits at the centre of a code keeps
        every sample in it with probability P^n, P = erf(0.5 / (s sqrt 2)) (s the reference noise in LSB less
        the rounding's 1/12), so a block of one code is worth at most n ln(1 / P) nats. The repeated-codes
        rate p_equal_codes averages over the level; at a code's centre a quiet gyro repeats more (at 10 Hz and
        0.36 LSB one block in six is a single code, and uncapped, 4 nats per block would take a healthy
        simulated plane to 15 of the 20 nats in an hour)."""
        s_l = self._noise_lsb(ref)
        if s_l <= 0:
            return math.inf
        p_one = math.erf(0.5 / (s_l * math.sqrt(2.0)))
        return -n * math.log(max(p_one, 1e-300)) if p_one < 1.0 else 0.0

    def _two_codes(self, obs: Observation, ref) -> float | None:
        """A frozen value flipping between two codes near their boundary: the codes since the CUSUM last stood at
        0, weighed by :func:`codes_glr` over the run's last blocks (:meth:`_best_window`), so that the step is
        that evidence less the CUSUM's value; the run ends when no window's evidence is above 0. The healthy noise s is the samples' own spread at rest (below),
        its rate beyond two codes on a boundary 2 Phi(-1 / s) at most the rate this axis showed at rest;
        counted only once the axis was seen beyond two codes ``MIN_OUTSIDE`` times (a quiet gyro that never
        leaves two codes is never judged by it). What is learned at rest is kept only once the run it
        belongs to ended healthy (the evidence fell back to 0): a frozen value's first blocks never teach
        the healthy rate. While stuck, each block's count beyond two codes clears it (:func:`two_code_llr`)."""
        y = np.asarray(obs.y)[:, obs.col]
        c = np.round(y / self.lsb)
        k, n = two_code_outside(y, self.lsb), y.shape[0]
        if obs.still and self.state == OK and self.cusum.s == 0.0 and n >= 2:
            pend = self.pend
            pend.outside += k
            pend.samples += n
            pend.var_sum += float(np.var(y, ddof=1)) * n  # unbiased: ddof 0 gives 0.9 of it at 10 samples
            pend.var_samples += n
            dd = np.diff(y, 2)
            pend.dd_sq += float(np.dot(dd, dd))
            pend.dd_count += dd.shape[0]
            self._learn_jitter(y)
            self.lpend.append((self.nblk, float(np.mean(y)) / self.lsb))
        else:
            self.prev_level = None
            if not obs.still:
                self.recent = []  # moved: the level before is no expectation
        self.nblk += 1
        if self.codes.outside < MIN_OUTSIDE or self.codes.var_samples == 0:
            self._end_run(commit=True)
            return None
        # What lands beyond two codes is the samples' own spread at rest (their within-block variance v_b),
        # not the second-difference figure v_dd: a gyro low-passed well below its logged rate (the rover: 5 Hz
        # at 50 Hz) spreads its samples over codes far beyond its sample-to-sample noise, and a decimated one
        # with energy near its Nyquist rate (the plane at 10 Hz) less than that figure says (taken from v_dd, a
        # healthy plane resting on a boundary for a minute would be named stuck). The noise s = sqrt(v_b - 1/12)
        # (Sheppard), less if the axis left two codes at rest less often than s on a boundary would; a
        # correlated block counts as n min(1, v_dd / v_b) independent samples (the share of its variance that
        # changes from sample to sample).
        v_b = self.codes.var_sum / self.codes.var_samples / (self.lsb * self.lsb)
        s_b = math.sqrt(max(v_b - 1.0 / 12.0, 0.0))
        seen = self.codes.outside / self.codes.samples
        if s_b <= 0 or seen <= 0:
            self._end_run(commit=True)
            return 0.0  # a level resting on a boundary could give all of it: no evidence either way
        s_l = min(s_b, -1.0 / _STD_NORMAL.inv_cdf(0.5 * min(seen, 0.9)))
        q0 = min(math.erfc(1.0 / (s_l * math.sqrt(2.0))), 0.45)
        f = self._independent_share(ref)
        if self.two.state == FAULT:
            self._end_run(commit=False)
            return two_code_llr(k * f, n * f, q0)
        if c.max() - c.min() > MAX_CODES:
            self._end_run(commit=True)
            return -self.two.s - 1.0
        lo = int(c.min())
        self.run.append((lo, np.bincount((c - lo).astype(np.int64)).astype(float), {}))
        del self.run[:-RUN_BLOCKS]
        g = self._best_window(s_l, q0 / Q_RATIO, f, self._jitter_lsb(f), self._level_prior())
        if g <= 0.0:
            self._end_run(commit=True)
            return -self.two.s - 1.0
        return g - self.two.s

    def _independent_share(self, ref) -> float:
        """min(1, v_dd / v_b): the share of the still samples' spread that changes from one sample to the next,
        each sample worth that many independent ones. Both from the same still samples (the reference's v2
        leaves outliers out and comes from the first still blocks only: on a plane's nearly white 10 Hz
        codes it is 0.79 of their spread, which would lose a fifth of the evidence)."""
        c = self.codes
        v_b = c.var_sum / c.var_samples if c.var_samples > 0 else 0.0
        v_dd = c.dd_sq / c.dd_count / 6.0 if c.dd_count > 0 else ref.sigma2
        return min(1.0, v_dd / v_b) if v_b > 0 else 1.0

    def _learn_jitter(self, y: np.ndarray) -> None:
        """One still block's level (mean, LSB) against the last one's: what moves a healthy level from block to
        block beyond its samples' own noise. Differences are clipped at 1 LSB (a level step, a nudge the motion
        gate missed, must not teach a wide jitter: too narrow a jitter only costs evidence)."""
        m = float(np.mean(y)) / self.lsb
        vm = float(np.var(y)) / (self.lsb * self.lsb) / y.shape[0]
        if self.prev_level is not None:
            d = m - self.prev_level[0]
            self.jpend.d2 += min(d * d, 1.0)
            self.jpend.within += vm + self.prev_level[1]
            self.jpend.pairs += 1
        self.prev_level = (m, vm)

    def _jitter_lsb(self, f: float) -> float:
        """The sd (LSB) of a healthy level's own block-to-block jitter at rest: half the mean squared difference
        of successive still blocks' means less what their samples' noise gives (over ``f`` independent samples
        each); 0 until ``JITTER_MIN`` pairs were seen."""
        d2, within, m = self.jitter.d2, self.jitter.within, self.jitter.pairs
        if m < JITTER_MIN or f <= 0:
            return 0.0
        return math.sqrt(max(0.0, (d2 - within / f) / (2.0 * m)))

    def _level_prior(self) -> tuple[float, float] | None:
        """Where a healthy level is expected (LSB) and the sd of that expectation for the current block: the mean
        of the last ``PRIOR_BLOCKS`` still blocks kept before the run, its error as learned at rest 1 and
        ``PRIOR_LEAD`` blocks ahead, linear in between and beyond (wander grows with the lead). None until
        ``JITTER_MIN`` errors of each lead were seen, or while too few still blocks precede the run."""
        le = self.lead_err
        e1, n1, e16, n16 = le.sq1, le.n1, le.sq_lead, le.n_lead
        if n1 < JITTER_MIN or n16 < JITTER_MIN or len(self.recent) < PRIOR_BLOCKS:
            return None
        last = self.recent[-PRIOR_BLOCKS:]
        lead = max(1, self.nblk - last[-1][0])
        v1, v16 = e1 / n1, e16 / n16
        var = v1 + max(0.0, v16 - v1) * (lead - 1) / (PRIOR_LEAD - 1)
        return sum(m for _, m in last) / PRIOR_BLOCKS, math.sqrt(max(var, 1e-6))

    def _learn_prior(self, blocks: list) -> None:
        """Still blocks kept (their run ended healthy): each block's level against the expectation from the
        blocks before it, 1 and ``PRIOR_LEAD`` blocks earlier (errors clipped at 1 LSB: a step or a nudge must
        not teach a wide expectation, which only costs evidence)."""
        for i, m in blocks:
            r = self.recent
            if len(r) >= PRIOR_BLOCKS and i - r[-1][0] == 1:
                e = m - sum(x for _, x in r[-PRIOR_BLOCKS:]) / PRIOR_BLOCKS
                self.lead_err.sq1 += min(e * e, 1.0)
                self.lead_err.n1 += 1
            k = PRIOR_BLOCKS + PRIOR_LEAD - 1
            if len(r) >= k and i - r[-k][0] == k:
                old = r[-k:-k + PRIOR_BLOCKS]
                e = m - sum(x for _, x in old) / PRIOR_BLOCKS
                self.lead_err.sq_lead += min(e * e, 1.0)
                self.lead_err.n_lead += 1
            r.append((i, m))
        del self.recent[:-(PRIOR_BLOCKS + PRIOR_LEAD)]

    def _best_window(self, s_l: float, q1: float, f: float = 1.0, tau: float = 0.0,
                     prior: tuple[float, float] | None = None) -> float:
        """The largest evidence (:func:`codes_glr`, each sample worth ``f``) of the run's last 1, 2, ..., 32, 48,
        64, ... blocks and of all of it (the change may have come inside the run: a frozen value's codes after
        healthy ones, or after one of its own rare flips to the next code). Frozen: one split between the
        window's two codes for all its blocks. Healthy: one level for the window, each block's own level
        spread around it by the jitter ``tau`` (LSB) learned at rest: a frozen value's split holds still from
        block to block, a healthy level's moves; and a window's healthy level away from where the still blocks
        before the run put it (``prior``: level, sd) is penalised, by at most ``PRIOR_CAP`` nats: a value
        frozen at one sample of the noise sits about one sample sd away from the level it froze from."""
        m = len(self.run)
        lo = min(b[0] for b in self.run)
        hi = max(b[0] + b[1].shape[0] for b in self.run)
        if hi - lo > MAX_CODES:
            return -1.0
        cnt = np.zeros(hi - lo)
        wins, k = [], 0
        for i, (b_lo, b_cnt, _) in enumerate(reversed(self.run)):
            cnt[b_lo - lo:b_lo - lo + b_cnt.shape[0]] += b_cnt
            if i + 1 == WINDOWS[k] or i + 1 == m:
                k += i + 1 == WINDOWS[k]
                j, n_a, n_b, n_o = _pair_counts(cnt)
                wins.append((i + 1, lo + j, n_a, n_b, n_o))
        best = -math.inf
        key = (round(s_l, 3), round(f, 3), round(tau, 3))
        for pair in {w[1] for w in wins}:
            healthy = np.cumsum(np.vstack([self._block_logs(b, pair, key) for b in reversed(self.run)]), axis=0)
            if prior is not None:
                lev = pair - 1.0 + np.arange(healthy.shape[1]) * LEVEL_STEP
                healthy = healthy - np.minimum(0.5 * ((lev - prior[0]) / prior[1]) ** 2, PRIOR_CAP)
            for w, p_code, n_a, n_b, n_o in wins:
                if p_code != pair:
                    continue
                n2 = n_a + n_b
                frozen = n_o * math.log(q1) + n2 * math.log(1.0 - q1)
                frozen += sum(x * math.log(x / n2) for x in (n_a, n_b) if x > 0)
                best = max(best, f * frozen - float(healthy[w - 1].max()))
        return best

    @staticmethod
    def _block_logs(block: tuple, pair: int, key: tuple) -> np.ndarray:
        """:func:`_block_level_logs` of one block of the run relative to the codes ``pair``, ``pair`` + 1 (kept
        with the block: only the newest block's are new at each step)."""
        b_lo, b_cnt, memo = block
        got = memo.get((pair, key))
        if got is None:
            i = pair - b_lo
            n_a = float(b_cnt[i]) if 0 <= i < b_cnt.shape[0] else 0.0
            n_b = float(b_cnt[i + 1]) if 0 <= i + 1 < b_cnt.shape[0] else 0.0
            row = np.array([n_a, n_b, float(b_cnt.sum()) - n_a - n_b])
            got = memo[(pair, key)] = _block_level_logs(row, key[0], key[1], key[2])
        return got

    def _end_run(self, commit: bool) -> None:
        """The run of codes ends: what it taught at rest is kept if it ended healthy (``commit``)."""
        if commit:
            self.codes.add(self.pend)
            self.jitter.add(self.jpend)
            self._learn_prior(self.lpend)
        self.pend = CodeTally()
        self.jpend = JitterTally()
        self.lpend = []
        self.run = []

    def state_dict(self) -> dict:
        return {"cusum": self.cusum.state_dict(), "two": self.two.state_dict(), "vib": self.vib.state_dict(),
                "equal_run": self.equal_run,
                "lsb": self.lsb if math.isfinite(self.lsb) else None, "quantised": self.quantised,
                "kind": self.kind, "detail": self.detail, "alive": self.alive,
                "out": [self.codes.outside, self.codes.samples], "spread": self.codes.spread,
                "pend": self.pend.to_list(), "jitter": self.jitter.to_list(), "jpend": self.jpend.to_list(),
                "recent": self.recent, "lpend": self.lpend, "lead_err": self.lead_err.to_list(), "nblk": self.nblk,
                "run": [[lo, c.tolist()] for lo, c, _ in self.run]}

    def load_state_dict(self, d: Mapping) -> None:
        self.cusum.load_state_dict(d.get("cusum", {}))
        self.two.load_state_dict(d.get("two", {}))
        self.vib.load_state_dict(d.get("vib", {}))
        self.equal_run = int(d.get("equal_run", 0))
        self.lsb = math.inf if d.get("lsb") is None else float(d["lsb"])
        self.quantised = bool(d.get("quantised", False))
        self.kind = "dead" if d.get("kind") == "dead" else "stuck"
        self.detail = str(d.get("detail", ""))
        self.alive = bool(d.get("alive", False))
        self.codes = CodeTally.from_lists(d.get("out"), d.get("spread"))
        self.pend = CodeTally.from_list(d.get("pend"))
        self.run = [(int(lo), np.asarray(c, dtype=float), {}) for lo, c in (d.get("run") or [])]
        self.jitter = JitterTally.from_list(d.get("jitter"))
        self.jpend = JitterTally.from_list(d.get("jpend"))
        self.prev_level = None
        self.recent = [(int(i), float(m)) for i, m in (d.get("recent") or [])]
        self.lpend = [(int(i), float(m)) for i, m in (d.get("lpend") or [])]
        self.lead_err = LeadErrors.from_list(d.get("lead_err"))
        self.nblk = int(d.get("nblk", 0))
