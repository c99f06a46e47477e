"""A gyro reading exactly 0 is named for what it is, a frozen value is stuck, a frozen value flipping between two
codes near their boundary is still stuck, a healthy gyro at 0.5 LSB of noise is never stuck.

On RAW_IMU / SCALED_IMU* (int16 mrad/s) a gyro quieter than 1 mrad/s reads exactly 0 at rest (ArduPilot
SITL): "dead or below resolution" (WARNING); in motion (accelerometer) still 0: dead (CRITICAL); a float
message never reads exactly 0.0 from a live gyro: dead. Data: arrays with known truth fed to the pipeline
(the same block path as `companion run`) and the realistic simulator's copter preset (50 Hz, 20 Hz low-pass,
0.47 LSB of noise from second differences after the 1 mrad/s rounding)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.health.axis_ref import AxisRef
from companion.health.block_stats import block_stats
from companion.health.faults import AXES, KIND_CODE, Observation
from companion.health.hold import FAULT
from companion.health.code_spread import codes_glr, two_code_llr, two_code_outside
from companion.health.stuck import StuckDetector
from companion.mavlink.reporter import MAV_SEVERITY_CRITICAL, MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING, Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from tests.support.sinks import RecordingSink

LSB = 1e-3
FS = 50.0
G = np.array([0.0, 0.0, -9.80665])


def feed(message, segments, seed=0):
    """``segments``: (seconds, gyro std rad/s, accel std m/s^2) in turn; gyro rounded to 1 mrad/s on int16
    messages (the accelerometer's std is what the motion gate sees)."""
    rng = np.random.default_rng(seed)
    sink = RecordingSink()
    p = Pipeline(PipelineConfig(baseline_s=600.0), Reporter(sink, 1.0))
    key = StreamKey(1, 1, message, 0)
    t0 = 1.0
    for secs, g_std, a_std in segments:
        n = int(secs * FS)
        t = t0 + np.arange(n) / FS
        g = rng.normal(0.0, g_std, (n, 3)) if g_std else np.zeros((n, 3))
        if message != "HIGHRES_IMU":
            g = np.round(g / LSB) * LSB
        a = G + rng.normal(0.0, a_std, (n, 3))
        p.on_samples(key, t, g, a)
        t0 = t[-1] + 1.0 / FS
    return p, [(s, x) for s, x in sink.texts if "learned" not in x], sink


def test_sub_lsb_raw_imu_reads_zero_named_dead_or_below_resolution_not_stuck():
    # 0.1 LSB of noise: every RAW_IMU sample is exactly 0
    p, texts, sink = feed("RAW_IMU", [(20.0, 0.1 * LSB, 0.02)])
    assert texts == [(MAV_SEVERITY_WARNING, f"IMU0 gyro {a} reads 0: dead or below resolution") for a in "XYZ"]
    assert all(len(x) <= 50 for _, x in texts)
    assert sink.values["IMU0G_FLT"] == KIND_CODE["dead"]
    assert int(sink.values["IMU0G_FLM"]) == 1 << KIND_CODE["dead"]
    ch = p.channels[0]
    assert p.fault_texts(ch)[0] == "IMU0 gyro X reads 0: dead or below resolution"


def test_zero_gyro_while_the_vehicle_moves_is_dead_and_a_moving_live_gyro_clears_it():
    # at rest: dead or below resolution; moving (accel) with the gyro still 0: dead, critical
    _, texts, _ = feed("RAW_IMU", [(15.0, 0.0, 0.02), (8.0, 0.0, 1.5)])
    assert (MAV_SEVERITY_CRITICAL, "IMU0 gyro X reads 0 while moving: dead") in texts
    # SITL: the gyro moves with the vehicle (alive), then reads 0 at rest again: cleared, and not named
    # again at the next rest (a landing) before a minute of zeros
    _, texts, _ = feed("RAW_IMU", [(15.0, 0.0, 0.02), (8.0, 0.05, 1.5), (40.0, 0.0, 0.02)])
    assert texts[3:] == [(MAV_SEVERITY_NOTICE, f"IMU0 gyro {a} zero reading cleared") for a in "XYZ"]


def test_float_message_zero_is_dead_and_a_frozen_nonzero_value_is_stuck():
    _, texts, _ = feed("HIGHRES_IMU", [(10.0, 0.0, 0.02)])
    assert texts == [(MAV_SEVERITY_CRITICAL, f"IMU0 gyro {a} reads exactly 0: dead") for a in "XYZ"]
    d = StuckDetector(LSB)
    frozen = block_stats(np.full((50, 3), 3 * LSB))
    ev = d.update(Observation(0, frozen, None, True, "gx", AxisRef())) + \
        d.update(Observation(0, frozen, None, True, "gx", AxisRef()))
    assert [(e.kind, e.state, e.critical, e.text()) for e in ev] == [("stuck", FAULT, True, "IMU0 gyro X stuck")]


def copter_blocks(seed, seconds, fault=None, on_boundary=False):
    """The realistic copter's IMU0 at rest in 1 s blocks, rounded to 1 mrad/s; ``on_boundary``: every axis
    shifted before the rounding so that its mean level sits on a boundary between two codes."""
    from companion.sim.preset import load_preset
    from companion.sim.vehicle import Schedule, VehicleSimulator

    P = load_preset("copter")
    sim = VehicleSimulator(P["model"], imus=1, seed=seed, rate_hz=P["vehicle"]["rate_hz"], realism=P["realism"],
                           fault=fault, schedule=Schedule())
    n = int(round(sim.rate_hz))
    g = sim.run(seconds).gyro[0] / LSB
    if on_boundary:
        g += np.floor(g.mean(axis=0)) + 0.5 - g.mean(axis=0)
    g = np.round(g) * LSB
    return [g[b * n:(b + 1) * n] for b in range(g.shape[0] // n)]


def detect(blocks, ref_blocks=30):
    """The stuck detectors of the three axes over the blocks, the references learned from the first
    ``ref_blocks`` as the pipeline does (block statistics with the reference's spike scale); the events."""
    refs, dets, events = [AxisRef() for _ in AXES], [StuckDetector(LSB) for _ in AXES], []
    for b, y in enumerate(blocks):
        scale = np.array([math.sqrt(6 * r.sigma2) for r in refs]) if all(r.ready for r in refs) else None
        st = block_stats(y, scale)
        for j, ax in enumerate(AXES):
            events += [(b, e) for e in dets[j].update(Observation(0, st, None, True, ax, refs[j], y=y))]
            if not refs[j].ready:
                refs[j].add(float(st.v2[j]), float(st.m2[j]), float(st.mean[j]), int(st.spikes[j]), st.n, ref_blocks)
    return events


def test_two_code_evidence_a_flipping_frozen_value_against_healthy_noise():
    rng = np.random.default_rng(3)
    s = 0.36
    q0 = math.erfc(1.0 / (s * math.sqrt(2.0)))  # healthy rate beyond two codes on a boundary: 2 Phi(-1/s)
    # a frozen value 0.02 LSB from a code boundary with a 0.08 LSB dither: two codes, flipping like noise
    frozen = (0.5 + 0.02) * LSB + rng.normal(0.0, 0.08 * LSB, 50)
    assert set(np.round(frozen / LSB)) == {0.0, 1.0}
    assert two_code_outside(frozen, LSB) == 0 and two_code_llr(0, 50, q0) == pytest.approx(0.25, abs=0.03)
    # healthy noise of that level anywhere on the grid: negative on average, most at a code's centre
    for level in (0.5, 0.3, 0.0):
        llr = [two_code_llr(two_code_outside(level * LSB + rng.normal(0.0, s * LSB, 50), LSB), 50, q0)
               for _ in range(400)]
        assert np.mean(llr) < -0.1
    assert two_code_outside(np.array([0.0, 1e-3, 2e-3, 1e-3]), LSB) == 1


def test_codes_evidence_reads_the_split_and_the_spread_at_the_best_healthy_level():
    s = 0.47
    q0 = math.erfc(1.0 / (s * math.sqrt(2.0)))  # 2 Phi(-1/s): healthy samples beyond two codes on a boundary
    # two codes in equal shares: a healthy level on the boundary, evidence ln((1 - q1) / (1 - q0)) per sample
    on = 50 * math.log((1 - q0 / 20) / (1 - q0))
    assert codes_glr(0, np.array([25.0, 25.0]), s, q0 / 20) == pytest.approx(on, rel=0.01)
    # a 23:77 split puts a healthy level 0.35 LSB off the boundary, where 8.6 % of the samples leave the two
    # codes: the same samples are worth about 2.5x as much
    off = codes_glr(0, np.array([11.5, 38.5]), s, q0 / 20)
    assert 2.0 < off / on < 3.0
    # one code: what a healthy level at the code's centre keeps in it, n ln(1 / P), P = erf(0.5 / (s sqrt 2))
    assert codes_glr(3, np.array([50.0]), s, q0 / 20) == pytest.approx(
        -50 * math.log(math.erf(0.5 / (s * 2 ** 0.5))), rel=0.01)
    # a sample beyond two codes costs about ln(q1 / q0) = -3 nats, wherever it lands
    assert codes_glr(0, np.array([25.0, 25.0, 1.0]), s, q0 / 20) < on - 2.5
    assert codes_glr(-20, np.r_[1.0, np.zeros(18), 25.0, 25.0], s, q0 / 20) < on - 2.5
    # a block in which motion starts: half of it on two codes, the rest spread over 25 (the healthy model at one
    # level fits none of it well, and that must not make it frozen)
    start = np.r_[np.full(12, 3), np.full(13, 4), np.round(np.linspace(-6.0, 19.0, 25))].astype(int)
    assert codes_glr(-6, np.bincount(start + 6).astype(float), s, q0 / 20) < -50
    # a gyro spread far beyond its learned noise (real logs: vibration, a noisier period) is no frozen value
    wide = np.random.default_rng(1).normal(0.0, 8.0, 50).round().astype(int)
    assert codes_glr(int(wide.min()), np.bincount(wide - wide.min()).astype(float), 4.0, 0.45 / 20) < -50
    # healthy noise anywhere on the grid: negative on average (runs of 200 samples)
    rng = np.random.default_rng(5)
    for level in (0.5, 0.3, 0.0):
        g = []
        for _ in range(200):
            c = np.round(level + rng.normal(0.0, s, 200)).astype(int)
            g.append(codes_glr(int(c.min()), np.bincount(c - c.min()).astype(float), s, q0 / 20))
        assert np.mean(g) < -5.0


def frozen_copter_delay(seed, dither_sigma, seconds):
    """The realistic copter at 0.47 LSB with a value frozen at 60 s with a dither of ``dither_sigma`` times
    the noise, on an axis drawn from the seed: (axis, codes after the fault, first stuck block, early events)."""
    from companion.sim.vehicle import Fault

    rng = np.random.default_rng(seed)
    ax = AXES[rng.integers(3)]
    blocks = copter_blocks(100 + seed, 60.0 + seconds + 2.0,
                           Fault("stuck", at=60.0, size=dither_sigma * 0.47e-3, axis=ax))
    codes = set(np.round(np.concatenate(blocks[61:])[:, AXES.index(ax)] / LSB).astype(int).tolist())
    events = detect(blocks)
    hits = [b for b, e in events if e.axis == ax and e.state == FAULT and e.kind == "stuck"]
    return ax, codes, (hits[0] if hits else None), [e for b, e in events if b < 59]


@pytest.mark.parametrize("seed", [0, 21, 41, 47])
def test_copter_gyro_frozen_between_two_codes_off_their_boundary_is_stuck_within_10_s(seed):
    # a 0.3 sigma dither (the bench's worst) 0.1-0.2 LSB from a boundary: the samples split 15:85 to 35:65
    # between two codes and never leave them; a healthy level giving that split would leave them 2-3x as
    # often as on the boundary (the split says where it would sit): about 3 nats a block, named in 5-9 s
    ax, codes, hit, early = frozen_copter_delay(seed, 0.3, 12.0)
    assert len(codes) == 2 and early == []
    assert hit is not None and 60 <= hit <= 70


@pytest.mark.parametrize("seed, within", [(9, 10), (15, 35), (31, 35)])
def test_dithered_frozen_copter_gyro_flipping_codes_is_stuck(seed, within):
    # a 0.17 sigma dither; seeds 15 and 31 freeze the value on a code boundary (41:59 and 59:41 between two
    # codes), where it flips about as often as the healthy gyro changes code: neither the variance nor the
    # repeated codes see it, only what a healthy gyro there would add beyond two codes (2 Phi(-1/s) at the
    # Sheppard-corrected s = 0.43 LSB: 2 % of its samples, about 0.9 equivalent nats a block against h = 20:
    # 22 blocks expected; named in 16-22 s)
    ax, codes, hit, early = frozen_copter_delay(seed, 0.17, within)
    assert early == []
    assert hit is not None and 59 <= hit <= 60 + within


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_healthy_copter_gyro_at_half_an_lsb_is_not_stuck(seed):
    events = detect(copter_blocks(seed, 300.0))
    assert events == []


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_healthy_copter_gyro_resting_on_code_boundaries_is_not_stuck(seed):
    # every axis shifted so that its level over the 5 minutes sits on a boundary between two codes, where a
    # healthy gyro leaves two codes least often and flips between them like a frozen value on the boundary
    blocks = copter_blocks(seed, 300.0, on_boundary=True)
    assert np.allclose(np.concatenate(blocks).mean(axis=0) / LSB % 1.0, 0.5, atol=0.1)
    assert detect(blocks) == []


def test_inspect_sentence_of_an_int16_stream_reading_zero_names_both_causes():
    from companion.health.dead import dead_gyro_text

    text = dead_gyro_text("RAW_IMU[0]", np.zeros((100, 3)), LSB)
    assert "gyro dead or below resolution: X, Y, Z exactly 0 in all 100 samples" in text
    assert "1 mrad/s = 0.0573 deg/s" in text and "HIGHRES_IMU" in text
    # a float stream (DataFlash, ULog, HIGHRES_IMU) reading exactly 0: dead, and a constant: frozen
    assert "gyro dead: X, Y, Z exactly 0" in dead_gyro_text("IMU[1]", np.zeros((100, 3)))
    assert "below resolution" not in dead_gyro_text("RAW_IMU[0]", np.full((100, 3), 2 * LSB), LSB)


def lowpassed_blocks(seed, seconds, frozen_from=None):
    """A gyro low-passed at 5 Hz and logged at 50 Hz like the rover's (2nd-order Butterworth on 1 kHz white noise,
    every 20th sample), 1.2 LSB of sample spread but 0.3 LSB from sample to sample, rounded to 1 mrad/s; from
    ``frozen_from`` s on axis X frozen exactly on the boundary between codes 0 and 1 with a 0.05 LSB dither."""
    from scipy.signal import butter, lfilter

    rng = np.random.default_rng(seed)
    b, a = butter(2, 5.0 / 500.0)
    n = int(seconds * FS)
    raw = lfilter(b, a, rng.normal(0.0, 1.0, (n * 20 + 2000, 3)), axis=0)[2000::20][:n]
    g = raw / raw.std(axis=0) * 1.2 * LSB + 0.3 * LSB
    if frozen_from is not None:
        k = int(frozen_from * FS)
        g[k:, 0] = 0.5 * LSB + rng.normal(0.0, 0.05 * LSB, n - k)
    g = np.round(g / LSB) * LSB
    m = int(FS)
    return [g[i * m:(i + 1) * m] for i in range(n // m)]


def test_lowpassed_gyro_frozen_between_two_codes_is_stuck_and_the_healthy_one_is_not():
    blocks = lowpassed_blocks(1, 60.0, frozen_from=40.0)
    assert {int(v) for v in np.round(np.concatenate(blocks[41:])[:, 0] / LSB)} == {0, 1}
    events = detect(blocks)
    hits = [b for b, e in events if e.axis == "gx" and e.state == FAULT and e.kind == "stuck"]
    assert hits and 40 <= hits[0] <= 52, events  # 20 s of healthy spread beyond two codes, then 1-12 s
    assert [e for b, e in events if b < 40] == []
    assert detect(lowpassed_blocks(2, 120.0)) == []


def test_level_jitter_learned_at_rest_matches_the_simulated_one():
    # still blocks whose level moves by a normal jitter of sd tau from block to block around a fixed level, with
    # 0.4 LSB of white noise on 50 rounded samples: the learned jitter is tau, what the samples' own noise
    # moves a block's mean (0.07 LSB here) taken out
    rng = np.random.default_rng(7)
    for tau in (0.0, 0.12):
        det = StuckDetector(LSB)
        det.lsb = LSB
        for _ in range(600):
            level = 0.3 + rng.normal(0.0, tau)
            det._learn_jitter(np.round(level + rng.normal(0.0, 0.4, 50)) * LSB)
        det._end_run(commit=True)
        assert det._jitter_lsb(1.0) == pytest.approx(tau, abs=0.03)


def test_a_frozen_split_holds_still_while_a_healthy_level_moves_and_its_expected_level_counts_at_most_a_cap():
    from companion.health import stuck

    s, q1 = 0.43, math.erfc(1.0 / (0.43 * math.sqrt(2.0))) / 20
    rng = np.random.default_rng(11)
    det = StuckDetector(LSB)
    # eight blocks of a value frozen 0.05 LSB off the boundary of codes 0 and 1 with a 0.12 LSB dither
    det.run = [(0, np.bincount(np.round(0.55 + rng.normal(0.0, 0.12, 50)).astype(int), minlength=2).astype(float),
                {}) for _ in range(8)]
    plain = det._best_window(s, q1)
    # a healthy level moving 0.08 LSB from block to block could not hold its split this still
    assert det._best_window(s, q1, tau=0.08) > plain + 2.0
    # an expected level far from any that fits: the healthy pays the cap, no more (a level may have stepped)
    far = det._best_window(s, q1, prior=(6.0, 0.1))
    assert far == pytest.approx(plain + stuck.PRIOR_CAP, abs=1e-6)
    # an expected level where the split puts a healthy one: nearly nothing
    assert det._best_window(s, q1, prior=(0.5, 0.3)) == pytest.approx(plain, abs=0.3)
    # healthy blocks whose level moves by that jitter around the boundary, judged with it: evidence for healthy on
    # average (about -1.7 nats for 8 blocks; the plain model gives -2.1 there: the best of the windows and
    # levels is no likelihood ratio, which is what the threshold of 20 nats is for)
    g = []
    for _ in range(60):
        det.run = []
        for _ in range(8):
            c = np.round(0.5 + rng.normal(0.0, 0.08) + rng.normal(0.0, s, 50)).astype(int)
            det.run.append((int(c.min()), np.bincount(c - c.min()).astype(float), {}))
        g.append(det._best_window(s, q1, tau=0.08, prior=(0.5, 0.15)))
    assert np.mean(g) < -1.0


def test_nearly_white_codes_count_as_independent_samples():
    # 10 Hz blocks of white noise of 0.36 LSB rounded to the LSB (the plane's decimated codes at rest): every
    # sample is an independent one; the share is read from the same still samples as their spread
    rng = np.random.default_rng(2)
    refs, dets = [AxisRef() for _ in AXES], [StuckDetector(LSB) for _ in AXES]
    for _ in range(400):
        y = np.round(0.2 + rng.normal(0.0, 0.36, (10, 3))) * LSB
        scale = np.array([math.sqrt(6 * r.sigma2) for r in refs]) if all(r.ready for r in refs) else None
        st = block_stats(y, scale)
        for j, ax in enumerate(AXES):
            dets[j].update(Observation(0, st, None, True, ax, refs[j], y=y))
            if not refs[j].ready:
                refs[j].add(float(st.v2[j]), float(st.m2[j]), float(st.mean[j]), int(st.spikes[j]), st.n, 30)
    for d in dets:
        assert d.spread[1] > 3000
        v_b = d.spread[0] / d.spread[1]
        assert d._independent_share(refs[0]) == pytest.approx(1.0, abs=0.05)
        # and the spread itself is the noise's (unbiased within a block of 10: 0.36^2 + 1/12 LSB^2 with rounding)
        assert v_b / LSB**2 == pytest.approx(0.36**2 + 1 / 12, rel=0.06)
