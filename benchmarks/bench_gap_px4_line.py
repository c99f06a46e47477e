"""How much of the PX4 sample's gz gap at the shortest cluster time is the 116 Hz vibration line.

    companion gap ../shared/data/px4/pyulog_sample.ulg --datasheet MPU-6000 --axis gz --json px4_gz.json
    python benchmarks/bench_gap_px4_line.py px4_gz.json [--shared ../shared/data]

From the workflow's JSON (its still segments, rate and model after) and the log's ``sensor_combined``
(pyulog): the measured and modelled AVAR at tau0 and their difference, and per segment and gyro axis the
line's frequency and amplitude near 116 Hz (Hann-windowed FFT) and the AVAR a sampled line of that
amplitude adds at tau0, A^2 sin^2(pi f tau0) (at 2 tau0, near Nyquist, almost nothing).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from companion.gap.likelihood import model_avar  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json")
    ap.add_argument("--shared", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--band", default="110,122", help="where to look for the line (Hz)")
    a = ap.parse_args()
    from pyulog import ULog

    d = json.loads(Path(a.json).read_text())
    d = d["axes"][0] if "axes" in d else d
    rate, m = d["measured"]["rate_hz"], d["measured"]
    s0 = float(model_avar(d["terms_after"], np.array(m["tau"][:1]), rate)[0])
    a0 = m["adev"][0] ** 2
    print(f"{d['axis']} at tau0 {m['tau'][0] * 1e3:.2f} ms: measured AVAR {a0:.3e}, model after {s0:.3e}, excess "
          f"{a0 - s0:.3e} rad^2/s^2 (ADEV ratio {math.sqrt(a0 / s0):.3f})")
    sc = next(x for x in ULog(str(Path(a.shared) / "px4" / "pyulog_sample.ulg")).data_list
              if x.name == "sensor_combined")
    t = sc.data["timestamp"] / 1e6
    lo, hi = (float(x) for x in a.band.split(","))
    for k, axis in enumerate(("gx", "gy", "gz")):
        for t0, t1 in d["ranges_s"]:
            y = sc.data[f"gyro_rad[{k}]"][(t >= t0) & (t <= t1)]
            w = np.hanning(y.size)
            X = np.fft.rfft((y - y.mean()) * w)
            f = np.fft.rfftfreq(y.size, 1.0 / rate)
            band = (f > lo) & (f < hi)
            i = int(np.argmax(np.abs(X[band])))
            amp, fp = 2.0 * abs(X[band][i]) / w.sum(), f[band][i]
            print(f"  {axis} {t0:.1f}-{t1:.1f} s: line {fp:.2f} Hz, amplitude {amp:.3e} rad/s, AVAR at tau0 "
                  f"{amp ** 2 * math.sin(math.pi * fp / rate) ** 2:.3e}")


if __name__ == "__main__":
    main()
