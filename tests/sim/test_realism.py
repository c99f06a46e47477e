"""The realistic gyro path (companion.sim.realism) against analytic truth: filter + decimation Allan variance,
vibration lines (also aliased), per-IMU timing skew, temperature-driven bias, presets, writers' temperature."""

import math

import numpy as np
import pytest
from scipy import signal

from companion.errors import CompanionError
from companion.sim.preset import load_preset
from companion.sim.realism import (PRESETS, Realism, Vibration, filtered_white_avar,
                                   psd_line_amplitude)
from companion.mavlink.vehicle_tlog import write_tlog
from companion.sim.vehicle import Flight, Schedule, VehicleSimulator

N = 1e-3
WHITE = {"rate_hz": 50.0, "axes": {"gx": [{"effect": "white_noise", "N": N}]}}


def _sim(model, seed, realism, block_s=None, **kw):
    """A simulator whose internal block fits a short test run (the default block is 600 s)."""
    sim = VehicleSimulator(model, seed=seed, realism=realism, **kw)
    if block_s is not None:
        sim.BLOCK_S = block_s
    return sim


def _avar(y, m):
    c = np.cumsum(np.r_[0.0, y])
    a = (c[m:] - c[:-m]) / m
    return 0.5 * np.mean((a[m:] - a[:-m]) ** 2)


def _quiet(rate=50.0, n=1e-9):
    return {"rate_hz": rate, "axes": {a: [{"effect": "white_noise", "N": n}] for a in ("gx", "gy", "gz")}}


@pytest.mark.parametrize("fc", [None, 20.0, 5.0])
def test_filter_and_decimation_allan_matches_the_analytic_curve(fc):
    """White noise drawn at 1 kHz, low-passed (2nd-order Butterworth) and picked at 50 Hz: the mean AVAR over
    seeds equals the AVAR computed from the filter's folded PSD, within 4 standard errors of that mean."""
    r = Realism(gyro_lpf_hz=fc)
    taus = np.array([0.02, 0.04, 0.1, 0.2, 0.5, 1.0])
    an = filtered_white_avar(N, r, 50.0, taus)
    seeds = 12
    est = np.array([[_avar(_sim(WHITE, s, r, 150.0).run(150).gyro[0, :, 0],
                           int(round(t * 50))) for t in taus] for s in range(seeds)])
    ratio = est.mean(0) / an
    se = est.std(0, ddof=1) / math.sqrt(seeds) / an
    assert np.all(np.abs(ratio - 1.0) < 4 * se + 0.005), (ratio, se)


def test_analytic_shape_rolls_off_below_the_corner_and_reaches_the_white_level_above_it():
    """ADEV sqrt(tau) of filtered, decimated white noise: far below N at tau ~ 1/fc for a 5 Hz filter, within a
    few % of N (plus the folded filter skirt) for tau >> 1/fc; without a filter the whole sensor band aliases
    (white level x fs/fl)."""
    taus = np.array([0.02, 0.2, 5.0, 50.0])
    lo = filtered_white_avar(N, Realism(gyro_lpf_hz=5.0), 50.0, taus) * taus / N**2
    assert lo[0] < 0.05 and 0.95 < lo[-1] < 1.01
    # the skirt beyond the log band folds in: 1 + 2 sum_m |H(m fl)|^2
    b, a = signal.butter(2, 20.0, fs=1000.0)
    _, h = signal.freqz(b, a, worN=50.0 * np.arange(1, 10), fs=1000.0)
    fold = 1 + 2 * np.sum(np.abs(h) ** 2)
    mid = filtered_white_avar(N, Realism(gyro_lpf_hz=20.0), 50.0, np.array([200.0])) * 200.0 / N**2
    assert mid[0] == pytest.approx(fold, rel=0.01)
    none = filtered_white_avar(N, Realism(gyro_lpf_hz=None), 50.0, np.array([10.0])) * 10.0 / N**2
    assert none[0] == pytest.approx(20.0, rel=0.01)


