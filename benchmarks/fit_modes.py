"""Modes of benchmarks/bench_fit.py for filtered, real and drawn data: `python -m benchmarks.bench_fit MODE`
(real, filtered, draws, short, plain, preset, gm, shape; its --help lists them).

real: every gyro axis of the real still stretches in ../shared/data through `companion analyze --online --json`
(the user's path), against an independent reference: the white-noise plateau of ADEV sqrt(tau), i.e. the
EDF-weighted mean of AVAR x tau over the longest run of octave points where it is flat (the earliest of equal
ones), starting at or after the first point that is no longer below the following ones (above the filter's corner)
nor, below 10 sample periods, more than 25 % above them (an output line near Nyquist lifts the first octaves). "Flat": every point within 2.5 standard deviations (white-noise EDF
of NIST SP 1065 Table 5, with a floor of 2 % of AVAR x tau, 1 % of ADEV sqrt(tau): on hours of 100 Hz data the
EDF alone would call a 1 % wiggle of a real sensor's curve a break) of the run's mean; at least 3 points, and
the corner within 100 sample periods, else "no plateau".
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.fit_draws import run_draws
from benchmarks.results import SHARED_DATA
from companion.allan.adev import cluster_sizes, oavar
from companion.allan.confidence import edf_simple
from companion.allan.fit import fit_avar
from companion.allan.terms import avar_white_noise

ROOT = Path(__file__).resolve().parent.parent
DATA = SHARED_DATA
RAD2DEG_SQRTH = 180.0 / math.pi * 60.0  # rad/s/sqrt(Hz) -> deg/sqrt(h)
RAD2DEG_H = 180.0 / math.pi * 3600.0

REAL = [
    ("ardupilot/dronekit_log171.bin", []),
    ("px4/pyulog_sample.ulg", []),
    ("px4/pyulog_sample_appended_multiple.ulg", []),
    ("px4/pyulog_sample_px4_events.ulg", []),
    ("adis16405/adis16405_imu1.csv.gz", []),
    ("adis16405/adis16405_imu2.csv.gz", []),
    ("adis16405/adis16405_imu3.csv.gz", []),
]


def plateau(tau, avar, n, rate_hz, k=2.5):
    """(N_ref, (tau_first, tau_last)) of the white-noise plateau, or (None, None). See the module docstring."""
    tau, avar = np.asarray(tau, float), np.asarray(avar, float)
    m = np.maximum(np.round(tau * rate_hz), 1)
    edf = np.maximum(np.array([edf_simple(n + 1, mm, 0) for mm in m]), 1.0)
    r = avar * tau
    rel = np.maximum(np.sqrt(2.0 / edf), 0.02)  # of AVAR x tau: 1 % of ADEV sqrt(tau)
    # corner: first point not significantly below the median of the next three (nor above it by > 25 %, a line's
    # lift, below 10 tau0; on a 30-s record a point 10 % above is noise)
    i0 = 0
    while i0 + 3 < len(r):
        med = np.median(r[i0 + 1:i0 + 4])
        if not (r[i0] < med * (1 - 2.0 * rel[i0]) or (r[i0] > med * (1 + max(2.0 * rel[i0], 0.25)) and m[i0] < 10)):
            break
        i0 += 1
    if m[i0] > 100:  # no corner within 100 sample periods: the curve rises throughout, no plateau
        return None, None
    best = None  # (points, -start, mean, start, stop): the longest flat run, the earliest of equal ones
    for s0 in range(i0, len(r)):
        if m[s0] > 100:
            break
        j, run = s0 + 1, None
        while j < len(r):
            w = edf[s0:j + 1]
            mean = float(np.sum(w * r[s0:j + 1]) / np.sum(w))
            if np.any(np.abs(r[s0:j + 1] - mean) > k * rel[s0:j + 1] * mean):
                break
            run = (j - s0 + 1, -s0, mean, s0, j)
            j += 1
        if run and (best is None or run[:2] > best[:2]):
            best = run
    if best is None or best[0] < 3:
        return None, None
    return math.sqrt(best[2]), (float(tau[best[3]]), float(tau[best[4]]))


def _val(terms, effect, p):
    for t in terms or ():
        if t["effect"] == effect:
            return t[p], t.get("ci95", {}).get(p), bool(t.get("bound"))
    return None, None, None


_LOG_SUFFIXES = (".bin", ".ulg", ".tlog", ".csv", ".csv.gz")


def _real_sources(args):
    """The shared recordings, then each further file named, or every log under each further folder named."""
    out = [] if "--no-shared" in args else [(DATA / rel, rel, extra) for rel, extra in REAL]
    for a in (a for a in args if a != "--no-shared"):
        p = Path(a)
        if not p.exists():
            raise SystemExit(f"bench_fit real: no such file or folder: {a}")
        files = sorted(f for f in p.rglob("*") if f.name.lower().endswith(_LOG_SUFFIXES)) if p.is_dir() else [p]
        out += [(f, f.name, []) for f in files]
    return out


def run_real(args):
    rows = []
    for path, rel_path, extra in _real_sources(args):
        if not path.exists():
            continue
        with tempfile.TemporaryDirectory() as d:
            out = Path(d) / "r.json"
            t0 = time.time()
            p = subprocess.run([sys.executable, "-m", "companion", "analyze", str(path), "--axes", "gx,gy,gz",
                                "--online", "--json", str(out), "--quiet"] + extra,
                               capture_output=True, text=True, cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
            if not out.exists():
                print(f"{rel_path}: rc {p.returncode}: {(p.stderr or p.stdout).strip().splitlines()[-1:]}")
                continue
            rep = json.loads(out.read_text())
        for st in rep["streams"]:
            for ax in ("gx", "gy", "gz"):
                a = st["axes"].get(ax) or {}
                if a.get("status") != "ok":
                    continue
                n, rate = int(st["samples"]), float(st["rate_hz"])
                tau, adev = np.array(a["tau"]), np.array(a["adev"])
                Nref, span = plateau(tau, adev**2, n, rate)
                # where the log gives the low-pass cut-off (not fitted), the filter-aware reference: the plateau
                # of AVAR x tau / s(tau), s the 2-pole filter's shape at that cut-off (1 far above the corner)
                flt = (a.get("fit") or {}).get("filter") or {}
                Naware = None
                if flt.get("source") == "log":
                    s_tau = avar_white_noise(tau, 1.0, flt["filter_hz"], flt.get("sample_hz")) * tau
                    Naware, _ = plateau(tau, adev**2 / s_tau, n, rate)
                N, ci, _ = _val(a["terms"], "white_noise", "N")
                Nb = next((b["N"] for b in a.get("bounds", []) if b["effect"] == "white_noise"), None)
                B, _, _ = _val(a["terms"], "bias_instability", "B")
                Bb = next((b["B"] for b in a.get("bounds", []) if b["effect"] == "bias_instability"), None)
                oN, _, oNb = _val(a.get("online"), "white_noise", "N")
                oB, _, oBb = _val(a.get("online"), "bias_instability", "B")
                rows.append(dict(src=f"{Path(rel_path).name} {st['message']}[{st['instance']}]", ax=ax,
                                 secs=st["duration_s"], Nref=Nref, Naware=Naware, span=span, N=N, ci=ci, Nbound=Nb, B=B, Bbound=Bb,
                                 oN=oN, oNb=oNb, oB=oB, oBb=oBb, filt=(a.get("fit") or {}).get("filter"),
                                 notes=(a.get("fit") or {}).get("notes", [])))
        print(f"# {rel_path}: {time.time() - t0:.0f} s", flush=True)
    hdr = (f"{'stream':<44}{'ax':>3}{'s':>6}  {'plateau':>8} {'span s':>13}  {'offline N [95 %]':>24} {'vs plat.':>8} "
           f"{'covers':>6}  {'online N':>9} {'vs off.':>8}  {'B off.':>8} {'B onl.':>8} {'vs off.':>8}  filter")
    print(hdr)
    for r in rows:
        c = RAD2DEG_SQRTH
        plat = f"{r['Nref'] * c:8.3f}" if r["Nref"] else "    none"
        span = f"{r['span'][0]:.3g}-{r['span'][1]:.3g}" if r["span"] else "-"
        if r["N"] is not None:
            off = f"{r['N'] * c:.3f} [{r['ci'][0] * c:.3f}, {r['ci'][1] * c:.3f}]"
            d = f"{100 * (r['N'] / r['Nref'] - 1):+7.1f}%" if r["Nref"] else "       -"
            cov = ("yes" if r["ci"][0] <= r["Nref"] <= r["ci"][1] else "NO") if r["Nref"] else "-"
        else:
            off = f"< {r['Nbound'] * c:.3f} (bound)" if r["Nbound"] else "-"
            d, cov = "       -", "-"
        if r["oN"] is not None:
            on = ("<" if r["oNb"] else " ") + f"{r['oN'] * c:.3f}"
            base = r["N"] if r["N"] is not None else r["Nbound"]
            do = f"{100 * (r['oN'] / base - 1):+7.1f}%" if base else "       -"
        else:
            on, do = "-", "-"
        bo = (f"{r['B'] * RAD2DEG_H:8.2f}" if r["B"] else (f"<{r['Bbound'] * RAD2DEG_H:7.2f}" if r["Bbound"] else "       -"))
        bn = (("<" if r["oBb"] else " ") + f"{r['oB'] * RAD2DEG_H:7.2f}") if r["oB"] else "       -"
        bref = r["B"] or r["Bbound"]
        db = f"{100 * (r['oB'] / bref - 1):+7.1f}%" if (r["oB"] and bref and bool(r["oBb"]) == (r["B"] is None)) else "       -"
        f = r["filt"]
        fs = (f"{f['filter_hz']:.3g} Hz{' 1-pole' if f.get('filter_order') == 1 else ''} ({f['source']})"
              if f else "none")
        aw = ""
        if r["Naware"]:
            aw = f"  filter-aware {r['Naware'] * c:.3f}"
            if r["N"] is not None:
                aw += (f" ({100 * (r['N'] / r['Naware'] - 1):+.1f} %, "
                       f"{'covers' if r['ci'][0] <= r['Naware'] <= r['ci'][1] else 'NOT covered'})")
            elif r["Nbound"]:
                aw += f" ({'bound holds' if r['Nbound'] >= r['Naware'] else 'BELOW the bound'})"
        print(f"{r['src']:<44}{r['ax']:>3}{r['secs']:6.0f}  {plat} {span:>13}  {off:>24} {d:>8} {cov:>6}  {on:>9} {do:>8}  "
              f"{bo} {bn} {db:>8}  {fs}{aw}")
    return rows


def run_filtered(args):
    """Coverage of N's 95 % interval on simulated filtered + decimated white noise (10 min records)."""
    from companion.sim.filtered_noise import filtered_white_noise, logged_white_level

    seeds = int(args[0]) if args else 100
    for fs, fc, samp in ((50.0, 20.0, "point"), (250.0, 30.0, "average"), (100.0, 20.0, "point")):
        n = int(fs * 600)
        m = cluster_sizes(n, "octave")
        edf = edf_simple(n + 1, m, 0)
        level = logged_white_level(1e-3, fs, fc, samp)
        res = {"log": [], "data": [], "none": []}
        found = 0
        t0 = time.time()
        for s in range(seeds):
            y = filtered_white_noise(n, 1e-3, fs, fc, samp, 5000 + s)
            tau, av = oavar(y, fs, m=m)[:2]
            for key, kw in (("log", dict(white_filter={"filter_hz": fc, "sample_hz": fs if samp == "point" else None},
                                         detect_filter=samp)),
                            ("data", dict(detect_filter=samp)), ("none", {})):
                fr = fit_avar(tau, av, edf, n=n, rate_hz=fs, m=m, **kw)
                t = fr.term("white_noise")
                lo, hi = t["ci95"]["N"]
                res[key].append((t["N"] / level - 1, lo <= level <= hi, len(fr.terms) - 1))
                if key == "data":
                    found += fr.filter is not None
        print(f"{samp} {fs:g} Hz, f_c {fc:g} Hz, {seeds} seeds x {n / fs:.0f} s ({time.time() - t0:.0f} s): "
              f"roll-off found in the data in {found}/{seeds}")
        for key, v in res.items():
            e = np.array([x[0] for x in v]) * 100
            print(f"   filter {key:<5} N error median {np.median(e):+.2f} %, max |.| {np.abs(e).max():.2f} %, "
                  f"coverage {100 * np.mean([x[1] for x in v]):.0f} %, extra terms in {sum(x[2] > 0 for x in v)}")


