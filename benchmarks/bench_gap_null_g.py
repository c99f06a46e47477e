"""The spread of the gap metric G when the model is right, for one record's length and rate: is a G above the
noise floor (2) on a short real record noise or a disagreement?

    python benchmarks/bench_gap_null_g.py --N 6.17e-5 --cutoff 20 --rate 49.6 --n 1631 --g 2.47

Simulates white noise N (rad/s/sqrt(Hz)) through the autopilot's two-pole low-pass at --cutoff (Hz), point-
sampled at --rate (the dronekit log171 gz model after the workflow by default), measures its Allan curve as the
workflow does and prints G's median, 95th and 99th percentiles and the share of draws with G >= --g; the same
for G over the cluster times the record resolves (tau <= a tenth of the record, as the workflow's
gap_after_resolved) and the share with that G >= --g-resolved, and the share above the noise floor (2) of each.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from companion.allan.fit import RESOLVE_RECORD_FACTOR  # noqa: E402
from companion.gap.compare import measure  # noqa: E402
from companion.gap.filtered import synthesize_filtered_white  # noqa: E402
from companion.gap.likelihood import Measured, gap_metric, model_avar  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--N", type=float, default=6.17e-5)
    ap.add_argument("--cutoff", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=49.6)
    ap.add_argument("--n", type=int, default=1631)
    ap.add_argument("--g", type=float, default=2.47)
    ap.add_argument("--g-resolved", type=float, default=1.96)
    ap.add_argument("--draws", type=int, default=400)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    terms = [{"effect": "white_noise", "N": a.N, "cutoff_hz": a.cutoff, "order": 2}]
    rng = np.random.default_rng(a.seed)
    G, Gr = [], []
    tau_max = a.n / a.rate / RESOLVE_RECORD_FACTOR
    for _ in range(a.draws):
        m = measure(synthesize_filtered_white(a.N, a.cutoff, a.rate, a.n, rng, oversample=16), a.rate)
        G.append(gap_metric(m, model_avar(terms, m.tau, a.rate)))
        k = m.tau <= tau_max * (1 + 1e-9)
        sub = Measured(tau=m.tau[k], avar=m.avar[k], m=m.m[k], nu=m.nu[k], rate_hz=m.rate_hz, n=m.n, nu_raw=m.nu_raw[k])
        Gr.append(gap_metric(sub, model_avar(terms, sub.tau, a.rate)))
    for name, g, lim, npts in (("G", np.array(G), a.g, len(m.tau)),
                               (f"G over tau <= {tau_max:.3g} s", np.array(Gr), a.g_resolved, int(k.sum()))):
        print(f"{a.draws} draws, {name} ({npts} octave points): median {np.median(g):.2f}, 95th percentile "
              f"{np.percentile(g, 95):.2f}, 99th {np.percentile(g, 99):.2f}; >= {lim:g} in {100 * np.mean(g >= lim):.1f} %, "
              f"> 2 in {100 * np.mean(g > 2):.1f} %")


if __name__ == "__main__":
    main()
