"""The pure parts of an alarm's evidence: each detector's statistic and threshold after a block, min/max
decimation of a time series, the two-sided Welch PSD of a block, and the sentence that says what tripped an
alarm. The service keeps them around each alarm (:mod:`companion.service.evidence_log`); the schema of an
evidence item is in docs/reports.md. Pure numpy/scipy; no I/O.

A statistic is ``(value, threshold, state)``: for a CUSUM detector the evidence S (nats) for the fault while
the state is OK (the alarm when S passes the threshold), then the evidence for healthy that clears it; for a
debounced one the count of bad blocks in a row against the blocks it needs; for the Allan check the
current/baseline ratio of the worst parameter against ``ratio_on``; for the sample-level frozen watch
(health/frozen_watch.py) the equal pairs of samples seen while the vehicle moved against the ``NEED`` that
names the axis; for the in-flight noise test the change of the IMU's pair figures from their baseline in
standard deviations against the test's threshold.
"""

from __future__ import annotations

import math

import numpy as np

from companion.health import bias as _bias
from companion.health import disagreement as _dis
from companion.health import frozen_watch as _frz
from companion.health import noise as _noise
from companion.health import resolution as _res
from companion.health import spikes as _spk
from companion.health import stuck as _stk
from companion.health import timing_faults as _tim
from companion.health.faults import AXES
from companion.health.hold import FAULT, OK

DEG = math.pi / 180.0

#: kind -> (what the statistic is, its unit)
STAT_NAMES = {
    "noise": ("CUSUM of the noise-variance log-likelihood ratio", "nats"),
    "spikes": ("CUSUM of the outlier-rate log-likelihood ratio", "nats"),
    "stuck": ("frozen-reading evidence over its bar (largest of its three CUSUMs and the identical-sample run)",
              "share of the bar"),
    "dead": ("frozen-reading evidence over its bar (largest of its three CUSUMs and the identical-sample run)",
             "share of the bar"),
    "bias_jump": ("CUSUM of the still-block mean shift (larger of up and down)", "nats"),
    "bias_drift": ("distance of the slow bias average from its reference", "deg/s"),
    "saturation": ("largest |rate| of the block", "rad/s"),
    "resolution": ("blocks in a row with steps of 2 LSB or more", "blocks"),
    "rate": ("blocks in a row with the rate or the timing off", "blocks"),
    "disagree": ("CUSUM of the residual against the other IMU (larger of up and down)", "nats"),
    "allan": ("online Allan term over its baseline (worst of N, B, K)", "ratio"),
    "frozen": ("pairs of consecutive samples with one value while the vehicle moved (calm pairs by their weight)",
               "pairs"),
    "flight_noise": ("in flight: the change of the noise of the IMU's differences with its twins from their "
                     "baseline in standard deviations (a fall counted as a rise; the largest)", "sigma"),
    "ground_noise": ("armed on the ground: the change of the noise of the IMU's differences with its twins from "
                     "their baseline in standard deviations (a fall counted as a rise; the largest)", "sigma"),
}


#: kind -> the bar its statistic passes when the alarm is raised (the allan check's is its ratio_on)
ALARM_BAR = {"noise": _noise.H_ON, "spikes": _spk.H_ON, "stuck": 1.0, "dead": 1.0,
             "bias_jump": _bias.H_ON, "bias_drift": _bias.DRIFT_TOL / DEG, "resolution": float(_res.HOLD),
             "rate": float(_tim.HOLD), "disagree": _dis.H_ON, "frozen": float(_frz.NEED)}


def _cusum(c, h_on: float, h_off: float) -> tuple[float, float, int]:
    return float(c.s), (h_on if c.state == OK else h_off), int(c.state)