def run_plain(args):
    """Unfiltered white noise (+ a bias instability crossing it at 20 s) point-sampled at 50 Hz, analysed as
    ``companion analyze`` analyses a source without a cut-off (a CSV, a HIGHRES_IMU tlog): the roll-off looked
    for in the data (``detect_filter="point"``). How often a roll-off is claimed where there is none, N's error
    and the coverage of its 95 % interval, for ``seconds`` records (default 20, 60, 600)."""
    from companion.analysis.axis import analyze_axis
    from companion.estimators import make_estimator
    from companion.sim.synth import synthesize_axis

    seeds = int(args[0]) if args else 200
    lengths = [float(x) for x in args[1].split(",")] if len(args) > 1 else [20.0, 60.0, 600.0]
    fs, n_true = 50.0, 1e-3
    b_true = n_true / math.sqrt(0.4413 * 20.0)
    for secs in lengths:
        n = int(fs * secs)
        err, cover, claimed, t0 = [], 0, 0, time.time()
        on_off, on_cover, on_n = [], 0, 0
        for s in range(seeds):
            y = synthesize_axis([{"effect": "white_noise", "N": n_true}, {"effect": "bias_instability", "B": b_true}],
                                fs, n, np.random.default_rng(30_000 + s))
            a = analyze_axis(y, fs, sampling="point")  # what `companion analyze` reports, its rules on N included
            claimed += (a["fit"] or {}).get("filter") is not None
            t = next((x for x in a["terms"] if x["effect"] == "white_noise"), None)
            if t is None:
                continue
            err.append(t["N"] / n_true - 1)
            lo, hi = t["ci95"]["N"]
            cover += lo <= n_true <= hi
            # the online report (what `run` sends) on the same record
            est = make_estimator(rate_hz=fs, forgetting_s=None, sampling="point")
            est.update(y)
            w = next((x for x in est.terms(full=True) if x["effect"] == "white_noise" and not x.get("bound")), None)
            if w is not None:
                on_n += 1
                on_off.append(abs(w["N"] / t["N"] - 1))
                on_cover += w["ci95"]["N"][0] <= n_true <= w["ci95"]["N"][1]
        e = np.array(err) * 100
        d = np.array(on_off) * 100 if on_off else np.zeros(1)
        print(f"unfiltered white noise + B (crossing at 20 s), point samples at {fs:g} Hz, {seeds} x {secs:g} s "
              f"({time.time() - t0:.0f} s): roll-off claimed in {claimed}/{seeds}; N resolved in {len(e)}, error "
              f"median {np.median(e):+.2f} %, sd {np.std(e):.2f} %, coverage {cover}/{len(e)} "
              f"({100 * cover / max(len(e), 1):.1f} %); online: resolved in {on_n}, |online - offline| median "
              f"{np.median(d):.2f} %, max {d.max():.2f} %, coverage {on_cover}/{on_n} ({100 * on_cover / max(on_n, 1):.1f} %)")


