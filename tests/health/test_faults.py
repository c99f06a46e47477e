"""Fault detectors against simulated truth over many seeds (companion/health: stuck, noise, bias, spikes,
saturation, timing, disagreement), each fed block statistics exactly as the pipeline does."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.health.bias import BiasDetector
from companion.health.disagreement import PairDisagreement
from companion.health.axis_ref import AxisRef
from companion.health.block_stats import block_stats
from companion.health.faults import AXES, FaultEvent, Observation
from companion.health.hold import FAULT, OK
from companion.health.noise import NoiseDetector
from companion.health.saturation import SaturationDetector
from companion.health.spikes import SpikeDetector
from companion.health.stuck import StuckDetector
from companion.health.timing_faults import TimingDetector

FS = 100
LSB = 1e-3
DEG = math.pi / 180


def seeds(default: int, soak: int):
    """Parametrize ``seeds``: range(default) in the README's command, range(soak) (the same assertions over
    every seed) as a soak check (python -m benchmarks.soak_checks)."""
    return pytest.mark.parametrize("seeds", [range(default), pytest.param(range(soak), marks=pytest.mark.soak)],
                                   ids=[f"{default}seeds", f"{soak}seeds"])


def rounded_noise(rng, n, sigma, mean=0.0):
    return np.round((mean + rng.normal(0.0, sigma, (n, 3))) / LSB) * LSB


def learn_ref(rng, sigma, blocks=30, mean=0.0):
    refs = [AxisRef() for _ in range(3)]
    for _ in range(blocks):
        st = block_stats(rounded_noise(rng, FS, sigma, mean))
        for j, r in enumerate(refs):
            r.add(float(st.v2[j]), float(st.m2[j]), float(st.mean[j]), int(st.spikes[j]), st.n, blocks)
    assert all(r.ready for r in refs)
    return refs


def at(st, j, ref=None, **kw):
    """The observation of axis j of a block, as monitor.ImuFaults hands it to a detector."""
    return Observation(0, st, axis=AXES[j], ref=ref, **kw)


def scale_of(refs):
    return np.array([math.sqrt(6 * r.sigma2) for r in refs])


def test_block_stats_white_variance_ignores_smooth_motion_and_spikes():
    rng = np.random.default_rng(0)
    v = []
    for _ in range(200):
        t = np.arange(FS) / FS
        y = rng.normal(0, 0.01, (FS, 3)) + 0.5 * np.sin(2 * np.pi * 0.3 * t + rng.uniform(0, 6))[:, None]
        y[50, 0] += 0.3  # one spike on x
        st = block_stats(y)
        v.append(st.v2)
        assert st.spikes[0] == 1 and st.spikes[1] == 0
    v = np.array(v)
    # mean of 200 blocks: relative std sqrt(2 / (200 * 50)) = 1.4 %; 5 sigma
    assert np.mean(v) == pytest.approx(1e-4, rel=0.07)


def test_one_code_flips_of_a_sub_lsb_gyro_are_not_spikes_and_a_real_spike_still_is():
    # int16 mrad/s: a gyro of 0.2-0.4 LSB of noise whose bias sits near a code boundary flips to the next code
    # and back at random (a second difference of 2 LSB among zeros); no such flip is a spike, a 10 LSB one is
    lsb = 1e-3
    for seed in range(6):
        rng = np.random.default_rng(seed)
        sigma = rng.uniform(0.2, 0.4) * lsb
        bias = (rng.integers(-3, 3) + 0.5 - rng.uniform(0.1, 0.4)) * lsb  # near a boundary between two codes
        # the reference scale of the second differences as learned while the gyro sat on one code: ~0
        ref = np.full(3, 1e-12)
        flips = spikes = 0
        for _ in range(60):
            y = np.round((bias + rng.normal(0, sigma, (FS, 3))) / lsb) * lsb
            st = block_stats(y, ref)
            flips += int(np.count_nonzero(np.diff(y, axis=0)))
            spikes += int(st.spikes.sum())
            y[25, 1] += 10 * lsb
            assert block_stats(y, ref).spikes[1] >= 1
        assert flips > 100 and spikes == 0, (seed, flips, spikes)


@seeds(4, 10)
@pytest.mark.parametrize("sigma_lsb", [0.7, 3.0])
def test_stuck_caught_fast_with_or_without_dither_and_never_on_healthy_rounded_noise(sigma_lsb, seeds):
    sigma = sigma_lsb * LSB
    flagged_healthy, delays = 0, []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        refs = learn_ref(rng, sigma)
        dets = [StuckDetector() for _ in range(3)]
        for _ in range(600):  # 10 healthy minutes per seed and axis
            st = block_stats(rounded_noise(rng, FS, sigma), scale_of(refs))
            for j, d in enumerate(dets):
                flagged_healthy += len(d.update(at(st, j, refs[j])))
        frozen = rng.normal(0, sigma, 3)
        dither = rng.uniform(0, 0.3) * sigma * (seed % 2)  # half exactly frozen, half with a small dither
        for k in range(20):
            y = frozen + rng.normal(0, dither, (FS, 3)) if dither else np.tile(frozen, (FS, 1))
            st = block_stats(y, scale_of(refs))
            if dets[0].update(at(st, 0, refs[0])):
                delays.append(k + 1)
                break
    assert flagged_healthy == 0
    assert len(delays) == len(seeds) and max(delays) <= 3


def test_stuck_without_reference_uses_equal_values():
    d = StuckDetector()
    ref = AxisRef()
    frozen = block_stats(np.full((100, 3), 0.002))
    moving = block_stats(np.round(np.random.default_rng(0).normal(0, 0.01, (100, 3)) / LSB) * LSB)
    assert not d.update(at(frozen, 0, ref))
    ev = d.update(at(frozen, 0, ref))
    assert d.state == FAULT and [(e.kind, e.state, e.critical) for e in ev] == [("stuck", FAULT, True)]
    assert d.update(at(moving, 0, ref)) and d.state == OK


@seeds(4, 12)
def test_noise_rise_detected_near_its_information_limit_and_not_on_healthy(seeds):
    false, delays = 0, {2.0: [], 1.5: [], 1.3: []}
    for seed in seeds:
        rng = np.random.default_rng(100 + seed)
        sigma = rng.uniform(1.0, 4.0) * LSB
        refs = learn_ref(rng, sigma)
        d = NoiseDetector()
        for _ in range(600):
            st = block_stats(rounded_noise(rng, FS, sigma), scale_of(refs))
            false += len(d.update(at(st, 0, refs[0])))
        for f in delays:
            d = NoiseDetector()
            for k in range(300):
                st = block_stats(rounded_noise(rng, FS, f * sigma), scale_of(refs))
                if d.update(at(st, 0, refs[0])):
                    delays[f].append(k + 1)
                    assert d.value == pytest.approx(f, rel=0.35)
                    break
    assert false == 0
    n = len(seeds)
    assert len(delays[2.0]) == n and max(delays[2.0]) <= 5  # limit h / KL = 20 / (50 * 0.5 * (4 - 1 - ln 4)) = 0.5 blocks
    assert len(delays[1.5]) == n and max(delays[1.5]) <= 15
    assert len(delays[1.3]) == n and max(delays[1.3]) <= 60


@seeds(4, 8)  # even seeds warm up downwards, odd ones upwards
def test_bias_step_is_a_jump_warm_up_is_nothing_and_a_ramp_is_a_drift(seeds):
    sigma = 2e-3
    jumps, quiet = [], 0
    for seed in seeds:
        rng = np.random.default_rng(200 + seed)
        refs = learn_ref(rng, sigma)
        d = BiasDetector()
        warm = 0.1 * DEG * (1 - np.exp(-np.arange(1200) / 200.0)) * (1 if seed % 2 else -1)
        for k in range(1200):  # 20 min of cold-start warm-up: 0.1 deg/s exponential, tau 200 s
            st = block_stats(rounded_noise(rng, FS, sigma, warm[k]), scale_of(refs))
            quiet += len(d.update(at(st, 0, refs[0])))
        step = rng.uniform(1.0, 2.0) * DEG * (1 if seed % 2 else -1)  # at or above the 1 deg/s floor
        for k in range(30):
            st = block_stats(rounded_noise(rng, FS, sigma, warm[-1] + step), scale_of(refs))
            if "bias_jump" in [e.kind for e in d.update(at(st, 0, refs[0]))]:
                jumps.append((k + 1, d.value, step / DEG))
                break
    assert quiet == 0
    # evidence capped at h / 5 per block: one knock is not a jump, a step is named within 5-6 blocks
    assert len(jumps) == len(seeds) and max(k for k, _, _ in jumps) <= 6
    for _, v, s in jumps:
        assert v == pytest.approx(s, abs=0.15)
    # a step below the floor (0.6 deg/s, clearly significant against this noise) is wander, not a fault
    rng = np.random.default_rng(8)
    refs = learn_ref(rng, sigma)
    d = BiasDetector()
    small = []
    for k in range(300):
        st = block_stats(rounded_noise(rng, FS, sigma, 0.6 * DEG if k >= 100 else 0.0), scale_of(refs))
        small += d.update(at(st, 0, refs[0]))
    assert small == []
    # a ramp: named a drift
    rng = np.random.default_rng(9)
    refs = learn_ref(rng, sigma)
    d = BiasDetector()
    kinds = []
    for k in range(400):
        st = block_stats(rounded_noise(rng, FS, sigma, 1e-4 * max(k - 60, 0)), scale_of(refs))
        kinds += [e.kind for e in d.update(at(st, 0, refs[0]))]
        if kinds:
            break
    assert kinds == ["bias_drift"] and d.drift_state == FAULT


@seeds(4, 10)
def test_spikes_named_as_spikes_not_noise(seeds):
    delays, noise_flags, false = [], 0, 0
    for seed in seeds:
        rng = np.random.default_rng(300 + seed)
        sigma = rng.uniform(0.7, 4.0) * LSB
        refs = learn_ref(rng, sigma)
        sp, nd = SpikeDetector(), NoiseDetector()
        for _ in range(900):
            st = block_stats(rounded_noise(rng, FS, sigma), scale_of(refs))
            false += len(sp.update(at(st, 0, refs[0])))
        frac = rng.uniform(0.002, 0.01)
        for k in range(60):
            y = rounded_noise(rng, FS, sigma)
            hit = rng.random(FS) < frac
            y[hit, 0] += 0.3 * rng.choice([-1, 1], hit.sum())
            st = block_stats(y, scale_of(refs))
            noise_flags += len(nd.update(at(st, 0, refs[0])))
            if sp.update(at(st, 0, refs[0])):
                delays.append(k + 1)
                break
    assert false == 0 and noise_flags == 0
    assert len(delays) == len(seeds) and max(delays) <= 30


def test_saturation_at_a_clip_level_and_at_the_range_limit():
    rng = np.random.default_rng(4)
    refs = learn_ref(rng, 2e-3)
    d = SaturationDetector(abs_limit=32.767)
    changed = []
    for k in range(20):  # manoeuvres reaching 1.2 rad/s, clipped at 0.8
        t = (k * FS + np.arange(FS)) / FS
        y = rounded_noise(rng, FS, 2e-3) + 1.2 * np.sin(2 * np.pi * 0.7 * t)[:, None]
        y[:, 0] = np.clip(y[:, 0], -0.8, 0.8)
        st = block_stats(y, scale_of(refs))
        changed.append(bool(d.update(at(st, 0, refs[0]))))
    assert any(changed) and d.state == FAULT and d.value == pytest.approx(0.8)
    healthy = SaturationDetector(abs_limit=32.767)  # the same motion unclipped (axis y): never
    for k in range(200):
        t = (k * FS + np.arange(FS)) / FS
        y = rounded_noise(rng, FS, 2e-3) + 1.2 * np.sin(2 * np.pi * 0.7 * t)[:, None]
        st = block_stats(y, scale_of(refs))
        assert not healthy.update(at(st, 1, refs[1]))
    hard = SaturationDetector(abs_limit=32.767)
    assert hard.update(at(block_stats(np.array([[32.767, 0, 0]] + [[0.0, 0, 0]] * 9)), 0, refs[0]))


def test_timing_rate_drop_and_jitter():
    d = TimingDetector()
    rng = np.random.default_rng(1)
    t0 = 0.0
    for k in range(30):
        t = t0 + np.arange(100) / 100.0
        assert not d.update(Observation(t=t))
        t0 = t[-1] + 0.01
    for k in range(10):  # 40 % of the messages lost on the link: not a sensor fault
        t = t0 + np.flatnonzero(rng.random(100) > 0.4) / 100.0
        assert not d.update(Observation(t=t))
        t0 += 1.0
    for k in range(5):  # the sensor now samples at 50 Hz
        t = t0 + np.arange(50) / 50.0
        ch = d.update(Observation(t=t))
        t0 = t[-1] + 0.02
    assert ch and d.state == FAULT and "50 Hz" in d.detail
    assert [(e.kind, e.axis, e.state) for e in ch] == [("rate", "", FAULT)]
    d2 = TimingDetector()
    for k in range(10):
        d2.update(Observation(t=np.arange(100) / 100.0 + k))
    for k in range(5):
        t = np.cumsum(rng.uniform(0.002, 0.018, 100)) + 20 + k
        ch = d2.update(Observation(t=t))
    assert ch and "irregular" in d2.detail



def test_timing_jitter_needs_ten_intervals_a_block():
    """A 4 Hz telemetry stream (5 samples a block) whose send times scatter by +-30 %: its jitter is not judged
    (a few intervals' rms passes 20 % by chance, and the times are the autopilot's choice of sample). At 100 Hz the same relative scatter is still called irregular."""
    from companion.health.timing_faults import JITTER_MIN_INTERVALS

    def blocks(rng, rate, scatter, n, t0=0.0):
        for _ in range(n):
            t = t0 + np.concatenate([[0.0], np.cumsum(1.0 + rng.uniform(-scatter, scatter, int(rate)))]) / rate
            t0 = t[-1] + 1.0 / rate
            yield t

    assert JITTER_MIN_INTERVALS > 5
    for seed in range(3):
        d = TimingDetector()
        events = [ev for t in blocks(np.random.default_rng(seed), 4.0, 0.3, 3000) for ev in d.update(Observation(t=t))]
        assert events == [], [e.text() for e in events]
    d = TimingDetector()
    events = [ev for t in blocks(np.random.default_rng(3), 100.0, 0.9, 40) for ev in d.update(Observation(t=t))]
    assert events and "irregular" in events[0].detail

def rotation(rng, n, t0):
    t = (t0 + np.arange(n)) / FS
    w = np.column_stack([1.2 * np.sin(2 * np.pi * 0.4 * t + 1), 0.9 * np.sin(2 * np.pi * 0.7 * t),
                         0.6 * np.sin(2 * np.pi * 0.2 * t + 2)])
    return w + 0.02 * rng.normal(size=(n, 3))  # shared vibration


def test_disagreement_tolerates_scale_and_misalignment_in_fast_rotation_and_catches_a_bias():
    delays, false = [], 0
    for seed in range(6):
        rng = np.random.default_rng(400 + seed)
        sigma = rng.uniform(1, 4) * LSB
        s = np.eye(3) + np.diag(rng.uniform(-0.01, 0.01, 3))
        ang = rng.uniform(0, 0.5) * DEG
        ax = rng.normal(size=3)
        ax /= np.linalg.norm(ax)
        K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
        C = s @ (np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K)
        pair = PairDisagreement(0, 1)
        b0, b1 = rng.normal(0, 0.5 * DEG, 3), rng.normal(0, 0.5 * DEG, 3)
        for k in range(600):
            w = rotation(rng, FS, k * FS)
            y0 = w + b0 + rng.normal(0, sigma, (FS, 3))
            y1 = w @ C.T + b1 + rng.normal(0, sigma, (FS, 3))
            nv = sigma ** 2 + LSB ** 2 / 12
            false += len(pair.update(Observation(0, y=np.round(y0 / LSB) * LSB, other=np.round(y1 / LSB) * LSB,
                                                 other_imu=1, noise_var=2 * nv, noise_other=nv)))
        # above the floor: 5 deg/s + 10 % of the rms rate (0.42 rad/s on Z here: 7.4 deg/s in all)
        step = 10.0 * DEG * (1 if seed % 2 else -1)
        for k in range(20):
            w = rotation(rng, FS, (600 + k) * FS)
            y0 = w + b0 + rng.normal(0, sigma, (FS, 3))
            y1 = w @ C.T + b1 + rng.normal(0, sigma, (FS, 3))
            y1[:, 2] += step
            ev = pair.update(Observation(0, y=y0, other=y1, other_imu=1, noise_var=2 * sigma ** 2, noise_other=sigma ** 2))
            if "gz" in [e.axis for e in ev]:
                assert ev[-1].detail == "IMU1" and ev[-1].state == FAULT
                delays.append(k + 1)
                break
    assert false == 0
    assert len(delays) == 6 and max(delays) <= 10


def test_event_texts_fit_statustext():
    texts = [FaultEvent(0, "gx", "stuck", FAULT).text(), FaultEvent(0, "gx", "noise", FAULT, 6.12).text(),
             FaultEvent(0, "gx", "bias_jump", FAULT, 1.2).text(), FaultEvent(0, "gx", "spikes", FAULT, 0.4).text(),
             FaultEvent(1, "gx", "disagree", FAULT, detail="IMU0/IMU2").text(),
             FaultEvent(0, "gz", "bias_drift", FAULT, -0.35).text(), FaultEvent(0, "gx", "stuck", OK).text()]
    assert texts == ["IMU0 gyro X stuck", "IMU0 gyro X noise 6.1x baseline", "IMU0 gyro X bias jump +1.20 deg/s",
                     "IMU0 gyro X spikes 0.4 %", "IMU1 gyro X disagrees with IMU0/IMU2",
                     "IMU0 gyro Z bias drift -0.35 deg/s", "IMU0 gyro X stuck cleared"]
    assert all(len(t) <= 50 for t in texts)


def test_resolution_loss_and_float_data_untested():
    from companion.health.resolution import ResolutionDetector

    rng = np.random.default_rng(5)
    d = ResolutionDetector()
    for _ in range(300):
        st = block_stats(rounded_noise(rng, FS, 3 * LSB))
        assert not d.update(at(st, 0))
    assert d.lsb == pytest.approx(LSB)
    flagged = False
    for k in range(12):  # the output now moves in 4 mrad/s steps
        y = np.round(rng.normal(0, 8 * LSB, (FS, 3)) / (4 * LSB)) * 4 * LSB
        st = block_stats(y)
        flagged |= bool(d.update(at(st, 0)))
    assert flagged and d.value == pytest.approx(4.0)
    f = ResolutionDetector()  # float data: no LSB, never tested
    for _ in range(50):
        st = block_stats(rng.normal(0, 1e-3, (FS, 3)))
        assert not f.update(at(st, 0))
    assert f.lsb == 0.0


@pytest.mark.parametrize("rate", [400.0, 300.0, 150.0])
def test_millisecond_stamps_at_rates_off_the_ms_grid_are_regular(rate):
    """SCALED_IMU2/3 carry time_boot_ms: at 400 Hz the stamps step 2, 3, 2, 3 ms. That is the stamp's
    resolution, not a timing fault; at 150 Hz (6.7 ms) a jitter of 35 % of the period still is one."""
    d = TimingDetector(stamp_res=1e-3)
    rng = np.random.default_rng(2)
    n = int(rate)
    for k in range(40):
        t = np.floor((10.0 + k + np.arange(n) / rate + rng.uniform(0, 1e-4, n)) * 1e3) / 1e3
        assert not d.update(Observation(t=t)), (k, d.detail)
    assert d.ref_rate == pytest.approx(rate, rel=0.01)
    if rate > 200.0:
        return  # a 1-ms stamp cannot show jitter of a fraction of a 2.5-3.3 ms period
    bad = None
    for k in range(40, 46):
        ideal = 10.0 + k + np.arange(n) / rate
        t = np.floor((ideal + rng.normal(0, 0.35 / rate, n)) * 1e3) / 1e3
        t = np.maximum.accumulate(t + 1e-9 * np.arange(n))
        bad = d.update(Observation(t=t)) or bad
    assert bad and "irregular" in d.detail


def test_two_faults_at_once_are_both_in_the_mask_and_the_code_is_the_most_severe():
    from companion.health.faults import KIND_CODE, fault_mask, mask_kinds
    from companion.health.monitor import ImuFaults
    from companion.mavlink.reporter import Reporter

    rng = np.random.default_rng(7)
    sigma = 2 * LSB
    f = ImuFaults(0, ref_blocks=30)
    for _ in range(30):  # learn the still references
        st = block_stats(rounded_noise(rng, FS, sigma))
        assert f.on_block(st, np.arange(FS) / FS, True) == [] and f.on_quiet(st) == []
    assert f.mask() == 0 and f.code() == 0
    events = []
    for k in range(5):  # x frozen and y 5x noisier, in the same blocks
        y = rounded_noise(rng, FS, sigma)
        y[:, 0] = 0.004
        y[:, 1] = np.round(rng.normal(0, 5 * sigma, FS) / LSB) * LSB
        st = block_stats(y, f.dd_scale_ref())
        t = 30 + k + np.arange(FS) / FS
        events += f.on_block(st, t, True) + f.on_quiet(st)
    assert {(e.kind, e.axis) for e in events} == {("stuck", "gx"), ("noise", "gy")}
    assert f.code() == KIND_CODE["stuck"]  # the most severe
    assert f.mask() == (1 << KIND_CODE["stuck"]) | (1 << KIND_CODE["noise"]) == fault_mask(["noise", "stuck"])
    assert mask_kinds(f.mask()) == ["stuck", "noise"]

    class Sink:
        values = {}

        def send_named_value_float(self, ms, name, value):
            self.values[name] = value

    rep = Reporter(Sink(), 1.0)
    rep.set_fault(0, f.code(), f.mask())
    rep.tick(0.0)
    rep.tick(1.0)
    assert Sink.values == {"IMU0G_FLT": 1.0, "IMU0G_FLM": 6.0}