@pytest.mark.parametrize("rotor, expect_hz", [(37.0, 37.0), (230.0, 30.0)])
def test_vibration_line_at_the_right_frequency_and_amplitude(rotor, expect_hz):
    """A rotor line (ground phase, no other motion) of amplitude A at the sensor: logged at 200 Hz through an
    80 Hz filter it has amplitude A |H(f)| at f, or, above the log's Nyquist, at the alias |f - 200|."""
    A = 0.05
    r = Realism(gyro_lpf_hz=80.0, ground=Vibration(rotor_hz=rotor, harmonics=(A,)))
    b, a = signal.butter(2, 80.0, fs=1000.0)
    _, h = signal.freqz(b, a, worN=[rotor], fs=1000.0)
    amps = []
    for seed in range(4):
        blk = _sim(_quiet(200.0, 1e-4), seed, r, 60.0, imus=2).run(60)
        for i in range(2):
            for j in range(3):
                y = blk.gyro[i, :, j]
                f, p = signal.periodogram(y - y.mean(), fs=200.0)
                assert abs(f[np.argmax(p)] - expect_hz) < 0.1
                amps.append(psd_line_amplitude(y, 200.0, expect_hz, 0.5))
    assert np.allclose(amps, A * abs(h[0]), rtol=0.03), (amps, A * abs(h[0]))


def test_vibration_per_imu_gain_and_phase():
    """Per-IMU gains scale the line; disarmed (ground: nothing) vs flight (rotor line) phases."""
    r = Realism(gyro_lpf_hz=None, sensor_rate_hz=1000.0, imu_vibration_gain=((1, 1, 1), (3, 3, 3), (0.5, 0.5, 0.5)),
                flight=Vibration(rotor_hz=60.0, harmonics=(0.02,)))
    sch = Schedule(flights=[Flight(100.0, 220.0)])
    blk = VehicleSimulator(_quiet(200.0, 1e-5), imus=3, seed=2, realism=r, schedule=sch).run(260)
    t = blk.t - 1.0
    air, ground = (t > 120) & (t < 200), t < 90
    for i, g in enumerate((1.0, 3.0, 0.5)):
        y = blk.gyro[i, air, 2]
        assert psd_line_amplitude(y - np.convolve(y, np.ones(41) / 41, "same"), 200.0, 60.0, 1.0) == pytest.approx(0.02 * g, rel=0.05)
        assert psd_line_amplitude(blk.gyro[i, ground, 2], 200.0, 60.0, 1.0) < 0.05 * 0.02 * g


def test_timing_skew_as_configured():
    """Own stamps: t_imu - t is the configured skew (jitter within 3 std); common stamps: the lag that a
    cross-spectrum of the shared broadband vibration measures between IMUs is the configured skew."""
    skew = (0.0, 0.004, -0.0025)
    jit = 2e-4
    r = Realism(gyro_lpf_hz=100.0, skew_s=skew, jitter_s=jit, stamp="own", ground=Vibration(broadband=0.5))
    blk = _sim(_quiet(400.0, 1e-6), 5, r, 60.0, imus=3).run(60)
    for i in range(3):
        d = blk.t_imu[i] - blk.t
        assert abs(np.mean(d) - skew[i]) < 3 * jit / math.sqrt(d.size) + 1e-6
        assert np.max(np.abs(d - skew[i])) <= 3 * jit + 1e-6
        assert np.std(d) == pytest.approx(jit, rel=0.1)
    r2 = Realism(gyro_lpf_hz=100.0, skew_s=skew, stamp="common", ground=Vibration(broadband=0.5))
    blk = _sim(_quiet(400.0, 1e-6), 6, r2, 60.0, imus=3).run(60)
    assert blk.t_imu is None
    for i in (1, 2):
        f, c = signal.csd(blk.gyro[0, :, 0], blk.gyro[i, :, 0], fs=400.0, nperseg=1024)
        m = (f > 2) & (f < 60)
        lag = np.polyfit(2 * np.pi * f[m], np.unwrap(np.angle(c[m])), 1)[0]  # IMU i shows the body at t + skew
        assert lag == pytest.approx(skew[i], abs=3e-4)  # the sensor clock is 1 ms: picks round down