def run_short(args):
    """What a short still window allows: the fit (the log's cut-off given, as for the copter's stills) and the
    plateau reference of ``real`` on the same simulated records, against the truth and against each other.
    White noise through the copter's filter (2-pole 20 Hz, point-sampled at 50 Hz), ``seconds`` long
    (default 33, the copter log's still window): how far apart two sound estimates of N are on such a record."""
    from companion.sim.filtered_noise import filtered_white_noise, logged_white_level

    seeds = int(args[0]) if args else 200
    secs = float(args[1]) if len(args) > 1 else 33.0
    fs, fc = 50.0, 20.0
    n = int(fs * secs)
    m = cluster_sizes(n, "octave")
    edf = edf_simple(n + 1, m, 0)
    level = logged_white_level(1e-3, fs, fc, "point")
    fit_e, plat_e, diff, cover, t0 = [], [], [], [], time.time()
    for s in range(seeds):
        y = filtered_white_noise(n, 1e-3, fs, fc, "point", 9000 + s)
        tau, av = oavar(y, fs, m=m)[:2]
        fr = fit_avar(tau, av, edf, n=n, rate_hz=fs, m=m, white_filter={"filter_hz": fc, "sample_hz": fs},
                      detect_filter="point")
        t = fr.term("white_noise")
        ref, _ = plateau(tau, av, n, fs)
        if t is None or ref is None:
            continue
        fit_e.append(t["N"] / level - 1)
        plat_e.append(ref / level - 1)
        diff.append(t["N"] / ref - 1)
        lo, hi = t["ci95"]["N"]
        cover.append(lo <= ref <= hi)
    fit_e, plat_e, diff = (np.array(v) * 100 for v in (fit_e, plat_e, diff))
    print(f"white noise through 2-pole {fc:g} Hz, point-sampled at {fs:g} Hz, {len(diff)} of {seeds} records x "
          f"{secs:g} s ({time.time() - t0:.0f} s)")
    for name, e in (("fit vs truth", fit_e), ("plateau vs truth", plat_e), ("fit vs plateau", diff)):
        print(f"   {name:<17} sd {np.std(e):.2f} %, |.| median {np.median(np.abs(e)):.2f} %, 95th pct "
              f"{np.percentile(np.abs(e), 95):.2f} %, beyond 3 % in {100 * np.mean(np.abs(e) > 3):.0f} %")
    print(f"   fit's 95 % interval covers the plateau in {100 * np.mean(cover):.0f} %")


