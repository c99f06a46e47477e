"""Is the flat level of ADEV*sqrt(tau) the white level N? White noise of known N through an autopilot's real
signal path, many seeds.

Each chain is simulated sample by sample as the autopilot runs it, independently of the analysis' filtered-
white model (:mod:`companion.allan.filtered_white`): white noise at the sensor rate, a digital 2-pole
Butterworth at the sensor rate (:func:`scipy.signal.butter`, the bilinear biquad of ArduPilot's and PX4's
LowPassFilter2p), then logged either as the newest value every k-th sample (ArduPilot DataFlash ``IMU``,
``RAW_IMU``) or as the mean over each logged interval (PX4 ``sensor_combined``: delta angle / dt). The true
white level of the logged samples (the long-tau N^2 / tau, aliasing included) comes from the filter's impulse
response: N^2 = tau_log sum_l r(l k), r the sensor-rate autocovariance of the filtered noise (point
samples), or the input density itself (means).

Chains (the two real logs whose flat regions the real-log benchmark, :mod:`benchmarks.bench_white_level`,
flags with N 3.0-3.7 % above the raw level):

* ``ardupilot``: dronekit log171, IMU at 49.6 Hz for 33 s, INS_GYRO_FILTER 20 Hz run at 1 kHz, point-sampled;
  the flagged flat region 0.04-0.32 s;
* ``px4``: pyulog_sample.ulg, sensor_combined at 248.6 Hz for 59 s, the driver's 30 Hz 2-pole at 1 kHz,
  averaged; the flagged region 0.064-0.515 s.

Per chain and seed: the curve and the flat regions as ``bench_white_level`` finds them (its own rule, on the
curve ``companion.analysis.axis.analyze_axis`` prints), the raw level and the level with the known filter's
roll-off divided out, both against the true N; and the analysis' N (told the log's filter, as ``analyze``
is) against the truth, with its 95 % interval's coverage. ``--figure PNG`` draws ADEV*sqrt(tau) / N (mean and
2.5-97.5 % of the seeds) with the flagged range.

    python -m benchmarks.bench_white_chain [--seeds 100] [--untold] [--figure docs/img/white_chain.png]

``--untold`` also analyses each seed as ``analyze`` does a log without the filter's parameter (the data's own
roll-off).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

import numpy as np

from benchmarks import results


@dataclass(frozen=True)
class Chain:
    name: str
    sensor_hz: float
    filter_hz: float
    decim: int  #: sensor samples per logged sample
    sampling: str  #: "point" or "average"
    secs: float
    flagged: tuple  #: the tau range the real log's flat region spans (s)

    @property
    def log_hz(self) -> float:
        return self.sensor_hz / self.decim


CHAINS = {
    "ardupilot": Chain("ardupilot log171: 20 Hz 2-pole at 1 kHz, point-sampled at 50 Hz, 33 s",
                       1000.0, 20.0, 20, "point", 33.0, (0.04, 0.32)),
    "px4": Chain("px4 pyulog_sample: 30 Hz 2-pole at 1 kHz, averaged into 250 Hz, 59 s",
                 1000.0, 30.0, 4, "average", 59.0, (0.064, 0.52)),
}


def _ba(c: Chain):
    from scipy.signal import butter
    return butter(2, c.filter_hz / (c.sensor_hz / 2.0))


def true_level(c: Chain, N_in: float) -> float:
    """White level N of the logged samples for input density N_in (module docstring)."""
    if c.sampling == "average":
        return N_in
    from scipy.signal import lfilter
    b, a = _ba(c)
    imp = np.zeros(int(40 * c.sensor_hz / c.filter_hz) + 64 * c.decim)
    imp[0] = 1.0
    h = lfilter(b, a, imp)
    var = N_in**2 * c.sensor_hz  # per-sample variance of the white input
    r = np.array([var * np.dot(h[:h.size - m], h[m:]) for m in range(0, h.size // 2, c.decim)])
    return math.sqrt((r[0] + 2.0 * r[1:].sum()) / c.log_hz)


def simulate(c: Chain, N_in: float, rng) -> np.ndarray:
    """Logged rate samples of one record."""
    from scipy.signal import lfilter
    b, a = _ba(c)
    burn = int(20 * c.sensor_hz / c.filter_hz)
    n = int(c.secs * c.log_hz)
    x = rng.normal(0.0, N_in * math.sqrt(c.sensor_hz), burn + n * c.decim)
    y = lfilter(b, a, x)[burn:]
    if c.sampling == "point":
        return y[c.decim - 1::c.decim][:n]
    return y[:n * c.decim].reshape(n, c.decim).mean(axis=1)


def oadev_sqrt_tau(y, rate_hz, m) -> float:
    """Overlapping ADEV * sqrt(tau) at cluster size m (NIST SP 1065 eq. (14)), straight from the samples."""
    x = np.concatenate([[0.0], np.cumsum(y)]) / rate_hz
    tau = m / rate_hz
    d = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
    return math.sqrt(np.mean(d * d) / (2 * tau * tau) * tau)


@dataclass
class Draw:
    tau: np.ndarray
    s: np.ndarray  #: ADEV*sqrt(tau) / N_true (the analysis' curve)
    s_direct: np.ndarray  #: the same from :func:`oadev_sqrt_tau`
    regions: list  #: (tau_lo, tau_hi, raw level / N, corrected level / N)
    N: float  #: the analysis' N / N_true
    covered: bool
    ci: tuple  #: the analysis' 95 % interval of N / N_true
    untold: tuple | None = None  #: (N / N_true, interval covers) of the analysis not told the filter


def draw(c: Chain, seed: int, N_in: float = 1e-3, untold: bool = False) -> Draw:
    from benchmarks.bench_white_level import flat_regions
    from companion.allan.terms import avar_white_noise
    from companion.analysis.axis import analyze_axis

    truth = true_level(c, N_in)
    y = simulate(c, N_in, np.random.default_rng(seed))
    told = {"filter_hz": c.filter_hz, "sample_hz": c.log_hz if c.sampling == "point" else None}
    e = analyze_axis(y, c.log_hz, white_filter=told, sampling=c.sampling)
    tau, adev = np.asarray(e["tau"]), np.asarray(e["adev"])
    shape = avar_white_noise(tau, 1.0, **told) * tau  # the known chain's share of the white AVAR
    regs = []
    for i, j, level in flat_regions(e["tau"], e["adev"], e["adev_lo"], e["adev_hi"], e["edf"]):
        w = np.asarray(e["edf"][i:j + 1])
        corr = math.sqrt(float(np.sum(w * adev[i:j + 1] ** 2 * tau[i:j + 1] / shape[i:j + 1]) / np.sum(w)))
        regs.append((tau[i], tau[j], level / truth, corr / truth))
    wn = next(t for t in e["terms"] if t["effect"] == "white_noise")
    lo, hi = wn["ci95"]["N"]
    direct = np.array([oadev_sqrt_tau(y, c.log_hz, int(round(t * c.log_hz))) for t in tau])
    out = Draw(tau, adev * np.sqrt(tau) / truth, direct / truth, regs, wn["N"] / truth, lo <= truth <= hi,
               (lo / truth, hi / truth))
    if untold:
        # as analyze runs on a log without the filter's parameter: the data's own roll-off
        e = analyze_axis(y, c.log_hz, white_filter=None, sampling=c.sampling)
        wn = next((t for t in e["terms"] if t["effect"] == "white_noise"), None)
        if wn is not None:
            lo, hi = wn["ci95"]["N"]
            out.untold = (wn["N"] / truth, lo <= truth <= hi)
    return out


def _at_flagged(c: Chain, d: Draw):
    """The region spanning the flagged range (the widest one that contains its start), else None."""
    inside = [r for r in d.regions if r[0] <= c.flagged[0] * 1.05 and r[1] >= c.flagged[1] * 0.95]
    return max(inside, key=lambda r: r[1] / r[0]) if inside else None


def report(c: Chain, draws: list[Draw]) -> dict:
    from companion.allan.terms import avar_white_noise

    tau = draws[0].tau
    told = {"filter_hz": c.filter_hz, "sample_hz": c.log_hz if c.sampling == "point" else None}
    model = np.sqrt(avar_white_noise(tau, 1.0, **told) * tau)
    s = np.array([d.s for d in draws])
    sd = np.array([d.s_direct for d in draws])
    print(f"\n{c.name}: {len(draws)} seeds")
    print("  tau (s)      ADEV*sqrt(tau)/N: mean [2.5, 97.5 %] of seeds (direct OADEV mean)  analytic model")
    for k, t in enumerate(tau):
        if t > 4 * c.flagged[1]:
            break
        q = np.percentile(s[:, k], [2.5, 97.5])
        flag = "  <- flagged range" if c.flagged[0] * 0.95 <= t <= c.flagged[1] * 1.05 else ""
        print(f"  {t:8.4g}   {s[:, k].mean():.4f} [{q[0]:.4f}, {q[1]:.4f}] ({sd[:, k].mean():.4f})  "
              f"{model[k]:.4f}{flag}")
    at = [r for r in (_at_flagged(c, d) for d in draws) if r is not None]
    raw = np.array([r[2] for r in at])
    corr = np.array([r[3] for r in at])
    N = np.array([d.N for d in draws])
    cover = sum(d.covered for d in draws)
    out = {"raw": raw.mean() - 1, "corr": corr.mean() - 1, "N": N.mean() - 1, "cover": cover / len(draws)}
    print(f"  flat region over the flagged range found on {len(at)}/{len(draws)} seeds: raw level / N "
          f"{raw.mean():.4f} (sd {raw.std():.4f}); true N more than 3 % above the raw level on "
          f"{np.mean(raw < 1 / 1.03) * 100:.0f} % of seeds; with the chain's roll-off divided out "
          f"{corr.mean():.4f} (sd {corr.std():.4f})")
    both = [(d, r) for d in draws for r in [_at_flagged(c, d)] if r is not None]
    ok_raw = sum(abs(d.N / r[2] - 1) <= 0.03 for d, r in both)
    ok_corr = sum(abs(d.N / r[3] - 1) <= 0.03 for d, r in both)
    widest = [(d, max(d.regions, key=lambda r: (round(math.log2(r[1] / r[0]), 6), r[1]))) for d in draws
              if d.regions]

    def meets(d, lev):
        return abs(d.N / lev - 1) <= 0.03 and d.ci[0] <= lev <= d.ci[1]

    print(f"  the widest flat region of each seed (the one bench_white_level judges), on {len(widest)} seeds: the "
          f"analysis' N meets the target against its level with the roll-off divided out on "
          f"{sum(meets(d, r[3]) for d, r in widest)}, against its raw level on {sum(meets(d, r[2]) for d, r in widest)}")
    print(f"  the analysis' N (told the log's filter): N / true {N.mean():.4f} (sd {N.std():.4f}), 95 % interval "
          f"covers the truth on {cover}/{len(draws)} seeds; within 3 % of the raw level on {ok_raw}/{len(both)}, "
          f"of the corrected level on {ok_corr}/{len(both)}")
    un = [d.untold for d in draws if d.untold is not None]
    if un:
        v = np.array([u[0] for u in un])
        print(f"  the analysis not told the filter (the data's own roll-off), N resolved on {len(un)}/{len(draws)} "
              f"seeds: N / true {v.mean():.4f} (sd {v.std():.4f}), 95 % interval covers the truth on "
              f"{sum(u[1] for u in un)}/{len(un)}")
    return out


def figure(path: str, per_chain: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from companion.allan.terms import avar_white_noise

    fig, axes = plt.subplots(1, len(per_chain), figsize=(6 * len(per_chain), 4.2), squeeze=False)
    for ax, (c, draws) in zip(axes[0], per_chain.items()):
        tau = draws[0].tau
        keep = tau <= 8 * c.flagged[1]
        s = np.array([d.s for d in draws])[:, keep]
        t = tau[keep]
        told = {"filter_hz": c.filter_hz, "sample_hz": c.log_hz if c.sampling == "point" else None}
        ax.fill_between(t, *np.percentile(s, [2.5, 97.5], axis=0), alpha=0.25, label="2.5-97.5 % of seeds")
        ax.semilogx(t, s.mean(axis=0), "o-", label="mean of seeds")
        ax.semilogx(t, np.sqrt(avar_white_noise(t, 1.0, **told) * t), "k--", lw=1, label="filtered-white model")
        ax.axvspan(*c.flagged, color="orange", alpha=0.15, label="flagged flat region")
        for v in (1.0, 0.97, 1.03):
            ax.axhline(v, color="grey", lw=0.6 if v != 1 else 1.0, ls=":" if v != 1 else "-")
        ax.set_title(c.name, fontsize=9)
        ax.set_xlabel("tau (s)")
        ax.set_ylabel("ADEV*sqrt(tau) / true N")
        ax.set_ylim(0.75, 1.15)
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"\nfigure: {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--chain", choices=sorted(CHAINS), action="append")
    ap.add_argument("--figure", help="PNG of ADEV*sqrt(tau) / N per chain")
    ap.add_argument("--untold", action="store_true", help="also analyse each seed without the filter's parameter")
    args = results.parse_args(ap, {"seeds": 20}, argv)
    per_chain = {}
    for key in args.chain or sorted(CHAINS):
        c = CHAINS[key]
        print(f"{key}: true white level of the logged samples / input density = "
              f"{true_level(c, 1.0):.4f}")
        per_chain[c] = [draw(c, seed, untold=args.untold) for seed in range(args.seeds)]
        report(c, per_chain[c])
    if args.figure:
        figure(args.figure, per_chain)
    return 0


if __name__ == "__main__":
    sys.exit(results.run(main))
