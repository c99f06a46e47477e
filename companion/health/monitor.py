"""All fault detectors of one IMU: per-axis references and detectors, the timing detector, the reported code.

``ImuFaults.on_block`` runs the checks valid on every block (stuck, spikes, saturation, timing: still or
moving, armed or not); ``ImuFaults.on_quiet`` the ones valid only on still, settled blocks (noise, bias
jump/drift, resolution) and learns the per-axis references (axis_ref.AxisRef) from the first ``ref_blocks`` of them
(the noise test's level on, on a slow stream, until it holds axis_ref.NU_REF_MIN degrees of freedom).
Disagreement lives with the pairs of IMUs (disagreement.py, driven by service/imu_group.py) and the Allan
rise with degradation.py; both feed ``set_external`` so that one code per IMU is reported.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from companion.health.bias import BiasDetector
from companion.health.axis_ref import AxisRef
from companion.health.block_stats import SPIKE_K, BlockStats
from companion.health.faults import (AXES, KIND_CODE, KNOCK_RUN, PRIORITY, FaultDetector, FaultEvent, Observation,
                                     fault_mask)
from companion.health.hold import FAULT, OK
from companion.health.evidence_rules import FaultLimits
from companion.health.noise import NoiseDetector
from companion.health.resolution import ResolutionDetector
from companion.health.saturation import SaturationDetector
from companion.health.spikes import SpikeDetector
from companion.health.stuck import StuckDetector
from companion.health.timing_faults import TimingDetector

REF_BLOCKS = 30  # still blocks (s) learned as the reference of the fast detectors


class AxisFaults:
    def __init__(self, abs_limit: float, limits: FaultLimits | None = None, coded_lsb: float | None = None):
        self.ref = AxisRef()
        self.stuck = StuckDetector(coded_lsb)
        self.noise = NoiseDetector(limits)
        self.bias = BiasDetector(limits)
        self.spikes = SpikeDetector()
        self.saturation = SaturationDetector(abs_limit)
        self.resolution = ResolutionDetector()
        #: run on every block (still or moving), spikes and saturation only while the axis is not stuck
        self.every: tuple[FaultDetector, ...] = (self.stuck, self.spikes, self.saturation)
        #: run on still, settled blocks once the reference is learned and the axis is not stuck
        self.quiet: tuple[FaultDetector, ...] = (self.resolution, self.noise, self.bias)

    def states(self) -> dict[str, int]:
        return {self.stuck.kind: self.stuck.state, "noise": self.noise.state, "bias_jump": self.bias.state,
                "bias_drift": self.bias.drift_state, "spikes": self.spikes.state,
                "saturation": self.saturation.state, "resolution": self.resolution.state}

    def state_dict(self) -> dict:
        return {"ref": self.ref.state_dict(), "stuck": self.stuck.state_dict(), "noise": self.noise.state_dict(),
                "bias": self.bias.state_dict(), "spikes": self.spikes.state_dict(),
                "saturation": self.saturation.state_dict(), "resolution": self.resolution.state_dict()}

    def load_state_dict(self, d: Mapping) -> None:
        self.ref.load_state_dict(d.get("ref", {}))
        self.stuck.load_state_dict(d.get("stuck", {}))
        self.noise.load_state_dict(d.get("noise", {}))
        self.bias.load_state_dict(d.get("bias", {}))
        self.spikes.load_state_dict(d.get("spikes", {}))
        self.saturation.load_state_dict(d.get("saturation", {}))
        self.resolution.load_state_dict(d.get("resolution", {}))


class ImuFaults:
    def __init__(self, imu: int, abs_limit: float = math.inf, ref_blocks: int = REF_BLOCKS, stamp_res: float = 0.0,
                 limits: FaultLimits | None = None, coded_lsb: float | None = None):
        """``coded_lsb``: the gyro's step (rad/s) on integer messages (RAW_IMU, SCALED_IMU*: 1 mrad/s), None for
        float messages (how an axis reading exactly 0 is named, health/stuck.py)."""
        self.imu = imu
        self.ref_blocks = int(ref_blocks)
        self.limits = limits or FaultLimits()
        self.axes = {ax: AxisFaults(abs_limit, self.limits, coded_lsb) for ax in AXES}
        self.timing = TimingDetector(stamp_res)
        self.external: dict[tuple[str, str], int] = {}  # (kind, axis) -> state, e.g. ("disagree", "gx")
        self.external_detail: dict[str, str] = {}  # axis -> the words of an external "dead" (frozen_hook)
        self.quiet_blocks = 0
        self.accel_ref = math.nan  # pooled accel second-difference variance of still blocks ((m/s^2)^2)
        self._accel = [0.0, 0]  # its sum and block count while it is learned
        self.accel_quiet = False  # the last block's accelerometer had no outlier against that reference
        self.accel_knock = False  # ... and outliers over more samples than an isolated glitch's (faults.KNOCK_RUN)

    # ------------------------------------------------------------------ inputs
    def dd_scale_ref(self) -> np.ndarray | None:
        """The still second differences' scale per axis (block_stats' outlier bar), at least what the learned
        resolution's rounding gives (sqrt(1/2) LSB): a healthy flip between two codes is no spike."""
        refs = [a.ref for a in self.axes.values()]
        if not all(r.ready for r in refs):
            return None
        return np.array([max(math.sqrt(6.0 * a.ref.sigma2), math.sqrt(0.5) * a.stuck.lsb if math.isfinite(a.stuck.lsb)
                             else 0.0) for a in self.axes.values()])

    def observe(self, st: BlockStats, t: np.ndarray | None = None, still: bool = True) -> Observation:
        """The observation of one block handed to the detectors of this IMU (``at`` narrows it to an axis)."""
        return Observation(self.imu, st, t, still)

    def vibration(self, accel: np.ndarray | None, still: bool) -> float:
        """The block's accelerometer second-difference variance (three axes pooled) over that of the first
        ``ref_blocks`` still blocks (learned meanwhile, like the gyro references): 1 while the vehicle
        vibrates as it did then, below 1 when the vibration fell (an engine stopped), nan when unknown."""
        self.accel_quiet = self.accel_knock = False
        if accel is None or accel.shape[0] < 5:
            return math.nan
        dd = accel[2:] - 2.0 * accel[1:-1] + accel[:-2]
        v = float(np.mean(dd * dd)) * 3.0 / 6.0
        if not math.isfinite(v):
            return math.nan
        if math.isfinite(self.accel_ref):
            # per axis the second differences' variance is 6 / 3 of the pooled figure: a knock or a jolt of the
            # vehicle shows there, a glitch of the gyro alone does not (spikes.py weighs a spike's size only then)
            bar = SPIKE_K * math.sqrt(2.0 * self.accel_ref)
            self.accel_quiet = bool(np.max(np.abs(dd)) <= bar)
        else:  # before the reference: the block's own robust scale (the median absolute dd of each axis)
            bar = SPIKE_K * 1.4826 * np.median(np.abs(dd), axis=0)
        out = np.any(np.abs(dd) > bar, axis=1) if np.all(np.asarray(bar) > 0) else np.zeros(dd.shape[0], bool)
        self.accel_knock = bool(_longest_cluster(out) > KNOCK_RUN)
        if not math.isfinite(self.accel_ref):
            if still:
                self._accel[0] += v
                self._accel[1] += 1
                if self._accel[1] >= self.ref_blocks and self._accel[0] > 0:
                    self.accel_ref = self._accel[0] / self._accel[1]
            return math.nan
        return v / self.accel_ref

    def on_block(self, st: BlockStats, t: np.ndarray, still: bool, y: np.ndarray | None = None,
                 accel: np.ndarray | None = None) -> list[FaultEvent]:
        """Every block: timing, then per axis stuck, spikes, saturation. ``y``: the block's gyro samples (n, 3)
        (the stuck test reads their spread over codes); ``accel``: the accelerometer's (n, 3) (the vibration the
        stuck test weighs a gyro's quiet against)."""
        obs = self.observe(st, t, still)
        obs.y = y
        obs.vibration = self.vibration(accel, still)
        obs.accel_quiet = self.accel_quiet
        obs.accel_knock = self.accel_knock
        ev = self.timing.update(obs)
        for ax, af in self.axes.items():
            o = obs.at(ax, af.ref)
            ev += af.stuck.update(o)
            if af.stuck.state == OK:
                ev += af.spikes.update(o)
                ev += af.saturation.update(o)
        return ev

    def on_quiet(self, st: BlockStats, extra_var: Mapping[str, float] | None = None,
                 y: np.ndarray | None = None, t: np.ndarray | None = None) -> list[FaultEvent]:
        """A still, settled block: learn the references, then resolution, noise and bias. ``y``, ``t``: the
        block's gyro samples (n, 3) and times (the noise test places the bias on the code grid with them)."""
        ev = []
        self.quiet_blocks += 1
        obs = self.observe(st, t)
        obs.y = y
        for j, (ax, af) in enumerate(self.axes.items()):
            learning = not af.ref.ready
            # the reference's blocks, and on for the noise test's level until it holds NU_REF_MIN dof (slow streams)
            if not af.ref.noise_ready and af.stuck.state == OK and af.spikes.state == OK:
                af.noise.learn(obs.at(ax, af.ref))
                af.ref.add(float(st.v2[j]), float(st.m2[j]), float(st.mean[j]), int(st.spikes[j]), st.n,
                           self.ref_blocks)
                if learning:  # the bias wander of the reference period counts too; its temperature is the origin
                    af.bias.add_reference(float(st.mean[j]), float(st.temperature))
            if learning or af.stuck.state == FAULT:
                continue
            o = obs.at(ax, af.ref, extra_var=(extra_var or {}).get(ax, 0.0))
            for det in af.quiet:
                ev += det.update(o)
        return ev

    def set_external(self, kind: str, axis: str, state: int) -> None:
        if state == FAULT:
            self.external[(kind, axis)] = FAULT
        else:
            self.external.pop((kind, axis), None)

    # ------------------------------------------------------------------ outputs
    def active(self) -> list[tuple[str, str]]:
        """Active faults as (kind, axis), most severe first."""
        out = [(k, ax) for ax, af in self.axes.items() for k, s in af.states().items() if s == FAULT]
        if self.timing.state == FAULT:
            out.append(("rate", ""))
        out += [k for k, s in self.external.items() if s == FAULT]
        return sorted(out, key=lambda ka: (PRIORITY.index(ka[0]), ka[1]))

    def code(self) -> int:
        """``IMU{i}G_FLT``: the code of the most severe active fault (0: none)."""
        act = self.active()
        return KIND_CODE[act[0][0]] if act else 0

    def mask(self) -> int:
        """``IMU{i}G_FLM``: every active fault kind as a bit (bit k: code k), e.g. stuck and noise -> 0b110."""
        return fault_mask(k for k, _ in self.active())

    def still_sigma2(self) -> list[float] | None:
        """The white-noise variance of every axis' still reference; None until all are learned (and > 0)."""
        refs = [a.ref for a in self.axes.values()]
        if not all(r.ready and r.sigma2 > 0 for r in refs):
            return None
        return [r.sigma2 for r in refs]

    def value_of(self, kind: str, axis: str) -> float:
        """The figure quoted for an active fault (ratio, offset, percentage, level; rate for ``rate``)."""
        if kind == "rate":
            return self.timing.value
        af = self.axes[axis]
        return {"stuck": math.nan, "dead": math.nan, "noise": af.noise.value, "bias_jump": af.bias.value,
                "bias_drift": af.bias.drift_value, "spikes": af.spikes.value,
                "saturation": af.saturation.value, "resolution": af.resolution.value}[kind]

    def event_of(self, kind: str, axis: str) -> FaultEvent:
        """The FAULT event of an active per-axis fault as its detector said it: value, words, severity."""
        # held by the sample-level test (health/frozen_watch.py): a value held while the vehicle moves
        crit = kind in ("stuck", "dead") and (self.axes[axis].stuck.critical or (kind, axis) in self.external)
        return FaultEvent(self.imu, axis, kind, FAULT, self.value_of(kind, axis), self.detail_of(kind, axis), crit)

    def detail_of(self, kind: str, axis: str) -> str:
        """The words that go with an active fault beside its value ("float"/"moving" of a zero reading, the
        timing's rate or jitter)."""
        if kind == "rate":
            return self.timing.detail
        if kind == "dead" and (kind, axis) in self.external:
            return self.external_detail.get(axis, "moving")
        return self.axes[axis].stuck.detail if kind == "dead" and axis in self.axes else ""

    def restart(self) -> None:
        """A new run restored from the state: what is judged within a run only starts afresh, the bias
        (health/bias.py, Restarts) and the timing (health/timing_faults.py); the noise references are the sensor's
        and are kept."""
        for af in self.axes.values():
            af.bias.restart()
        self.timing.restart()

    def noise_ref(self, axis: str) -> float | None:
        r = self.axes[axis].ref
        return r.sigma2 if r.ready else None

    def state_dict(self) -> dict:
        return {"axes": {ax: af.state_dict() for ax, af in self.axes.items()}, "timing": self.timing.state_dict(),
                "external": [[k, a] for (k, a) in self.external], "quiet_blocks": self.quiet_blocks,
                "accel_ref": self.accel_ref if math.isfinite(self.accel_ref) else None, "accel_learn": self._accel}

    def load_state_dict(self, d: Mapping) -> None:
        for ax, s in (d.get("axes") or {}).items():
            if ax in self.axes:
                self.axes[ax].load_state_dict(s)
        self.timing.load_state_dict(d.get("timing", {}))
        self.external = {(k, a): FAULT for k, a in d.get("external", [])}
        self.quiet_blocks = int(d.get("quiet_blocks", 0))
        self.accel_ref = math.nan if d.get("accel_ref") is None else float(d["accel_ref"])
        self._accel = [float(v) for v in (d.get("accel_learn") or [0.0, 0])]


def _longest_cluster(mask: np.ndarray, gap: int = 2) -> int:
    """The longest extent (samples, first to last) of the ``mask``'s True samples with at most ``gap`` False
    ones between neighbours: a ringing knock's second differences cross zero between their outliers."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return 0
    cut = np.flatnonzero(np.diff(idx) > gap + 1)
    starts, ends = idx[np.r_[0, cut + 1]], idx[np.r_[cut, idx.size - 1]]
    return int((ends - starts).max()) + 1