def run_shape(args):
    """A roll-off of another shape than the log's: ``shape [seeds=40] [seconds=20,60,120] [log=5|none]``.
    White noise through a 2-pole 8.4 Hz filter (4e-4 rad/s/sqrt(Hz) before it) plus a Gauss-Markov process
    (sigma 7.4e-3 rad/s, tau_c 73 ms), point samples at 50 Hz, the log saying 5 Hz (a 20-s still of a 2014
    MPU-6000 rover log, gz, looks like this): the Gauss-Markov process is white noise through a first-order
    low-pass, its long-tau level the plateau of ADEV sqrt(tau) above the roll-off. N and its 95 % interval
    against that level, and which shape the fit used. ``none``: no cut-off from a log (a tlog, a CSV), the
    roll-off left to the data alone."""
    from collections import Counter

    from companion.sim.filtered_noise import filtered_white_noise, logged_white_level
    from companion.sim.synth import synthesize_axis

    seeds = int(args[0]) if args else 40
    lengths = [float(x) for x in args[1].split(",")] if len(args) > 1 else [20.0, 60.0, 120.0]
    log = None if len(args) > 2 and args[2] == "none" else float(args[2]) if len(args) > 2 else 5.0
    fs, n_w, fc_w, sigma, tau_c = 50.0, 4e-4, 8.4, 7.4e-3, 0.073
    phi = math.exp(-1.0 / (fs * tau_c))
    level = math.sqrt(logged_white_level(n_w, fs, fc_w) ** 2 + sigma**2 / fs * (1 + phi) / (1 - phi))
    print(f"white noise through 2-pole {fc_w:g} Hz + Gauss-Markov {sigma:g} rad/s / {tau_c:g} s at {fs:g} Hz, "
          + (f"the log saying {log:g} Hz" if log else "no cut-off from a log")
          + f"; long-tau white level {level * RAD2DEG_SQRTH:.2f} deg/sqrt(h); {seeds} seeds per length")
    for secs in lengths:
        n = int(fs * secs)
        m = cluster_sizes(n, "octave")
        edf = edf_simple(n + 1, m, 0)
        ratio, cover, kinds, t0 = [], 0, Counter(), time.time()
        for s in range(seeds):
            y = filtered_white_noise(n, n_w, fs, fc_w, "point", 500 + s) + synthesize_axis(
                [{"effect": "gauss_markov", "sigma": sigma, "tau_c": tau_c}], fs, n, np.random.default_rng(900 + s))
            tau, av = oavar(y, fs, m=m)[:2]
            fr = fit_avar(tau, av, edf, n=n, rate_hz=fs, m=m, detect_filter="point",
                          white_filter={"filter_hz": log, "sample_hz": fs} if log else None)
            f = fr.filter or {}
            kinds[(f"{f.get('filter_order', 2)}-pole ({f.get('source')})" if f else "no filter")
                  + "".join(f" + {t['effect']}" for t in list(fr.terms) + list(fr.nuisance)
                            if t["effect"] != "white_noise")] += 1
            t = fr.term("white_noise")
            if t is None:
                continue
            ratio.append(t["N"] / level)
            cover += t["ci95"]["N"][0] <= level <= t["ci95"]["N"][1]
        print(f"  {secs:g} s ({time.time() - t0:.0f} s): N resolved in {len(ratio)}/{seeds}, N / level median "
              f"{np.median(ratio):.3f} (5-95 % {np.percentile(ratio, 5):.2f}-{np.percentile(ratio, 95):.2f}); "
              f"95 % interval covers it in {cover}/{len(ratio)}; models: "
              + ", ".join(f"{k} {v}" for k, v in kinds.most_common()))