def test_temperature_warmup_gives_the_configured_bias_slope():
    """Bias vs temperature over a warm-up: the regression slope of 1 s means on the logged temperature is the
    drawn per-axis slope (truth: sim.temp_slope), to within its standard error from the white noise."""
    r = Realism(gyro_lpf_hz=20.0, rise_c=(20.0, 10.0, 5.0), temp_tau_s=(200.0, 200.0, 200.0), temp_slope=2e-4)
    errs = []
    for seed in range(6):
        sim = _sim(_quiet(50.0, 3e-4), seed, r, 900.0, imus=3)
        blk = sim.run(900)
        for i in range(3):
            T = blk.temperature[i].reshape(-1, 50).mean(1)
            assert T[-1] - T[0] == pytest.approx(r.rise_c[i] * (math.exp(-1 / 200) - math.exp(-900 / 200)), rel=0.02)
            for j in range(3):
                g = blk.gyro[i, :, j].reshape(-1, 50).mean(1)
                slope, _ = np.polyfit(T, g, 1)
                se = 3e-4 * math.sqrt(1.05) / math.sqrt(np.sum((T - T.mean()) ** 2))  # 1 s means of white N
                errs.append((slope - sim.temp_slope[i, j]) / se)
    errs = np.array(errs)
    assert np.all(np.abs(errs) < 5) and abs(errs.mean()) < 4 / math.sqrt(errs.size) + 0.3, errs


def test_gauss_markov_bias_and_lsb():
    """The Gauss-Markov bias has the configured variance (slow part, many axes); with a sensor LSB and no filter
    the output is on the LSB grid."""
    r = Realism(gyro_lpf_hz=None, bias_gm_sigma=2e-3, bias_gm_tau_s=5.0)
    v = [np.var(VehicleSimulator(_quiet(50.0, 1e-7), imus=3, seed=s, realism=r).run(600).gyro[:, :, :], axis=1)
         for s in range(4)]
    assert np.mean(v) == pytest.approx(4e-6, rel=0.15)
    lsb = math.radians(1 / 16.4)
    r = Realism(gyro_lpf_hz=None, gyro_lsb=lsb, ground=Vibration(broadband=0.01))
    g = _sim(_quiet(50.0, 1e-4), 1, r, 20.0).run(20).gyro[0]
    assert np.allclose(g / lsb, np.round(g / lsb), atol=1e-6)


def test_average_decimation_is_the_mean_of_the_sensor_samples():
    """decimation=average (PX4 sensor_combined) of a line: the sinc gain of a k-sample mean, no alias of the
    filtered band beyond it."""
    f0, A = 90.0, 0.05
    r = Realism(gyro_lpf_hz=None, decimation="average", ground=Vibration(rotor_hz=f0, harmonics=(A,)))
    y = _sim(_quiet(250.0, 1e-7), 3, r, 40.0).run(40).gyro[0, :, 0]
    k = 4
    gain = abs(np.sin(np.pi * f0 * k / 1000) / (k * np.sin(np.pi * f0 / 1000)))
    assert psd_line_amplitude(y, 250.0, f0, 0.5) == pytest.approx(A * gain, rel=0.03)


def test_default_path_unchanged_and_blocks_continue():
    """Without Realism nothing changes (no temperature, common time); with it, one long run equals the same
    run taken in pieces (filter state, rotor phase and sensor clock carried)."""
    sim = VehicleSimulator(WHITE, imus=2, seed=1)
    blk = sim.run(10)
    assert blk.temperature is None and blk.t_imu is None
    r = load_preset("copter")["realism"]
    sch = Schedule(flights=[Flight(100.0, 400.0)])
    a = _sim(WHITE, 4, r, 250.0, imus=3, schedule=sch, rate_hz=50.0).run(700)
    sim = _sim(WHITE, 4, r, 250.0, imus=3, schedule=sch, rate_hz=50.0)
    parts = [sim.take_until(x) for x in (123.4, 260.0, 650.0, a.t[-1])]
    b = np.concatenate([p.gyro for p in parts], axis=1)
    assert np.array_equal(a.gyro, b)


@pytest.mark.parametrize("name", PRESETS)
def test_presets_load_and_run(name, tmp_path):
    P = load_preset(name)
    assert P["realism"].gyro_lpf_hz > 0 and P["model"].rate_hz == P["vehicle"]["rate_hz"]
    sim = VehicleSimulator(P["model"], imus=P["vehicle"]["imus"], seed=1, realism=P["realism"],
                           schedule=Schedule(flights=[Flight(20.0, 60.0)]))
    path = tmp_path / "x.tlog"
    write_tlog(str(path), sim, 80)
    from companion.sources import load

    streams = load(str(path)).streams
    assert len(streams) == P["vehicle"]["imus"]
    for s in streams:
        assert s.rate_hz == pytest.approx(P["vehicle"]["rate_hz"], rel=0.01) and s.temperature is not None