def axis_statistics(af, ax: str) -> dict[str, tuple[float, float, int]]:
    """The statistics of one axis' detectors (health.monitor.AxisFaults) after a block, keyed by kind."""
    st = af.stuck
    # the CUSUMs over their bar, and the run of identical samples over the run that flags it (health/stuck.py)
    bar = _stk.H_ON if st.state == OK else _stk.H_OFF
    run = st.equal_run / (_stk.EQUAL_BLOCKS * _stk.EQUAL_MIN_SAMPLES) if st.state == OK else 0.0
    stuck = (float(max(st.cusum.s / bar, st.two.s / bar, st.vib.s / bar, run)), 1.0, int(st.state))
    b = af.bias
    up, down = (b.up, b.down)
    jump = (float(max(up.s, down.s)), _bias.H_ON if b.state == OK else _bias.H_OFF, int(b.state))
    drift = abs(b.e - (b.drift_r if b.drift_state == FAULT else b.r)) / DEG if math.isfinite(b.e) and math.isfinite(b.r) else math.nan
    sat = af.saturation
    return {
        "noise": _cusum(af.noise.cusum, _noise.H_ON, _noise.H_OFF),
        "spikes": _cusum(af.spikes.cusum, _spk.H_ON, _spk.H_OFF),
        "stuck": stuck, "dead": stuck,
        "bias_jump": jump,
        "bias_drift": (float(drift), _bias.DRIFT_TOL / DEG, int(b.drift_state)),
        "saturation": (math.nan, float(sat.abs_limit) if math.isfinite(sat.abs_limit) else math.nan, int(sat.state)),
        "resolution": (float(af.resolution.count), float(_res.HOLD), int(af.resolution.state)),
    }


def imu_statistics(faults, top=None) -> dict[str, tuple[float, float, int]]:
    """Every per-axis statistic of one IMU (health.monitor.ImuFaults), keyed ``kind/axis``, and the timing's
    as ``rate/``. ``top``: the block's largest |rate| per axis (BlockStats.top), the saturation statistic."""
    out = {}
    for j, (ax, af) in enumerate(faults.axes.items()):
        for kind, v in axis_statistics(af, ax).items():
            if kind == "saturation" and top is not None:
                v = (float(top[j]), v[1], v[2])
            out[f"{kind}/{ax}"] = v
    tm = faults.timing
    out["rate/"] = (float(tm.count), float(_tim.HOLD), int(tm.state))
    return out


def pair_statistics(pairs, imu: int) -> dict[str, tuple[float, float, int]]:
    """The disagreement CUSUMs of every pair holding ``imu`` (health.disagreement.PairDisagreement), the
    largest per axis, keyed ``disagree/axis``."""
    out: dict[str, tuple[float, float, int]] = {}
    for (i, j), p in pairs.items():
        if imu not in (i, j):
            continue
        for a, ax in enumerate(AXES):
            s = float(max(p.up[a].s, p.down[a].s))
            state = int(p.axis_state(a))
            v = (s, _dis.H_ON if state == OK else _dis.H_OFF, state)
            old = out.get(f"disagree/{ax}")
            if old is None or v[2] > old[2] or (v[2] == old[2] and v[0] > old[0]):
                out[f"disagree/{ax}"] = v
    return out


def allan_statistics(detector, ratio_on: float) -> dict[str, tuple[float, float, int]]:
    """The Allan check's worst current/baseline ratio per axis (health.degradation.HealthDetector)."""
    out: dict[str, tuple[float, float, int]] = {}
    for (ax, _p), d in detector.detectors.items():
        if not math.isfinite(d.ratio):
            continue
        old = out.get(f"allan/{ax}")
        if old is None or d.ratio > old[0]:
            out[f"allan/{ax}"] = (float(d.ratio), float(ratio_on), int(max(d.state, old[2] if old else 0)))
    return out


def frozen_statistics(watch, imu: int) -> dict[str, tuple[float, float, int]]:
    """The frozen watch's run of equal values per axis of ``imu`` (health.frozen_watch.FrozenWatch): its
    motion pairs so far against the ``NEED`` that names the axis, keyed ``frozen/axis``."""
    tr = watch.imus.get(imu) if watch is not None else None
    if tr is None:
        return {}
    return {f"frozen/{ax}": (float(r.motion * _frz.NEED), float(_frz.NEED), int(r.state))
            for ax, r in zip(_frz.AXES, tr.runs)}


def minmax_buckets(t: np.ndarray, y: np.ndarray, width: float,
                   hi: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Decimation that keeps every spike and plateau: the samples ``y`` (n, k) at times ``t`` (n,, in order)
    cut into buckets of ``width`` s on one grid (bucket i holds i * width <= t < (i + 1) * width); per bucket its
    index i and each column's min and max. ``hi``: the samples are already buckets (``y`` their min, ``hi``
    their max), merged where they share an index."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float).reshape(t.shape[0], -1)
    top = y if hi is None else np.asarray(hi, dtype=float).reshape(y.shape)
    if t.size == 0:
        return np.empty(0, dtype=np.int64), np.empty((0, y.shape[1])), np.empty((0, y.shape[1]))
    idx = np.floor(t / width).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, np.diff(idx) != 0])
    return idx[starts], np.minimum.reduceat(y, starts, axis=0), np.maximum.reduceat(top, starts, axis=0)


