"""companion.sim.vehicle against independent truth: noise statistics over seeds, faults exactly as specified
(against a fault-free twin with the same seed), IMU agreement up to the configured spread, rigid-body
kinematics (integrated gyro vs the gravity the accelerometers see), armed flags, the tlog read back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.errors import CompanionError
from companion.mavlink.vehicle_tlog import write_tlog
from companion.sim.vehicle import (FAULT_KINDS, Fault, Flight, Handling, ImuSpread, Schedule, VehicleSimulator,
                                   WarmUp)

FS = 100.0
N = 3e-3  # rad/s/sqrt(Hz): 0.03 rad/s per sample at 100 Hz
SIGMA = N * math.sqrt(FS)
WHITE = {"rate_hz": FS, "axes": {a: [{"effect": "white_noise", "N": N}] for a in ("gx", "gy", "gz")}}
NO_SPREAD = ImuSpread(scale=0.0, misalignment_deg=0.0, gyro_bias=0.0, accel_bias=0.0)


def still(seed=0, **kw):
    return VehicleSimulator(WHITE, seed=seed, **kw)


# ------------------------------------------------------------------------------------------ noise statistics
def test_white_noise_variance_matches_the_model_over_seeds():
    """Sample variance of each IMU axis at rest against N^2 fs: z-scores from the chi-square law."""
    n = 20_000
    z = []
    for seed in range(12):
        blk = still(seed, imus=3).run(n / FS)
        for i in range(3):
            v = blk.gyro[i].var(axis=0, ddof=1)  # the constant bias is removed by the mean
            z.extend((v - SIGMA**2) / (SIGMA**2 * math.sqrt(2.0 / (n - 1))))
    z = np.asarray(z)
    assert np.all(np.abs(z) < 4.5), z
    assert abs(z.mean()) < 4.0 / math.sqrt(z.size)  # no common bias of the variance
    assert 0.6 < z.std() < 1.4


def test_imus_have_independent_noise_and_imu0_does_not_depend_on_the_imu_count():
    one = still(3, imus=1).run(200.0)
    three = still(3, imus=3).run(200.0)
    assert np.array_equal(one.gyro[0], three.gyro[0])
    r = np.corrcoef(three.gyro[0, :, 0], three.gyro[1, :, 0])[0, 1]
    assert abs(r) < 4.0 / math.sqrt(one.n)


def test_random_walk_and_gauss_markov_continue_across_blocks_and_rate_changes():
    """Increment variance of a random walk K^2/fs at the internal 600 s block edge equals the one inside;
    a Gauss-Markov process keeps its lag-1 correlation phi across block edges (checked over many edges)."""
    K, sig, tc = 1e-3, 1e-2, 2.0
    model = {"rate_hz": FS, "axes": {"gx": [{"effect": "random_walk", "K": K}],
                                     "gy": [{"effect": "gauss_markov", "sigma": sig, "tau_c": tc}]}}
    edges_rw, edges_gm = [], []
    for seed in range(40):
        sim = VehicleSimulator(model, seed=seed, spread=NO_SPREAD)
        sim.BLOCK_S = 5.0  # many block edges
        blk = sim.run(40.0)
        g = blk.gyro[0]
        k = np.arange(500, g.shape[0], 500)  # first samples of each new block
        edges_rw.extend(g[k, 0] - g[k - 1, 0])
        edges_gm.extend(zip(g[k - 1, 1], g[k, 1]))
    d = np.asarray(edges_rw)
    s2 = K**2 / FS
    assert d.var() == pytest.approx(s2, rel=6 * math.sqrt(2.0 / d.size))
    a, b = np.asarray(edges_gm).T
    phi = math.exp(-1.0 / (FS * tc))
    r = np.corrcoef(a, b)[0, 1]
    assert r == pytest.approx(phi, abs=4 * (1 - phi**2) / math.sqrt(a.size) + 0.01)
    # a rate change in the middle of a block: time and the random walk continue
    sim = VehicleSimulator(model, seed=1, spread=NO_SPREAD)
    b1 = sim.take_until(10.0)
    sim.set_rate(50.0)
    b2 = sim.take_until(20.0)
    assert b2.t[0] == pytest.approx(b1.t[-1] + 0.01) and np.allclose(np.diff(b2.t), 0.02)
    assert abs(b2.gyro[0, 0, 0] - b1.gyro[0, -1, 0]) < 6 * K / math.sqrt(50.0)


def test_taking_in_chunks_gives_the_same_samples_as_one_run():
    kw = dict(imus=2, seed=5, schedule=Schedule(flights=(Flight(30, 90),), handlings=(Handling(5, 10),)),
              fault=Fault("spikes", at=50, imu=1, size=0.01), warmup=WarmUp())
    whole = VehicleSimulator(WHITE, **kw).run(120.0)
    sim = VehicleSimulator(WHITE, **kw)
    sim.BLOCK_S = 600.0
    parts = [sim.take_until(t) for t in (3.3, 3.3, 17.77, 60.0, 120.995)]
    t = np.concatenate([p.t for p in parts])
    g = np.concatenate([p.gyro for p in parts], axis=1)
    assert np.array_equal(t, whole.t) and np.array_equal(g, whole.gyro)


# ------------------------------------------------------------------------------------------ faults
def twin_pair(kind, size=None, at=37.3, imu=1, axis="gy", seed=7, schedule=None, duration=80.0, block_s=None, **kw):
    base = dict(imus=3, seed=seed, schedule=schedule or Schedule())
    a = VehicleSimulator(WHITE, **base)
    b = VehicleSimulator(WHITE, fault=Fault(kind, at=at, size=size, imu=imu, axis=axis, **kw), **base)
    if block_s:
        a.BLOCK_S = b.BLOCK_S = block_s
    return a.run(duration), b.run(duration), b.fault


def untouched(clean, bad, imu, j):
    """Everything except IMU ``imu`` axis ``j`` is bit-identical to the fault-free twin."""
    mask = np.ones(clean.gyro.shape, bool)
    mask[imu, :, j] = False
    return np.array_equal(clean.gyro[mask], bad.gyro[mask]) and np.array_equal(clean.accel, bad.accel)


@pytest.mark.parametrize("kind", FAULT_KINDS)
def test_every_fault_kind_appears_exactly_as_specified(kind):
    size = {"stuck": 0.0, "noise": 6.0, "bias": 0.021, "spikes": 0.02, "drift": 3e-4, "saturate": 0.04,
            "flight_noise": 6.0}[kind]
    clean, bad, fault = twin_pair(kind, size)
    j = 1
    s = clean.t - 1.0
    on = s >= fault.at
    y0, y = clean.gyro[1, :, j], bad.gyro[1, :, j]
    assert untouched(clean, bad, 1, j)
    assert np.array_equal(y0[~on], y[~on])  # nothing before the fault
    d = y[on] - y0[on]
    if kind == "stuck":
        assert np.all(y[on] == y0[~on][-1])  # frozen at the last value before the fault
    elif kind == "bias":
        assert np.allclose(d, 0.021, rtol=0, atol=1e-15)
    elif kind == "drift":
        assert np.allclose(d, 3e-4 * (s[on] - fault.at), rtol=0, atol=1e-15)
    elif kind == "saturate":
        assert np.array_equal(y[on], np.clip(y0[on], -0.04, 0.04)) and np.abs(y0[on]).max() > 0.04
    elif kind == "spikes":
        hits = d != 0
        assert np.allclose(np.abs(d[hits]), 0.3, rtol=0, atol=1e-12)
        p, m = 0.02, int(on.sum())
        assert abs(hits.sum() - p * m) < 4 * math.sqrt(m * p * (1 - p))
        assert abs(np.sign(d[hits]).mean()) < 4 / math.sqrt(hits.sum())
    elif kind in ("noise", "flight_noise"):  # without Realism the own noise is the white noise
        ratio = y[on].std() / y0[on].std()
        m = int(on.sum())
        assert ratio == pytest.approx(6.0, rel=4 * math.sqrt(1.0 / m))  # std of a std ~ 1/sqrt(2m), twice
        assert abs(np.corrcoef(d, y0[on])[0, 1] - 1.0) < 1e-12  # the white part scaled, not a new noise


def test_stuck_with_dither_and_noise_size_statistics_over_seeds():
    """Stuck with dither: std of the output = size; noise x F: std ratio F (seeds pooled, chi-square bounds)."""
    for seed in range(5):
        clean, bad, f = twin_pair("stuck", 2e-4, seed=seed)
        on = clean.t - 1.0 >= f.at
        y = bad.gyro[1, on, 1]
        assert y.mean() == pytest.approx(clean.gyro[1, ~on, 1][-1], abs=5 * 2e-4 / math.sqrt(y.size))
        assert y.std(ddof=1) == pytest.approx(2e-4, rel=5 / math.sqrt(2 * y.size))
    for F in (0.5, 1.3, 3.0):
        clean, bad, f = twin_pair("noise", F, axis="gz", imu=0)
        on = clean.t - 1.0 >= f.at
        assert bad.gyro[0, on, 2].std() / SIGMA == pytest.approx(F, rel=5 / math.sqrt(2 * on.sum()))


def test_stuck_at_an_internal_block_edge_and_in_flight():
    """The frozen value is the sample before the fault also when that sample is in the previous block, and a
    gyro stuck in flight keeps its flight rate after landing."""
    clean, bad, f = twin_pair("stuck", at=10.0, block_s=10.0, duration=20.0)
    on = clean.t - 1.0 >= 10.0
    assert np.all(bad.gyro[1, on, 1] == clean.gyro[1, ~on, 1][-1])
    sch = Schedule(flights=(Flight(20, 60),))
    clean, bad, f = twin_pair("stuck", at=40.0, schedule=sch, duration=90.0, axis="gx", imu=0)
    on = clean.t - 1.0 >= 40.0
    frozen = clean.gyro[0, ~on, 0][-1]
    assert np.all(bad.gyro[0, on, 0] == frozen)
    assert abs(frozen) > 5 * SIGMA or abs(clean.rate_true[~on, 0][-1]) > 0.05  # a flight rate, not rest
    assert untouched(clean, bad, 0, 0)


def test_bias_fault_on_a_flight_is_the_only_difference_between_imus():
    """Two IMUs without spread: their difference in flight is noise (std sqrt(2) sigma, mean 0) until the
    bias jump, then shifted by exactly the jump."""
    sch = Schedule(flights=(Flight(10, 110),))
    sim = VehicleSimulator(WHITE, imus=2, seed=3, schedule=sch, spread=NO_SPREAD,
                           fault=Fault("bias", at=60, size=math.radians(1.0), imu=1, axis="gz"))
    blk = sim.run(120.0)
    s = blk.t - 1.0
    fly = (s > 20) & (s < 100)
    assert np.abs(blk.rate_true[fly]).max() > 0.8  # it really manoeuvres
    d = blk.gyro[1] - blk.gyro[0]
    for lo, hi, mean in ((20, 60, 0.0), (60, 100, math.radians(1.0))):
        m = (s >= lo) & (s < hi)
        for j in range(3):
            expect = mean if j == 2 else 0.0
            assert d[m, j].mean() == pytest.approx(expect, abs=5 * math.sqrt(2) * SIGMA / math.sqrt(m.sum()))
            assert d[m, j].std() == pytest.approx(math.sqrt(2) * SIGMA, rel=0.05)


def test_fault_validation_gives_one_clear_line():
    cases = [(lambda: Fault("frozen", 1.0), "unknown"), (lambda: Fault("spikes", 1.0, size=2.0), "<= 1"),
             (lambda: Fault("saturate", 1.0, size=0.0), "> 0"), (lambda: Fault("bias", -1.0), ">= 0"),
             (lambda: Fault("bias", 1.0, imu=3), "IMU"), (lambda: Fault("bias", 1.0, axis="ax"), "axis"),
             (lambda: VehicleSimulator(WHITE, imus=2, fault=Fault("stuck", 1.0, imu=2)), "2 IMU"),
             (lambda: VehicleSimulator({"rate_hz": FS, "axes": {"gx": [{"effect": "random_walk", "K": 1e-4}]}},
                                       fault=Fault("noise", 1.0)), "white_noise"),
             (lambda: Schedule(flights=(Flight(10, 100),), handlings=(Handling(90, 20),)), "overlaps"),
             (lambda: Flight(10, 12), "4 s"), (lambda: VehicleSimulator(WHITE, imus=4), "1, 2 or 3"),
             (lambda: VehicleSimulator({"rate_hz": FS, "axes": {"gx": [{"effect": "white_noise"}]}}), "needs parameter"),
             (lambda: VehicleSimulator({"rate_hz": FS, "axes": {"mx": []}}), "unknown")]
    for make, word in cases:
        with pytest.raises(CompanionError) as e:
            make()
        msg = str(e.value)
        assert word in msg and "\n" not in msg, msg


def test_default_sizes_and_units():
    assert Fault("bias", 0).size == pytest.approx(math.radians(1.0))
    assert Fault("stuck", 0).size == 0.0 and Fault("noise", 0).size == 6.0
    assert "IMU1 gz spikes 0.4 %" in Fault("spikes", 5, size=0.004, imu=1, axis="gz").describe()


# ------------------------------------------------------------------------------------------ body motion
def integrate(rate, dt):
    """Body-to-world rotation after integrating body rates (exact per-step rotation, Rodrigues)."""
    R = np.eye(3)
    for w in rate:
        th = np.linalg.norm(w) * dt
        if th > 0:
            k = w / np.linalg.norm(w)
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            R = R @ (np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K)
    return R


@pytest.mark.parametrize("event", ["handling", "flight"])
def test_integrated_body_rates_rotate_gravity_as_the_accelerometers_see_it(event):
    """Independent check of the kinematics: the rotation integrated from the true body rates over a handling
    or a whole flight maps the specific force at rest before it onto the one after it."""
    fs = 1000.0
    sch = Schedule(handlings=(Handling(2.0, 10.0),)) if event == "handling" else Schedule(flights=(Flight(2.0, 40.0),))
    sim = VehicleSimulator(WHITE, seed=11, rate_hz=fs, schedule=sch)
    for e in sim.motion.events:
        if e.vib is not None:
            e.vib = [(0.0, lines) for _, lines in e.vib]  # vibration off: it is not a rotation of the body
    end = sch.events()[0].end
    blk = sim.run(end + 3.0)
    s = blk.t - 1.0
    move = (s >= 1.0) & (s < end + 1.0)
    R = integrate(blk.rate_true[move], 1.0 / fs)
    f0, f1 = blk.accel_true[np.flatnonzero(move)[0] - 1], blk.accel_true[-1]
    assert np.linalg.norm(f0) == pytest.approx(9.80665) and np.linalg.norm(f1) == pytest.approx(9.80665)
    assert np.allclose(R @ f1, f0, atol=2e-3 * 9.81)  # R = R_0^T R_t: gravity fixed in the world, the body turned
    turned = math.degrees(math.acos(np.clip(f0 @ f1 / 9.80665**2, -1, 1)))
    peak = np.abs(blk.rate_true[move]).max()
    if event == "handling":
        tilt = np.degrees(np.arccos(np.clip(-blk.accel_true[move, 2] / np.linalg.norm(blk.accel_true[move], axis=1), -1, 1)))
        assert tilt.max() > 30.0  # gravity moved between the accel axes while held
        assert 0.5 < peak < 3.0
    else:
        assert 0.7 < peak < 3.0 and turned < 10.0  # landed on level-ish ground


def test_flight_phases_armed_flags_and_vibration():
    sch = Schedule(flights=(Flight(30, 150),))
    sim = VehicleSimulator(WHITE, imus=2, seed=2, schedule=sch)
    blk = sim.run(200.0)
    s = blk.t - 1.0
    assert np.array_equal(blk.armed, (s >= 30) & (s < 150))
    assert np.array_equal(sim.armed_at(blk.t), blk.armed)
    rest = s < 30
    assert np.all(blk.rate_true[rest] == 0) and np.allclose(np.linalg.norm(blk.accel_true[rest], axis=1), 9.80665)
    air = (s > 40) & (s < 140)
    assert 1.0 < blk.accel_true[air].std(axis=0).mean() < 4.0  # vibration ~2 m/s^2
    assert np.abs(blk.rate_true[air]).max() > 0.7
    assert blk.accel_true[air, 2].mean() < -9.8  # thrust along body -z holds the vehicle up


def test_imus_agree_up_to_their_configured_scale_and_misalignment():
    spread = ImuSpread(scale=0.008, misalignment_deg=0.4, gyro_bias=3e-3)
    sim = VehicleSimulator(WHITE, imus=3, seed=9, schedule=Schedule(flights=(Flight(5, 95),)), spread=spread,
                           warmup=WarmUp(math.radians(0.1), 100.0))
    blk = sim.run(100.0)
    for i in range(3):
        C = sim.gyro_matrix[i]
        Rm = sim.misalignment[i]
        assert np.allclose(Rm @ Rm.T, np.eye(3))
        angle = math.degrees(math.acos(np.clip((np.trace(Rm) - 1) / 2, -1, 1)))
        assert angle <= 0.4 + 1e-9
        assert np.all(np.abs(np.diag(C @ Rm.T) - 1) <= 0.008 + 1e-12)
        model = blk.rate_true @ C.T + sim.gyro_bias[i] + sim.warmup_amplitude[i] * np.exp(-blk.t / 100.0)[:, None]
        resid = blk.gyro[i] - model
        assert np.abs(resid.mean(axis=0)).max() < 5 * SIGMA / math.sqrt(blk.n)
        assert resid.std(axis=0) == pytest.approx(np.full(3, SIGMA), rel=0.05)
    d = blk.gyro[1] - blk.gyro[0]  # the vehicle's motion cancels up to the spread
    w = np.abs(blk.rate_true).max()
    assert np.abs(d - (blk.rate_true @ (sim.gyro_matrix[1] - sim.gyro_matrix[0]).T)).std() < 2 * SIGMA
    assert np.abs(blk.rate_true @ (sim.gyro_matrix[1] - sim.gyro_matrix[0]).T).max() <= w * (2 * 0.008 + 2 * math.radians(0.4)) * 1.8


def test_warmup_drift_is_the_configured_exponential():
    sim = VehicleSimulator(WHITE, imus=2, seed=4, warmup=WarmUp(math.radians(0.1), 200.0), spread=NO_SPREAD)
    blk = sim.run(1200.0)
    a = sim.warmup_amplitude[:2]
    assert np.all((np.abs(a) >= math.radians(0.05)) & (np.abs(a) <= math.radians(0.1)))
    for lo in (0, 300, 900):
        m = (blk.t >= lo + 1) & (blk.t < lo + 101)
        expect = a[:, None, :] * np.exp(-blk.t[m] / 200.0)[None, :, None]
        assert np.allclose((blk.gyro[:, m] - expect).mean(axis=1), 0.0, atol=5 * SIGMA / math.sqrt(m.sum()))


def test_random_schedule_is_valid_and_covers_the_duration():
    sch = Schedule.random(36_000, seed=1)
    ev = sch.events()
    assert len(sch.flights) >= 5 and len(sch.handlings) >= 5
    assert all(b.start >= a.end + 60 for a, b in zip(ev, ev[1:])) and ev[-1].end <= 36_000


# ------------------------------------------------------------------------------------------ tlog
def test_tlog_read_back_by_companion_and_pymavlink(tmp_path):
    from companion.sources import load
    from tests.support.pymavlink_reference import pymavlink_messages

    kw = dict(imus=3, seed=6, schedule=Schedule(flights=(Flight(20, 50),)), fault=Fault("bias", 30, imu=2))
    path = tmp_path / "v.tlog"
    counts = write_tlog(path, VehicleSimulator(WHITE, **kw), 70.0, block_s=25.0)
    truth = VehicleSimulator(WHITE, **kw).run(70.0)
    assert counts == {"imu_messages": 3 * 7000, "heartbeats": 70}
    res = load(str(path))
    streams = {s.key.message: s for s in res.imu_streams()}
    assert sorted(streams) == ["RAW_IMU", "SCALED_IMU2", "SCALED_IMU3"]
    for i, name in enumerate(("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")):
        st = streams[name]
        assert st.key.instance == i
        assert np.allclose(st.t, truth.t, atol=1e-9)
        assert np.array_equal(st.gyro, np.rint(truth.gyro[i] / 1e-3) * 1e-3)  # int16 mrad/s, rounded
        assert np.allclose(st.accel, np.rint(truth.accel[i] / 9.80665e-3) * 9.80665e-3)  # int16 mG
    msgs = pymavlink_messages(path)
    hb = [m for m in msgs if m.get_type() == "HEARTBEAT"]
    armed = [bool(m.base_mode & 128) for m in hb]
    assert armed == [20 <= k < 50 for k in range(70)]
    imu2 = [m for m in msgs if m.get_type() == "SCALED_IMU3"]
    assert [m.xgyro for m in imu2] == np.rint(truth.gyro[2, :, 0] / 1e-3).astype(int).tolist()
    assert [m.time_boot_ms for m in imu2[:3]] == [1000, 1010, 1020]
    seqs = [m.get_seq() for m in msgs]
    assert all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:]))  # sequence continues across blocks


def test_flight_noise_fault_grows_the_vibration_pickup_too():
    """With Realism, ``flight_noise`` adds (size - 1) x the IMU's filtered white noise *and* vibration pick-up:
    disarmed (no vibration) exactly what ``noise`` adds, in flight much more on IMU0 x (the copter preset's
    strongest pick-up)."""
    from companion.sim.preset import load_preset

    P = load_preset("copter")
    sched = Schedule(flights=(Flight(30.0, 70.0, max_rate=1.0),))

    def run(kind):
        fault = None if kind is None else Fault(kind, at=2.0, size=2.0, imu=0, axis="gx")
        sim = VehicleSimulator(P["model"], imus=3, seed=5, rate_hz=50.0, schedule=sched, fault=fault,
                               realism=P["realism"])
        return sim.run(80.0)

    clean, white, own = run(None), run("noise"), run("flight_noise")
    s = clean.t - 1.0
    rest, flying = (s >= 2.0) & (s < 29.0), (s > 40.0) & (s < 65.0)
    d_white = white.gyro[0, :, 0] - clean.gyro[0, :, 0]
    d_own = own.gyro[0, :, 0] - clean.gyro[0, :, 0]
    np.testing.assert_allclose(d_own[rest], d_white[rest], rtol=0, atol=1e-12)
    assert d_own[flying].std() > 3.0 * d_white[flying].std()
    assert np.array_equal(own.gyro[1:], clean.gyro[1:])  # the other IMUs untouched