def test_realism_errors_are_one_line():
    with pytest.raises(CompanionError, match="gyro_lpf_hz"):
        Realism(gyro_lpf_hz=600.0)
    with pytest.raises(CompanionError, match="decimation"):
        Realism(decimation="nearest")
    with pytest.raises(CompanionError, match="rotor_hz"):
        Realism.from_dict({"flight": {"harmonics": [0.1]}})
    with pytest.raises(CompanionError, match="unknown key"):
        Realism.from_dict({"gyro_filter": 20})
    with pytest.raises(CompanionError, match="preset"):
        load_preset("submarine")
    with pytest.raises(CompanionError, match="below the logged rate"):
        VehicleSimulator(WHITE, realism=Realism(sensor_rate_hz=20.0, gyro_lpf_hz=5.0))


def test_writers_log_the_temperature(tmp_path):
    """The simulated warm-up reaches the logs: tlog RAW_IMU/SCALED_IMU2/3 temperature (cdegC), DataFlash IMU
    Temp (old 3-IMU layout, as log171) and T (4.x), ULog sensor_gyro temperature; read back by companion's
    readers."""
    from companion.sim.dataflash_writer import write_imu_log
    from companion.sim.ulog_writer import write_ulog
    from companion.sources import load

    P = load_preset("copter")
    sim = _sim(P["model"], 3, P["realism"], 120.0, imus=3, rate_hz=50.0)
    blk = sim.run(120)
    assert np.all(np.diff(blk.temperature, axis=1) >= -1e-9) and np.all(blk.temperature[:, -1] > blk.temperature[:, 0])
    paths = {"tlog": tmp_path / "x.tlog", "2015": tmp_path / "x2015.bin", "4.x": tmp_path / "x4.bin",
             "ulg": tmp_path / "x.ulg"}
    write_tlog(str(paths["tlog"]), _sim(P["model"], 3, P["realism"], 120.0, imus=3, rate_hz=50.0), 120)
    for layout in ("2015", "4.x"):
        write_imu_log(paths[layout], blk.t, blk.gyro, blk.accel, layout=layout, temperature=blk.temperature)
    write_ulog(paths["ulg"], blk.t, blk.gyro, blk.accel, temperature=blk.temperature)
    for kind, path in paths.items():
        streams = [s for s in load(str(path)).streams if s.key.message != "sensor_combined"]
        assert len(streams) == 3, kind
        for i, s in enumerate(sorted(streams, key=lambda s: s.key.instance)):
            tol = 0.006 if kind == "tlog" else 1e-4
            assert s.temperature is not None, kind
            assert np.allclose(s.temperature, blk.temperature[i][:s.temperature.shape[0]], atol=tol), kind


def test_faults_on_the_realistic_path():
    """A noise fault multiplies the faulty axis' filtered white noise (on a still vehicle its std grows by
    about the factor); a stuck fault freezes the logged value; every other IMU and axis is bit-identical to
    the run without the fault."""
    from companion.sim.vehicle import Fault

    r = Realism(gyro_lpf_hz=20.0, imu_noise_gain=(1.0, 2.0, 1.0))
    model = {"rate_hz": 50.0, "axes": {a: [{"effect": "white_noise", "N": 1e-3}] for a in ("gx", "gy", "gz")}}
    base = _sim(model, 7, r, 200.0, imus=3).run(200)
    for kind, size in (("noise", 4.0), ("stuck", 0.0)):
        blk = _sim(model, 7, r, 200.0, imus=3, fault=Fault(kind, at=100.0, size=size, imu=1, axis="gy")).run(200)
        on = blk.t - 1.0 >= 100.0
        assert np.array_equal(blk.gyro[[0, 2]], base.gyro[[0, 2]])
        assert np.array_equal(blk.gyro[1, :, [0, 2]], base.gyro[1, :, [0, 2]])
        assert np.array_equal(blk.gyro[1, ~on, 1], base.gyro[1, ~on, 1])
        y, y0 = blk.gyro[1, on, 1], base.gyro[1, on, 1]
        if kind == "noise":
            assert np.std(y) / np.std(y0) == pytest.approx(4.0, rel=0.05)
        else:
            assert np.all(y == base.gyro[1, ~on, 1][-1])


