"""Still bias against IMU temperature: a warm-up the temperature explains is not a fault, a drift at a steady
temperature still is (companion.health.bias_temperature through the bias detectors of companion.health.monitor).

Simulated still blocks with known parameters: white noise of 4 LSB at 1 mrad/s, a Gauss-Markov bias wander
(0.017 deg/s, 60 s), an exponential warm-up of 24 K (tau 150 s) and a bias-temperature slope of
0.045-0.07 deg/s/K per axis (1.1-1.7 deg/s over the warm-up: above the 1 deg/s floors).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.health.block_stats import block_stats
from companion.health.hold import FAULT
from companion.health.evidence_rules import FaultLimits
from companion.health.monitor import ImuFaults
from companion.health.bias_temperature import ThermalBias

DEG = math.pi / 180.0
FS = 25
LSB = 1e-3


def _slopes(seed):
    rng = np.random.default_rng(100 + seed)
    return rng.choice([-1.0, 1.0], 3) * rng.uniform(0.045, 0.07, 3)  # deg/s/K


def _faults(seed, slope_dps_k, with_temp=True, ramp=None, dur=1200, rise=24.0, tau=150.0, first=False):
    """Bias alarms (t, kind, axis) of one simulated still IMU (``first``: stop at the first one)."""
    rng = np.random.default_rng(seed)
    f = ImuFaults(0, limits=FaultLimits())
    slopes = np.asarray(slope_dps_k) * DEG
    bias0 = rng.normal(0.0, 0.5 * DEG, 3)
    a = math.exp(-1.0 / 60.0)
    gm = np.zeros(3)
    out = []
    for k in range(dur):
        t = k + np.arange(FS) / FS
        temp = 25.0 + rise * (1.0 - np.exp(-t / tau))
        gm = gm * a + rng.normal(0.0, 3e-4 * math.sqrt(1.0 - a * a), 3)
        b = bias0 + gm + slopes[None, :] * (temp[:, None] - 25.0)
        if ramp is not None:
            ax, t_r, rate = ramp
            b[:, ax] += rate * np.maximum(0.0, t - t_r)
        y = np.round((b + rng.normal(0.0, 4 * LSB, (FS, 3))) / LSB) * LSB
        st = block_stats(y, f.dd_scale_ref())
        st.temperature = float(temp.mean()) if with_temp else math.nan
        for e in f.on_block(st, t, True) + f.on_quiet(st, {}):
            if e.state == FAULT and e.kind in ("bias_jump", "bias_drift"):
                out.append((float(t[-1]), e.kind, e.axis))
        if first and out:
            break
    return out


@pytest.mark.parametrize("seed", range(3))
def test_warm_up_explained_by_temperature_is_not_a_fault(seed):
    s = _slopes(seed)
    assert _faults(seed, s) == []
    # the same data without the temperature: the warm-up is taken for a drift (the test can fail)
    assert any(kind == "bias_drift" for _, kind, _ in _faults(seed, s, with_temp=False, first=True))


@pytest.mark.parametrize("seed", range(3))
def test_drift_at_a_steady_temperature_is_found(seed):
    # 1e-4 rad/s per s (0.0057 deg/s per s) from 900 s, when the warm-up is over (6 tau): 1 deg/s at 1075 s
    ax = seed % 3
    found = _faults(seed, _slopes(seed), ramp=(ax, 900.0, 1e-4), dur=1400, first=True)
    assert found, "drift missed"
    t, kind, axis = found[0]
    assert axis == ("gx", "gy", "gz")[ax] and 900.0 < t < 1400.0, found


def test_slope_learned_from_temperature_changes_only():
    th = ThermalBias(0.1 * DEG)
    th.add_reference(30.0)
    rng = np.random.default_rng(1)
    s_true = 0.03 * DEG
    for _ in range(200):  # pairs 1-4 K apart with 0.02 deg/s of noise on each difference
        dT = rng.uniform(1.0, 4.0)
        th.add_pair(s_true * dT + rng.normal(0.0, 0.02 * DEG), dT)
    for _ in range(500):  # a drift at a steady temperature: 0.3 deg/s per pair, dT below MIN_DT
        th.add_pair(0.3 * DEG, rng.uniform(-0.3, 0.3))
    assert th.slope == pytest.approx(s_true, rel=0.05)
    assert th.correction(40.0) == pytest.approx(10.0 * th.slope)
    assert th.correction(math.nan) == 0.0
    th.add_pair(100.0 * DEG * 10.0, 10.0)  # an absurd slope is clipped at s_max
    assert abs(th.slope) <= 0.1 * DEG + 1e-15


def _warm_log(tmp_path, kind, with_temp=True):
    """160 s of a still IMU at 50 Hz warming linearly 30 -> 46 degC, gx bias 0.05 deg/s/K, 2 mrad/s noise."""
    from companion.mavlink.tlog_writer import write_imu_tlog
    from companion.sim.dataflash_writer import write_imu_log

    rng = np.random.default_rng(4)
    t = np.arange(0.0, 160.0, 0.02) + 1.0
    temp = 30.0 + 0.1 * (t - t[0])
    gyro = rng.normal(0.0, 2e-3, (t.size, 3))
    gyro[:, 0] += 0.05 * DEG * (temp - 30.0)
    accel = np.tile([0.0, 0.0, -9.80665], (t.size, 1)) + rng.normal(0.0, 0.02, (t.size, 3))
    if kind == "tlog":
        path = tmp_path / "warm.tlog"
        write_imu_tlog(path, t, gyro, accel, temperature=temp if with_temp else None)
    else:
        path = tmp_path / "warm.bin"
        write_imu_log(path, t, gyro, accel, temperature=temp[None] if with_temp else 40.0)
    return path


@pytest.mark.parametrize("kind", ["tlog", "bin"])
def test_replay_carries_the_temperature_to_the_bias_model(tmp_path, kind):
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline, PipelineConfig
    from companion.service.replay import replay_log, replay_tlog
    from tests.support.sinks import RecordingSink

    def slope(path):
        # the Allan report is not what this checks: none before 1e9 s of still data (fast)
        p = Pipeline(PipelineConfig(min_report_s=1e9), Reporter(RecordingSink(), 1.0))
        (replay_tlog if kind == "tlog" else replay_log)(path, p)
        th = p.channels[0].faults.axes["gx"].bias.thermal
        return th, p

    th, p = slope(_warm_log(tmp_path, kind))
    assert 30.0 < th.t0 < 46.0 and th.pairs > 40
    assert th.slope / DEG == pytest.approx(0.05, rel=0.1)  # the warm-up's slope, learned
    assert not [x for _, x in p.transitions if "bias" in x]  # 0.8 deg/s over the warm-up: no alarm
    th, p = slope(_warm_log(tmp_path, kind, with_temp=False))
    assert th.slope == 0.0  # a constant temperature (bin) or none (tlog) explains nothing