def psd_two_sided(y: np.ndarray, rate_hz: float, nperseg: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD (Hann, half overlap, mean removed) of the columns of ``y`` (n, k), two-sided as IEEE 952
    uses it ((unit)^2/Hz, at 0 .. rate/2): the one-sided estimate halved except at 0 and Nyquist."""
    from scipy.signal import welch

    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    seg = int(min(nperseg, n))
    if seg < 8 or not rate_hz > 0:
        return np.empty(0), np.empty((0, y.shape[1] if y.ndim > 1 else 1))
    f, p = welch(y, fs=rate_hz, nperseg=seg, axis=0, detrend="constant")
    p = np.asarray(p).reshape(f.size, -1) / 2.0
    p[0] *= 2.0
    if seg % 2 == 0:
        p[-1] *= 2.0
    return f, p


def sentence(kind: str, imu: int, axis: str, value: float, detail: str = "", threshold: float = math.nan) -> str:
    """One sentence a user can read without the docs: what the detector saw and the bar it passed."""
    who = f"IMU{imu} gyro" + (f" axis {axis[1].upper()}" if axis else "")
    h = f"{threshold:g}" if math.isfinite(threshold) else "its threshold"
    v = value if math.isfinite(value) else math.nan
    if kind == "frozen":
        what, word = ("exactly 0", "dead") if value == 0.0 else (f"one value ({v:.4g} rad/s)", "frozen")
        if detail == "float":
            return (f"{who}: it read {what} at rest for far more pairs of samples than its own noise allows (it "
                    f"changed value in most pairs before): {word}.")
        return (f"{who}: it read {what} in {h} or more pairs of consecutive samples while the other IMUs' same "
                f"axis (or its own accelerometer) showed the vehicle turning: {word}.")
    if kind in ("flight_noise", "ground_noise"):
        where = "in flight" if kind == "flight_noise" else "armed on the ground"
        way = "rose" if not v < 1.0 else "fell"
        return (f"{who}: {where}, the noise of its difference with a twin IMU {way} to {v:.2g}x the level learned "
                f"{where}; the change stayed beyond {h} standard deviations (the threshold of the test's false-alarm "
                "rate) for several checks in a row while the other IMUs' difference stayed as before: this IMU's own noise "
                "or its pick-up of the frame's vibration changed.")
    words = {
        "noise": f"{who}: its noise rose to {v:.1f}x the level learned at rest; the CUSUM of the per-block "
                 f"variance test passed {h} nats.",
        "spikes": f"{who}: isolated outliers came at {v:.2g} % of samples, more than a healthy gyro's; the CUSUM "
                  f"of the outlier rate passed {h} nats.",
        "stuck": f"{who}: its readings stopped changing (frozen on one or two codes, or identical samples) while "
                 "the vehicle still vibrated or the noise was expected to move them.",
        "dead": f"{who}: it read exactly 0 in every sample ({detail or 'dead or below resolution'}).",
        "bias_jump": f"{who}: the mean of still blocks stepped by {v:+.2f} deg/s from its reference; the step "
                     f"CUSUM passed {h} nats.",
        "bias_drift": f"{who}: the still-block mean moved {v:+.2f} deg/s from its reference like a ramp, beyond "
                      f"the {h} deg/s tolerance.",
        "saturation": f"{who}: the rate sat at {v:.3g} rad/s, the sensor's range limit or the same flat plateau "
                      "in several blocks.",
        "rate": f"{who}: the sample timing went off ({detail or f'rate {v:.0f} Hz'}) for {h} blocks in a row.",
        "disagree": f"{who}: it departed from {detail or 'another IMU'} by more than their mounting and noise "
                    f"explain; the residual's CUSUM passed {h} nats.",
        "allan": f"{who}: the online Allan estimate rose above its baseline ({detail}); the lower 3-sigma bound "
                 f"of the ratio stayed above {h}x for several checks in a row.",
        "resolution": f"{who}: the smallest step between readings grew to {v:.0f}x the learned LSB for {h} "
                      "blocks in a row.",
    }
    return words.get(kind, f"{who}: {kind}.")