def test_cli_preset(tmp_path):
    """`companion simulate --vehicle --preset copter` without a model: the preset's 3 IMUs at 50 Hz with a
    rising temperature; a missing model without a preset is one error line."""
    from companion.cli.main import main
    from companion.sources import load

    out = tmp_path / "c.tlog"
    assert main(["simulate", "--vehicle", "--preset", "copter", "--duration", "60", "--arm-at", "20",
                 "--out", str(out)]) == 0
    streams = load(str(out)).streams
    assert [s.key.message for s in streams] == ["RAW_IMU", "SCALED_IMU2", "SCALED_IMU3"]
    for s in streams:
        assert s.rate_hz == pytest.approx(50.0, rel=0.01) and s.temperature[-1] > s.temperature[0]
    assert main(["simulate", "--vehicle", "--duration", "10", "--out", str(tmp_path / "x.tlog")]) != 0
    assert main(["simulate", "--vehicle", "--preset", "boat", "--duration", "10", "--out", str(tmp_path / "x.tlog")]) != 0


def test_rate_change_on_the_realistic_path():
    """A SET_MESSAGE_INTERVAL (set_rate) mid-run: the samples continue at the new rate, one time grid, and the
    filtered white noise keeps its per-sample level at the new rate (from the analytic curve)."""
    r = Realism(gyro_lpf_hz=20.0)
    sim = _sim(WHITE, 3, r, 100.0, imus=1)
    a = sim.take_until(60.0)
    sim.set_rate(100.0)
    b = sim.take_until(400.0)
    assert np.all(np.diff(np.r_[a.t, b.t]) > 0)
    assert np.allclose(np.diff(b.t), 0.01)
    expect = math.sqrt(filtered_white_avar(N, r, 100.0, np.array([0.01]))[0])
    y = b.gyro[0, :, 0]
    got = math.sqrt(_avar(y, 1))
    assert got == pytest.approx(expect, rel=4 / math.sqrt(y.size / 3))


@pytest.mark.shared
def test_copter_preset_matches_log171(shared_data):
    """A regression check of the copter preset's fit, not a validation: the preset was fitted to this log
    (ArduCopter 3.3, 3 IMUs at 50 Hz, still 31-70 s after boot, INS_GYRO_FILTER 20 Hz; no other log of the
    kind is in ../shared/data), so agreement shows the simulator still reproduces its fit: per-IMU ground
    noise (median 2-s std) within 15 %, the IMU1/IMU0 ratio (about 9) within 15 %, the still-run temperatures
    rising as the log's do (IMU2 the fastest). The independent reference is ../shared/data/README.md's reading
    of the log (its authors', not this code's): "on the ground the three IMUs' noise differs by about 10x (a
    quiet one and two noisier ones)": the spread (largest / smallest 5-20x) is checked on the log as this test
    measures it and on the simulation; the count is not (in this still window two IMUs are quiet, one 9x)."""
    from companion.sources import load

    d = load(str(shared_data / "ardupilot" / "dronekit_log171.bin"))
    P = load_preset("copter")
    assert d.meta["params"]["INS_GYRO_FILTER"] == P["realism"].gyro_lpf_hz
    streams = sorted([s for s in d.streams if s.key.message == "IMU"], key=lambda s: s.key.instance)

    def noise(t, g):
        m = (t >= 31.0) & (t < 70.0)
        k = int(m.sum()) // 100 * 100
        return np.median(g[m][:k].reshape(-1, 100, 3).std(1).mean(1))

    real = np.array([noise(s.t, s.gyro) for s in streams])
    dT_real = np.array([np.interp(70.0, s.t, s.temperature) - np.interp(31.0, s.t, s.temperature) for s in streams])
    sims = []
    for seed in range(3):
        sim = _sim(P["model"], seed, P["realism"], 70.0, imus=3, rate_hz=50.0, t_start=float(streams[0].t[0]))
        blk = sim.run(60.0)
        sims.append([noise(blk.t, blk.gyro[i]) for i in range(3)])
        dT = blk.temperature[:, np.searchsorted(blk.t, 70.0) - 1] - blk.temperature[:, np.searchsorted(blk.t, 31.0)]
    sim_noise = np.median(sims, axis=0)
    for noise_of in (real, sim_noise):  # the independent reading: the IMUs' noise differs by about 10x
        assert 5.0 <= noise_of.max() / noise_of.min() <= 20.0, noise_of
    assert np.allclose(sim_noise, real, rtol=0.15), (sim_noise, real)
    assert sim_noise[1] / sim_noise[0] == pytest.approx(real[1] / real[0], rel=0.15)
    assert np.argmax(dT) == np.argmax(dT_real) == 2 and np.allclose(dT, dT_real, atol=0.8), (dT, dT_real)