def preset_white_level(preset: dict, imu: int, axis: str) -> float:
    """The white level N of the logged gyro samples of a realistic preset (no fit involved): the model's N
    times the IMU's noise gain, plus the sensor's LSB rounding (Delta^2 / 12 per sensor sample, white at the
    sensor rate: two-sided PSD Delta^2 / (12 fs)), then through the preset's digital filter and decimation
    (:func:`companion.sim.realism.filtered_white_avar`, the analytic truth of that path) at a cluster time far
    above the filter's corner, where AVAR x tau is the logged white level."""
    from companion.sim.realism import filtered_white_avar

    r, model = preset["realism"], preset["model"]
    n_in = next(t["N"] for t in model.axes[axis] if t["effect"] == "white_noise") * r.imu_noise_gain[imu]
    n2 = n_in**2 + (r.gyro_lsb**2 / 12.0 / r.sensor_rate_hz if r.gyro_lsb else 0.0)
    big = 1e4
    return math.sqrt(float(filtered_white_avar(math.sqrt(n2), r, model.rate_hz, np.array([big]))[0]) * big)


def run_preset(args):
    """Coverage of N's 95 % interval on the realistic simulator's stills: ``preset [name=copter] [seeds=20]
    [seconds=60]``. Each seed: the preset's vehicle at rest (its IMUs, sensor rate, filter, decimation, LSB,
    timing, temperature rise, Gauss-Markov bias wander; no vibration on the ground, no IMU scale or alignment
    spread), every gyro axis analysed as ``companion analyze`` does (``analyze_axis`` with the preset's
    cut-off as the log's; offline fit and the online report), N compared with :func:`preset_white_level`."""
    from companion.analysis.axis import analyze_axis
    from companion.estimators import online_terms
    from companion.sim.preset import load_preset
    from companion.sim.vehicle import ImuSpread, VehicleSimulator

    name = args[0] if args else "copter"
    seeds = int(args[1]) if len(args) > 1 else 20
    secs = float(args[2]) if len(args) > 2 else 60.0
    pr = load_preset(name)
    r, model = pr["realism"], pr["model"]
    imus = int(pr["vehicle"].get("imus", 1))
    fs = float(model.rate_hz)
    samp = "average" if r.decimation == "average" else "point"
    wf = {"filter_hz": r.gyro_lpf_hz, "sample_hz": fs if samp == "point" else None} if r.gyro_lpf_hz else None
    rows, t0 = [], time.time()
    for seed in range(seeds):
        blk = VehicleSimulator(model, imus=imus, seed=seed, realism=r, spread=ImuSpread(scale=0.0,
                               misalignment_deg=0.0)).run(secs)
        for i in range(imus):
            for j, ax in enumerate(("gx", "gy", "gz")):
                truth = preset_white_level(pr, i, ax)
                y = blk.gyro[i, :, j]
                a = analyze_axis(y, fs, white_filter=wf, sampling=samp)
                wn = next((t for t in a["terms"] if t["effect"] == "white_noise"), None)
                on = next((t for t in online_terms(y, fs, filter_hz=r.gyro_lpf_hz, sampling=samp)
                           if t["effect"] == "white_noise"), None)
                rows.append((i, ax, truth, wn, on, seed, a["fit"]["notes"]))
    print(f"preset {name}: {seeds} seeds x {imus} IMUs x 3 gyro axes, {secs:g} s still at {fs:g} Hz "
          f"(filter {r.gyro_lpf_hz} Hz, {r.decimation}); {time.time() - t0:.0f} s")
    for label, k in (("offline", 3), ("online", 4)):
        res = [x for x in rows if x[k] is not None and not x[k].get("bound")]
        err = np.array([x[k]["N"] / x[2] - 1 for x in res]) * 100
        cov = sum(x[k]["ci95"]["N"][0] <= x[2] <= x[k]["ci95"]["N"][1] for x in res)
        bnd = [x for x in rows if x[k] is not None and x[k].get("bound")]
        held = sum(x[k]["N"] >= x[2] for x in bnd)
        print(f"  {label:8} resolved {len(res)}/{len(rows)}: N error median {np.median(err):+.2f} %, "
              f"|error| 95th pct {np.percentile(np.abs(err), 95):.2f} %, max {np.max(np.abs(err)):.2f} %; "
              f"95 % interval covers {cov}/{len(res)} ({100 * cov / max(len(res), 1):.1f} %); "
              f"bounds {len(bnd)}, above the truth {held}")
    worst = sorted((x for x in rows if x[3] is not None and not x[3].get("bound")),
                   key=lambda x: -abs(x[3]["N"] / x[2] - 1))[:3]
    for x in worst:
        lo, hi = (v / x[2] for v in x[3]["ci95"]["N"])
        print(f"  worst: seed {x[5]} IMU{x[0]} {x[1]}: N {x[3]['N'] / x[2]:.3f} x the truth [{lo:.3f}, {hi:.3f}]; "
              f"{'; '.join(x[6])[:300]}")
    for i in range(imus):
        sub = [x for x in rows if x[0] == i and x[3] is not None and not x[3].get("bound")]
        cov = sum(x[3]["ci95"]["N"][0] <= x[2] <= x[3]["ci95"]["N"][1] for x in sub)
        print(f"    IMU{i} offline: truth {sub[0][2] if sub else float('nan'):.3g} rad/s/sqrt(Hz), covers {cov}/{len(sub)}")


