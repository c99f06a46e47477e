"""What the slow wander on dronekit log171 IMU[0] gz is not: temperature, a ramp, or a motion of the vehicle.

    python benchmarks/bench_gap_log171_wander.py [--shared ../shared/data] [--blocks 8,11,16]

The gap workflow leaves G 2.47 on this axis (docs/gap.md): a rise of the Allan deviation at 5-10 s that no
candidate reaches at its level on the 33 s still segment. This prints, from the log itself (pymavlink's
DFReader, the reference reader, over the still segment 32.5-65.4 s the workflow used):

* the block means of gz with a straight line taken out, and their chi^2 per degree of freedom against the
  white level of the datasheet's N (the variance of an L-second mean of white rate noise of two-sided
  density N is N^2 / L; about 1 for white noise; chosen after looking, so a description, not a test);
* the temperature channel: its slope, its residual from a straight line per block (a temperature-driven rate
  follows T; T that only rises is a ramp), and the rate regressed on time and T together;
* a quadratic in time: where the hump peaks (a ramp has no peak);
* the third IMU of the same vehicle (IMU3, its warm-up taken out by a quadratic), regressed on IMU[0]'s
  block residuals: a rotation of the vehicle is in every IMU's body-frame rate (slope 1), a bias wander of
  one gyro in that gyro only (slope 0).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
N_DATASHEET = 6.17e-5  # MPU-6000, rad/s/sqrt(Hz), two-sided (companion/datasheets.yaml)
SEGMENT = (32.5, 65.4)  # the still segment the workflow uses (s of log time)


def read(path: Path) -> dict:
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(path))
    out: dict = {"IMU": [], "IMU3": []}
    while True:
        m = r.recv_msg()
        if m is None:
            break
        if m.get_type() in out:
            out[m.get_type()].append([m.TimeMS / 1000.0, m.GyrX, m.GyrY, m.GyrZ, m.Temp])
    return {k: np.array(v) for k, v in out.items()}


def block_residuals(a: np.ndarray, col: int, nb: int, deg: int):
    s = (a[:, 0] >= SEGMENT[0]) & (a[:, 0] <= SEGMENT[1])
    t, y = a[s, 0] - a[s, 0][0], a[s, col]
    edges = np.linspace(0.0, t[-1] + 1e-9, nb + 1)
    bm = np.array([y[(t >= edges[i]) & (t < edges[i + 1])].mean() for i in range(nb)])
    tc = 0.5 * (edges[:-1] + edges[1:])
    return bm - np.polyval(np.polyfit(tc, bm, deg), tc), edges[1] - edges[0], t, y, s


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--blocks", default="8,11,16")
    a = ap.parse_args()
    d = read(Path(a.shared) / "ardupilot" / "dronekit_log171.bin")
    mdeg = np.degrees(1.0) * 1e3
    _, _, t, gz, s = block_residuals(d["IMU"], 3, 11, 1)
    temp = d["IMU"][s, 4]
    line = np.polyfit(t, temp, 1)
    print(f"IMU[0] still segment {SEGMENT[0]}-{SEGMENT[1]} s: {t.size} samples; temperature {temp[0]:.2f} -> "
          f"{temp[-1]:.2f} C, slope {line[0]:.4f} K/s, residual from the line sd {np.std(temp - np.polyval(line, t)):.3f} K "
          f"(the channel's step {np.min(np.diff(np.unique(temp))):.4f} K)")
    X = np.column_stack([np.ones_like(t), t, temp])
    c = np.linalg.lstsq(X, gz * mdeg, rcond=None)[0]
    q = np.polyfit(t, gz * mdeg, 2)
    print(f"gz on time and T together: {c[1]:.3f} mdeg/s per s, {c[2]:.2f} mdeg/s per K; quadratic in time: peak "
          f"at {-q[1] / (2 * q[0]):.1f} s of {t[-1]:.1f} s (curvature {q[0]:.4f} mdeg/s/s^2)")
    for nb in (int(x) for x in a.blocks.split(",")):
        r0, L, *_ = block_residuals(d["IMU"], 3, nb, 1)
        r3, *_ = block_residuals(d["IMU3"], 3, nb, 2)
        tr = block_residuals(np.column_stack([d["IMU"][:, 0], d["IMU"][:, 4]]), 1, nb, 1)[0]
        sd0 = N_DATASHEET / np.sqrt(L)
        sd3 = np.std(np.diff(r3)) / np.sqrt(2.0)
        slope = float(np.sum(r0 * r3) / np.sum(r0 * r0))
        se = float(sd3 / np.sqrt(np.sum(r0 * r0)))
        print(f"{nb} blocks of {L:.2f} s: gz - line (mdeg/s) {' '.join(f'{v * mdeg:5.1f}' for v in r0)}; "
              f"chi^2/dof vs white {np.sum((r0 / sd0) ** 2) / (nb - 2):.2f}; T - line (mK) "
              f"{' '.join(f'{v * 1e3:4.0f}' for v in tr)}; IMU3 gz on IMU[0]'s residuals: slope {slope:.2f} +- {se:.2f} "
              f"(a vehicle rotation: 1, {abs(1 - slope) / se:.1f} sigma away)")


if __name__ == "__main__":
    main()
