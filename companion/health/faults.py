"""Fault taxonomy of a gyro: the common interface of the fault detectors, their codes and block statistics.

Every detector (one module per kind: ``stuck``, ``noise``, ``bias``, ``spikes``, ``saturation``,
``resolution``, ``timing``, ``disagreement``) implements :class:`FaultDetector`, in the spirit of PX4's
DataValidator (small explicit states, named thresholds, one update):

* ``update(obs: Observation) -> list[FaultEvent]``: one block's :class:`Observation` (the block's
  ``BlockStats``, timestamps, still or not, the axis and its reference, the Allan-predicted extra variance of
  a block mean, and for a pair of IMUs the aligned samples of both); it returns the state changes
  (OK -> FAULT or FAULT -> OK) as events, empty when nothing changed (the bias detector may return two:
  a jump and a drift);
* ``state`` is ``OK`` or ``FAULT``; ``value`` the figure the report quotes (ratio, offset, percentage);
* ``state_dict()`` / ``load_state_dict()`` for the run state file.

Most detectors are a CUSUM (Page 1954) of a per-block log-likelihood ratio (LLR, nats) between a
healthy hypothesis H0 (the reference learned from still data) and a fault hypothesis H1:

    S_k = max(0, S_{k-1} + llr_k),   FAULT when S_k > h                                      (1)

A CUSUM with threshold h has an in-control average run length of about e^h blocks (Lorden's bound:
ARL0 >= e^h), and a detection delay close to h / KL(H1 || H0), the information limit for that
false-alarm rate (Lorden 1971). Once in FAULT the same recursion with -llr (evidence for healthy)
clears it when it exceeds ``h_off``. The others count consecutive bad / good blocks (:func:`debounce`).

Reported as NAMED_VALUE_FLOAT: ``IMU{i}G_FLT`` the code of the most severe active fault (``KIND_CODE``,
order ``PRIORITY``) and ``IMU{i}G_FLM`` the bitmask of every active fault (bit k set: code k active,
:func:`fault_mask`), so that faults present together are all seen. Pure numpy; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Iterable, Mapping, Protocol

import numpy as np

from companion.health.axis_ref import AxisRef
from companion.health.block_stats import BlockStats
from companion.health.hold import FAULT, OK

#: fault kind -> code sent as IMU{i}G_FLT (0: no fault) and bit in IMU{i}G_FLM. The highest-priority active
#: kind (lowest position in PRIORITY) is the code reported.
KIND_CODE = {
    "none": 0,
    "stuck": 1,
    "noise": 2,
    "bias_jump": 3,
    "bias_drift": 4,
    "spikes": 5,
    "saturation": 6,
    "rate": 7,
    "disagree": 8,
    "allan": 9,
    "resolution": 10,
    "dead": 11,
}
PRIORITY = ("stuck", "dead", "disagree", "saturation", "noise", "spikes", "resolution", "bias_jump", "bias_drift",
            "rate", "allan")
#: kinds sent as CRITICAL (MAV_SEVERITY_CRITICAL = 2); in-flight disagreement too (decided by the caller)
CRITICAL_KINDS = ("stuck",)


@dataclass
class FaultEvent:
    """One state change of one detector: what the STATUSTEXT says."""

    imu: int
    axis: str  # "gx", "gy", "gz", or "" for the whole IMU (timing)
    kind: str
    state: int  # FAULT or OK
    value: float = math.nan
    detail: str = ""  # extra words (e.g. "IMU0/IMU2" for a disagreement)
    critical: bool = False

    def text(self) -> str:
        """STATUSTEXT (<= 50 characters), e.g. ``IMU0 gyro X noise 6.1x baseline``."""
        where = f"IMU{self.imu} gyro" + (f" {self.axis[1].upper()}" if self.axis else "")
        if self.state == OK:
            return f"{where} {KIND_WORDS[self.kind]} cleared"[:50]
        v = self.value
        body = {
            "stuck": "stuck",
            "noise": f"noise {v:.1f}x baseline",
            "bias_jump": f"bias jump {v:+.2f} deg/s",
            "bias_drift": f"bias drift {v:+.2f} deg/s",
            "spikes": f"spikes {v:.2g} %",
            "saturation": f"saturated at {v:.3g} rad/s",
            "rate": self.detail or f"rate {v:.0f} Hz",
            "disagree": f"disagrees with {self.detail}",
            "allan": self.detail,
            "resolution": f"resolution lost: steps {v:.0f}x LSB",
            "dead": DEAD_WORDS.get(self.detail, DEAD_WORDS[""]),
        }[self.kind]
        return f"{where} {body}"[:50]


KIND_WORDS = {"stuck": "stuck", "noise": "noise", "bias_jump": "bias jump", "bias_drift": "bias drift",
              "spikes": "spikes", "saturation": "saturation", "rate": "timing", "disagree": "disagreement",
              "allan": "Allan terms", "resolution": "resolution loss", "dead": "zero reading"}
#: an axis reading exactly 0 in every sample (health/stuck.py): on integer messages (RAW_IMU, SCALED_IMU*:
#: int16 mrad/s) a gyro whose noise is below the 1 mrad/s step also reads 0 at rest, so the text says both;
#: a float message (HIGHRES_IMU, DataFlash, ULog) never reads exactly 0 from a live gyro, nor does a gyro
#: of a moving vehicle
DEAD_WORDS = {"": "reads 0: dead or below resolution", "float": "reads exactly 0: dead",
              "moving": "reads 0 while moving: dead"}


AXES = ("gx", "gy", "gz")


def fault_mask(kinds: Iterable[str]) -> int:
    """Bitmask of active fault kinds: bit ``KIND_CODE[kind]`` set for each (``IMU{i}G_FLM``; exact in a float32
    up to 2^24)."""
    m = 0
    for k in kinds:
        m |= 1 << KIND_CODE[k]
    return m


def mask_kinds(mask: int) -> list[str]:
    """The kinds whose bits are set in ``mask`` (inverse of :func:`fault_mask`)."""
    return [k for k, c in KIND_CODE.items() if c and int(mask) >> c & 1]


@dataclass
class Observation:
    """What a fault detector sees of one block of one IMU (the one argument of ``update``).

    * ``imu``: the IMU; ``axis``: "gx", "gy", "gz" for a per-axis detector ("" for the whole IMU);
    * ``stats``: the block's statistics (``BlockStats``, one column per axis); ``t``: its timestamps (s);
    * ``still``: the motion gate's decision for the block; ``ref``: the axis' still reference (``AxisRef``);
    * ``extra_var``: Allan-predicted variance of a block mean around the bias reference ((rad/s)^2);
    * ``y``: the block's samples (n, 3) (per-block detectors: the stuck test reads their codes);
    * pairs of IMUs: ``y`` and ``other`` the aligned samples (m, 3) of this IMU and of ``other_imu``,
      ``noise_var`` the white variance expected of their difference, ``noise_other`` the other IMU's own;
    * ``vibration``: the same IMU's accelerometer second-difference variance over its still reference (three
      axes pooled; nan before the reference or without an accelerometer): what the rest of the sensor sees;
      ``accel_quiet``: that accelerometer's second differences all stayed within ``SPIKE_K`` of their still
      scale in the block (False when unknown): no knock or jolt of the vehicle in it; ``accel_knock``: it
      moved beyond that scale for more than ``KNOCK_RUN`` samples in a row (the block's own robust scale
      before the reference exists): a knock or a touch, not an isolated glitch of the sensor.
    """

    imu: int = 0
    stats: BlockStats | None = None
    t: np.ndarray | None = None
    still: bool = True
    axis: str = ""
    ref: AxisRef | None = None
    extra_var: float = 0.0
    y: np.ndarray | None = None
    other: np.ndarray | None = None
    other_imu: int = -1
    noise_var: float | None = None
    noise_other: float | None = None
    vibration: float = math.nan
    accel_quiet: bool = False
    accel_knock: bool = False

    @property
    def col(self) -> int:
        """Column of ``axis`` in ``stats`` and in the samples."""
        return AXES.index(self.axis)

    def at(self, axis: str, ref: "AxisRef | None" = None, **kw) -> "Observation":
        """The same block seen by the detector of one axis."""
        return replace(self, axis=axis, ref=ref, **kw)

    def event(self, kind: str, state: int, value: float = math.nan, detail: str = "",
              critical: bool = False) -> "FaultEvent":
        return FaultEvent(self.imu, self.axis, kind, state, value, detail, critical)


class FaultDetector(Protocol):
    """The interface every fault detector implements (see the module docstring)."""

    kind: str
    state: int
    value: float

    def update(self, obs: Observation) -> list[FaultEvent]: ...

    def state_dict(self) -> dict: ...

    def load_state_dict(self, d: Mapping) -> None: ...


class Cusum:
    """One-sided CUSUM (1) with a reverse CUSUM that clears the fault; plain floats."""

    def __init__(self, h_on: float, h_off: float):
        self.h_on, self.h_off = float(h_on), float(h_off)
        self.state = OK
        self.s = 0.0  # evidence for the fault (while OK) or for healthy (while FAULT)

    def step(self, llr: float) -> bool:
        """Add one block's LLR (positive favours the fault); return True when the state changed."""
        if not math.isfinite(llr):
            return False
        if self.state == OK:
            self.s = max(0.0, self.s + llr)
            if self.s > self.h_on:
                self.state, self.s = FAULT, 0.0
                return True
        else:
            self.s = max(0.0, self.s - llr)
            if self.s > self.h_off:
                self.state, self.s = OK, 0.0
                return True
        return False

    def state_dict(self) -> dict:
        return {"state": self.state, "s": self.s}

    def load_state_dict(self, d: Mapping) -> None:
        self.state, self.s = int(d.get("state", OK)), float(d.get("s", 0.0))


def chi2_llr(u: float, nu: float, r1: float) -> float:
    """LLR of a variance ratio r1 against 1 for one block: u = s^2 / sigma0^2 with nu degrees of freedom.

    nu s^2 / sigma^2 ~ chi2(nu): llr = (nu / 2) * ((1 - 1 / r1) * u - ln r1).
    """
    return 0.5 * nu * ((1.0 - 1.0 / r1) * u - math.log(r1))


def gauss_mean_llr(x: float, sigma: float, delta: float) -> float:
    """Two-sided-ready LLR of a mean shift ``delta`` (same sign as wanted) for one block mean x +- sigma."""
    return (delta / (sigma * sigma)) * (x - 0.5 * delta)


#: an accelerometer beyond SPIKE_K of its scale over more than this many second differences (outliers at most
#: two samples apart: a ringing knock crosses zero) moved: a knock lasts several samples (a public PX4 log's
#: taps on a standing vehicle: 6-10 at 200 Hz, 20-40 sigma), an isolated outlier of the sensor 3 (+1, -2, +1)
KNOCK_RUN = 3