def run_gm(args):
    """Coverage of a Gauss-Markov term's 95 % intervals (sigma, tau_c) and of N's: white noise N = 1e-3
    rad/s/sqrt(Hz) plus a Gauss-Markov term, 50 Hz, ``gm [seeds=200]`` records in each of three cases (30 min,
    sigma 1e-3 rad/s, tau_c 20 s; 1 h, 5e-4, 10 s; 2 h, 3e-4, 30 s); a term the fit leaves out is not counted."""
    from companion.sim.synth import synthesize_axis

    seeds = int(args[0]) if args else 200
    fs = 50.0
    for secs, sig, tc in ((1800.0, 1e-3, 20.0), (3600.0, 5e-4, 10.0), (7200.0, 3e-4, 30.0)):
        n = int(secs * fs)
        m = cluster_sizes(n, "octave")
        edf = edf_simple(n + 1, m, 0)
        terms = [{"effect": "white_noise", "N": 1e-3}, {"effect": "gauss_markov", "sigma": sig, "tau_c": tc}]
        found = c_s = c_t = c_n = 0
        t0 = time.time()
        for s in range(seeds):
            y = synthesize_axis(terms, fs, n, np.random.default_rng(7000 + s))
            tau, av = oavar(y, fs, m=m)[:2]
            fr = fit_avar(tau, av, edf, n=n, rate_hz=fs, m=m)
            w, g = fr.term("white_noise"), fr.term("gauss_markov")
            c_n += bool(w) and w["ci95"]["N"][0] <= 1e-3 <= w["ci95"]["N"][1]
            if g is None:
                continue
            found += 1
            c_s += g["ci95"]["sigma"][0] <= sig <= g["ci95"]["sigma"][1]
            c_t += g["ci95"]["tau_c"][0] <= tc <= g["ci95"]["tau_c"][1]
        print(f"{secs / 60:g} min, sigma {sig:g} rad/s, tau_c {tc:g} s ({time.time() - t0:.0f} s): Gauss-Markov found "
              f"{found}/{seeds}; 95 % intervals cover sigma {c_s}/{found} ({100 * c_s / max(found, 1):.1f} %), "
              f"tau_c {c_t}/{found} ({100 * c_t / max(found, 1):.1f} %), N {c_n}/{seeds}")


def main_mode(mode, args):
    from companion.errors import CompanionError

    try:
        {"real": run_real, "filtered": run_filtered, "draws": run_draws, "short": run_short, "plain": run_plain,
         "preset": run_preset, "gm": run_gm, "shape": run_shape}[mode](args)
    except (CompanionError, ValueError) as exc:  # a bad argument: one line, no traceback
        raise SystemExit(f"bench_fit {mode}: {exc} (usage: the module docstring of benchmarks/bench_fit.py)")
