"""What healthy still data of one gyro axis looks like: the reference its fault tests are judged against
(white-noise level and dof, bias, spike rate), learned from the first quiet blocks (numpy only)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from companion.health.block_stats import DD_NU_PER_SAMPLE

#: The noise test's level is learned from the reference's blocks and on until they hold NU_REF_MIN chi-square
#: degrees of freedom (white second differences; at most REF_MAX_FACTOR x ref_blocks blocks); the other tests
#: start from the reference of ref_blocks. A level below the truth by a factor persists in every test
#: against it: the noise test's CUSUM (noise.py) drifts up on a healthy gyro once it is 22 % low. 30 blocks of
#: 50 Hz hold 756 dof (22 % is 4.3 standard errors), 30 blocks of 10 Hz only 123 (1.7: a healthy copter streamed
#: at 10 Hz would be called noisy a few times a day). With 700 dof the 10 Hz level takes about 3 minutes of rest;
#: a 4 Hz one (5 samples a block, 1.5 dof) stops at the cap, 5 minutes and 370 dof (22 % is 3 standard errors
#: there).
NU_REF_MIN = 700.0
REF_MAX_FACTOR = 8  #: the noise level's blocks stop at this many times ref_blocks (a slow stream's cap)
#: A reference block whose v2 is above KNOCK x the median of the reference blocks is not rest: a knock or a
#: touch the motion gate passed as still. At rest that is chance only far in the tail (chi^2 with 4 dof above
#: 8.4x its mean: 1e-6). Left out of the rest level (AxisRef.rest) that a collapse of the noise is judged
#: against; kept in the noise level that a rise is judged against (see AxisRef).
KNOCK = 10.0


@dataclass
class AxisRef:
    """What healthy still data of one axis looks like, learned from the first ``ref_blocks`` quiet blocks.

    * ``sigma2``: white-noise variance (pooled v2), ``nu``: chi-square dof of one block's v2, the smaller of
      the white-noise figure and the one measured from the spread of v2 (coarse rounding spreads it)
    * ``mu``: mean rate (the bias at the start), ``spike_rate``: outliers per sample
    * ``rest``: the same white-noise level and dof from the blocks that are not knocks (v2 at most ``KNOCK``
      x the median), for the stuck detector. Why two: one knock among a public copter log's 30 reference
      blocks (400x the others) made the mean 15x the rest level, and after a restart the same rest read as a
      collapse of the noise (stuck). Left out of the level a noise *rise* is judged against, the roll gyro of
      a parked plane rocking in the wind (bursts 10x its rest, the accelerometer quiet, one IMU) became a
      noise fault; a rest level never above the mean only makes a collapse harder to claim.
    """

    sigma2: float = math.nan
    nu: float = math.nan
    sigma2_rest: float = math.nan
    nu_rest: float = math.nan
    mu: float = math.nan
    spike_rate: float = 0.0
    blocks: int = 0
    noise_sigma2: float = math.nan  # the noise test's level: these blocks and on to NU_REF_MIN dof
    noise_nu: float = math.nan
    _v2: list | None = None
    _mu: list | None = None
    _spk: int = 0
    _samples: int = 0
    _nu_sum: float = 0.0

    @property
    def ready(self) -> bool:
        return math.isfinite(self.sigma2)

    @property
    def noise_ready(self) -> bool:
        """The noise test's level is learned (with the reference from 50 Hz up, up to minutes later below)."""
        return math.isfinite(self.noise_sigma2)

    @property
    def rest(self) -> "RestLevel":
        """The rest level (knocks left out); the plain level for a reference saved without one."""
        if math.isfinite(self.sigma2_rest):
            return RestLevel(self.sigma2_rest, self.nu_rest)
        return RestLevel(self.sigma2, self.nu)

    def add(self, v2: float, m2: float, mean: float, spikes: int, n: int, ref_blocks: int) -> bool:
        """Add one quiet block; returns True when the reference becomes ready. Once it is, blocks still go to
        the noise test's level until that holds NU_REF_MIN dof (noise_ready)."""
        if self.noise_ready or not math.isfinite(v2):
            return False
        nu_white = DD_NU_PER_SAMPLE * max(m2, 1.0)
        self._nu_sum += nu_white
        if self._v2 is None:
            self._v2, self._mu = [], []
        self._v2.append(v2)
        if self.ready:
            if self._nu_sum >= NU_REF_MIN or len(self._v2) >= REF_MAX_FACTOR * ref_blocks:
                self.noise_sigma2, self.noise_nu = _pooled(np.asarray(self._v2), nu_white)
                self._v2 = None
            return False
        self._mu.append(mean)
        self._spk += int(spikes)
        self._samples += int(n)
        self.blocks += 1
        if self.blocks < ref_blocks:
            return False
        v = np.asarray(self._v2)
        self.sigma2, self.nu = _pooled(v, nu_white)
        med = float(np.median(v))
        rest = v[v <= KNOCK * med] if med > 0 else v
        self.sigma2_rest, self.nu_rest = _pooled(rest, nu_white) if rest.size >= 2 else (self.sigma2, self.nu)
        self.mu = float(np.mean(self._mu))
        self.spike_rate = self._spk / max(self._samples, 1)
        self._mu = None
        if self._nu_sum >= NU_REF_MIN:
            self.noise_sigma2, self.noise_nu = self.sigma2, self.nu
            self._v2 = None
        return True

    def state_dict(self) -> dict:
        return {"sigma2": _f(self.sigma2), "nu": _f(self.nu), "sigma2_rest": _f(self.sigma2_rest),
                "nu_rest": _f(self.nu_rest), "mu": _f(self.mu), "spike_rate": self.spike_rate,
                "blocks": self.blocks, "v2": self._v2, "means": self._mu, "spk": self._spk, "samples": self._samples,
                "noise_sigma2": _f(self.noise_sigma2), "noise_nu": _f(self.noise_nu), "nu_sum": self._nu_sum}

    def load_state_dict(self, d: Mapping) -> None:
        self.sigma2, self.nu, self.mu = _nan(d.get("sigma2")), _nan(d.get("nu")), _nan(d.get("mu"))
        self.sigma2_rest, self.nu_rest = _nan(d.get("sigma2_rest")), _nan(d.get("nu_rest"))
        self.spike_rate = float(d.get("spike_rate", 0.0))
        self.blocks = int(d.get("blocks", 0))
        self._nu_sum = float(d.get("nu_sum", 0.0))
        self._v2 = list(d["v2"]) if d.get("v2") is not None else None
        self._mu = list(d["means"]) if d.get("means") is not None else None
        self._spk, self._samples = int(d.get("spk", 0)), int(d.get("samples", 0))
        if "noise_sigma2" in d:
            self.noise_sigma2, self.noise_nu = _nan(d.get("noise_sigma2")), _nan(d.get("noise_nu"))
        else:  # a state without a noise level of its own: the reference's
            self.noise_sigma2, self.noise_nu = self.sigma2, self.nu


@dataclass(frozen=True)
class RestLevel:
    """A white-noise variance and the chi-square dof of one block's v2 against it."""

    sigma2: float
    nu: float

    @property
    def ready(self) -> bool:
        return math.isfinite(self.sigma2)


def _pooled(v: np.ndarray, nu_white: float) -> tuple[float, float]:
    """The pooled variance of the reference blocks' v2 and the dof of one block's v2: the smaller of the
    white-noise figure and the one measured from the spread of v2 (coarse rounding spreads it)."""
    s2 = float(v.mean())
    if s2 > 0:
        rel = float(v.var(ddof=1)) / (s2 * s2)
        nu_emp = 2.0 / rel if rel > 0 else nu_white
        # the spread of a variance estimated from ref_blocks values is itself uncertain: keep 70 %
        nu = min(nu_white, 0.7 * nu_emp)
    else:
        nu = nu_white
    return s2, max(nu, 2.0)


def _f(x: float):
    return x if math.isfinite(x) else None


def _nan(x) -> float:
    return math.nan if x is None else float(x)
