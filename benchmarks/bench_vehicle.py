"""Vehicle simulator speed, side by side with the plain noise synthesiser, and its tlog writer beside write_imu_tlog.

    python -m benchmarks.bench_vehicle             # 1 h, 3 IMUs at 100 Hz, random flights and handling
    python -m benchmarks.bench_vehicle --hours 0.2 # quicker

1. ``companion.sim.vehicle.VehicleSimulator`` (3 IMUs: body motion, vibration, per-IMU errors, warm-up,
   model noise; 600 s blocks) against ``companion.sim.synth.simulate_model`` of the same model for the
   same samples (3 IMUs x 6 axes of noise only): the price of the vehicle over its noise.
   And the same vehicle with the realistic gyro path of ``--preset`` (default copter: 1 kHz sensors,
   filter, decimation, vibration, skew, temperature; ``companion.sim.realism``) at the same 100 Hz.
2. ``companion.mavlink.vehicle_tlog.write_tlog`` (3 streams and HEARTBEATs merged in time order, block by block)
   against ``companion.mavlink.tlog_writer.write_imu_tlog`` writing the same samples as 3 separate tlogs.
Times are CPU seconds of this process (the machine is shared). Also printed: how much of the run was armed
or handled, and the peak body rate.

Target: no fixed threshold: many times faster than real time; the price of the vehicle over the plain noise synthesis (ratio) is the figure.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


from benchmarks import results
from companion.mavlink.tlog_writer import write_imu_tlog
from companion.sim.synth import simulate_model
from companion.mavlink.vehicle_tlog import write_tlog
from companion.sim.vehicle import Schedule, VehicleSimulator, WarmUp

MODEL = {"rate_hz": 100.0, "axes": {
    **{a: [{"effect": "white_noise", "N": 3e-3}, {"effect": "bias_instability", "B": 5e-5},
           {"effect": "random_walk", "K": 1e-5}] for a in ("gx", "gy", "gz")},
    **{a: [{"effect": "white_noise", "N": 2e-3}] for a in ("ax", "ay", "az")}}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--preset", default="copter", help="preset of the realistic run (copter, plane, rover)")
    args = results.parse_args(ap, {"hours": 0.25})
    dur = args.hours * 3600.0
    sch = Schedule.random(dur, seed=args.seed, flights_per_hour=3, handlings_per_hour=3)

    def make():
        return VehicleSimulator(MODEL, imus=3, seed=args.seed, schedule=sch, warmup=WarmUp())

    t0 = time.process_time()
    sim = make()
    blocks = list(sim.blocks(dur))
    t_vehicle = time.process_time() - t0
    n = sum(b.n for b in blocks)
    t0 = time.process_time()
    for i in range(3):
        simulate_model(MODEL, dur, seed=args.seed + i)
    t_synth = time.process_time() - t0
    armed = sum(int(b.armed.sum()) for b in blocks) / n
    peak = max(float(np.abs(b.rate_true).max()) for b in blocks)
    print(f"{args.hours:g} h, 3 IMUs at 100 Hz ({n} samples each); {len(sch.flights)} flights "
          f"({100 * armed:.1f} % armed), {len(sch.handlings)} handlings; peak body rate {peak:.2f} rad/s")
    print(f"simulate  vehicle {t_vehicle:6.2f} s ({dur / t_vehicle:,.0f}x real time) | noise only "
          f"{t_synth:6.2f} s | ratio {t_vehicle / t_synth:.2f}")
    from companion.sim.preset import load_preset

    real = load_preset(args.preset)["realism"]
    t0 = time.process_time()
    for _ in VehicleSimulator(MODEL, imus=3, seed=args.seed, schedule=sch, warmup=WarmUp(), realism=real).blocks(dur):
        pass
    t_real = time.process_time() - t0
    print(f"realistic vehicle (--preset {args.preset}: {real.sensor_rate_hz:g} Hz sensors, {real.gyro_lpf_hz:g} Hz "
          f"low-pass) {t_real:6.2f} s ({dur / t_real:,.0f}x real time) | {t_real / t_vehicle:.2f}x the plain vehicle")
    with tempfile.TemporaryDirectory() as d:
        t0 = time.process_time()
        counts = write_tlog(Path(d) / "v.tlog", make(), dur)
        t_write = time.process_time() - t0 - t_vehicle  # minus the simulation measured above
        size = (Path(d) / "v.tlog").stat().st_size
        t = np.concatenate([b.t for b in blocks])
        t0 = time.process_time()
        for i, msg in enumerate(("RAW_IMU", "SCALED_IMU2", "SCALED_IMU3")):
            write_imu_tlog(Path(d) / f"{i}.tlog", t, np.concatenate([b.gyro[i] for b in blocks]),
                           np.concatenate([b.accel[i] for b in blocks]), message=msg, instance=i)
        t_single = time.process_time() - t0
    if t_write < 0.1 * t_single:  # a short run: the writing is within the simulation's timing noise
        print(f"tlog      write_tlog {t_write + t_vehicle:6.2f} s with the simulation ({size / 1e6:.1f} MB, "
              f"{counts['heartbeats']} HEARTBEAT): the writing alone is below the timing noise of a run this short "
              f"| write_imu_tlog x3 {t_single:6.2f} s")
        return 0
    rate = counts["imu_messages"] / t_write
    print(f"tlog      write_tlog {t_write:6.2f} s ({rate / 1e6:.2f} M IMU messages/s, {size / 1e6:.1f} MB, "
          f"{counts['heartbeats']} HEARTBEAT) | write_imu_tlog x3 {t_single:6.2f} s | ratio {t_write / t_single:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
