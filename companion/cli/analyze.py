"""``companion analyze``: overlapping Allan deviation with 95 % intervals and the fitted noise terms, per IMU
stream and axis, as a table in datasheet units, a JSON report (SI), a plot and a Kalibr imu.yaml."""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from companion import units
from companion.allan.adev import cluster_sizes
from companion.allan.confidence import adev_ci, edf_model, edf_simple
from companion.allan.lsb import lsb_report
from companion.allan.pooled import pooled_cluster_sizes, pooled_edf, pooled_oavar
from companion.allan.terms import PARAMS
from companion.cli.output import to_json, write_text
from companion.errors import CompanionError
from companion.samples import ACCEL_AXES, AXES, GYRO_AXES

DESCRIPTION = """\
Post-flight noise analysis. For every IMU stream of SOURCE (a .tlog, an ArduPilot DataFlash .bin, a PX4
.ulg, a CSV time_s,gx,gy,gz,ax,ay,az in rad/s and m/s^2 -- each optionally .gz -- or a connection string
listened to for --duration s) and every axis: the overlapping
Allan deviation with 95 % confidence intervals (EDF from the fitted noise model), and an automatic
weighted fit of the IEEE 952 terms (white noise N, bias instability B, rate random walk K; quantization Q,
ramp R and a Gauss-Markov term only when the data demand them), each with a 95 % interval.
Only the still parts are analysed: the log's armed state (DataFlash EV/ARM, ULog vehicle_status) and a
motion detector over the accelerometers and gyros of every IMU pick the still segments, and the Allan
variance is pooled over them (no cluster crosses a gap); the report says what was used and what was left
out. --start/--end restrict the time, --all skips the selection. A low-pass filter of the logged data
(INS_GYRO_FILTER, IMU_GYRO_CUTOFF, or a roll-off seen in the data) is kept out of the fit, so it never
becomes bias instability. A stream slower than 10 Hz or shorter than 60 s gets a warning and no Kalibr
file (unless --force). Gyro in deg/sqrt(h), deg/h, deg/h^1.5;
accel in m/s/sqrt(h), mg, m/s/h^1.5. For int16 messages the contribution of the 1-LSB rounding to N is
reported (and whether the data are dithered at all). Method: docs/analysis.md.
"""

EPILOG = """\
examples:
  companion analyze tlogs/sample.tlog --plot adev.png
  companion analyze flight.tlog --json report.json --kalibr imu.yaml
  companion analyze imu.csv.gz --taus log:10 --axes gx,gy,gz
  companion analyze imu.csv --taus 0.1,1,10,100          cluster times in seconds
  companion analyze flight.tlog --online --json r.json    offline and online estimates side by side
  companion analyze 00000042.BIN --plot adev.png          every IMU of an ArduPilot log, still parts only
  companion analyze before.bin after.bin --plot cmp.png   two logs overlaid in one figure
  companion analyze log.ulg --start 10 --end 95           a time window chosen by hand (still selection inside)
  companion analyze bench.csv --all                       no still selection

--taus: octave (1, 2, 4 ... samples), decade (1, 2, 4, 10, 20, 40 ...), all, log:N (N per decade), or a
comma list of seconds. The fit always uses octave-spaced points with their full covariance; --taus
chooses what the table/JSON/plot show.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("analyze", help="Allan deviation, fitted noise terms with 95 %% intervals, plot, JSON",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", nargs="+",
                   help=".tlog, DataFlash .bin, PX4 .ulg, .csv (each optionally .gz), or a connection string "
                        "(with --duration); several files are analysed one after the other (one plot overlays them)")
    p.add_argument("--json", metavar="OUT", help="write the report as JSON (SI units)")
    p.add_argument("--plot", metavar="PNG", help="write the Allan deviation plot (one file per stream if several)")
    p.add_argument("--kalibr", metavar="YAML", help="write a Kalibr imu.yaml (noise densities and random walks)")
    p.add_argument("--taus", default="octave", help="octave|decade|all|log:N|comma list of seconds (default octave)")
    p.add_argument("--axes", default=",".join(AXES), help="axes to analyse (default gx,gy,gz,ax,ay,az)")
    p.add_argument("--duration", type=float, default=None, help="seconds to listen on a live link")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column evidently in ms/us is refused)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--start", type=float, default=None, metavar="S",
                   help="analyse only from this time (seconds, the log's own clock as inspect shows it)")
    p.add_argument("--end", type=float, default=None, metavar="S", help="analyse only up to this time")
    p.add_argument("--all", action="store_true", dest="use_all",
                   help="no still-segment selection: every contiguous segment between --start and --end")
    p.add_argument("--min-still", type=float, default=10.0, metavar="S",
                   help="shortest still stretch used (default 10 s)")
    p.add_argument("--force", action="store_true",
                   help="write the Kalibr file even for a stream slower than 10 Hz or shorter than 60 s")
    p.add_argument("--online", action="store_true",
                   help="also run the online estimator (octave bank, model chosen from the data, docs/online.md) "
                        "over each axis, the same report as `companion run`: JSON key 'online' per axis (terms with "
                        "'bound': true for 95 %% upper bounds), table row 'online' ('< x' = bound)")
    p.set_defaults(func=run)


def parse_taus(spec: str, n: int, rate_hz: float):
    """--taus to cluster sizes m (samples) for ``n`` samples; seconds lists are rounded to whole samples."""
    spec = spec.strip()
    if spec in ("octave", "decade", "all") or spec.startswith("log:"):
        try:
            return cluster_sizes(n, spec)
        except ValueError as exc:
            raise CompanionError(str(exc)) from None
    try:
        secs = [float(s) for s in spec.split(",") if s.strip()]
    except ValueError:
        raise CompanionError(f"bad --taus {spec!r}: expected octave, decade, all, log:N or seconds like 0.1,1,10") from None
    if not secs or any(not (s > 0 and math.isfinite(s)) for s in secs):
        raise CompanionError(f"bad --taus {spec!r}: cluster times must be positive seconds")
    return cluster_sizes(n, np.maximum(np.round(np.array(secs) * rate_hz), 1).astype(np.int64))


def taus_beyond(spec: str, n: int, rate_hz: float) -> list[float]:
    """The cluster times (s) of a --taus seconds list that a record of ``n`` samples cannot reach
    (overlapping ADEV needs m <= n/2); [] for octave/decade/all/log:N."""
    spec = spec.strip()
    if spec in ("octave", "decade", "all") or spec.startswith("log:"):
        return []
    try:
        secs = [float(x) for x in spec.split(",") if x.strip()]
    except ValueError:
        return []  # parse_taus gives the error
    return [x for x in secs if math.isfinite(x) and x > 0 and max(round(x * rate_hz), 1) > n // 2]


def analyze_axis(y, rate_hz: float, taus="octave", lsb: float | None = None, effects=None, level: float = 0.95,
                 segments=None, tau_min: float = 0.0) -> dict:
    """Allan analysis of one axis (SI rate samples): the JSON ``axes`` entry.

    Keys: ``tau``, ``adev``, ``adev_lo``, ``adev_hi`` (``level`` interval, EDF from the fitted model),
    ``terms`` (fitted, each with ``ci95``), ``status`` ("ok", "constant", "too_short", "absent"), ``fit``
    (chi2, dof, criterion, ``tau_min``), ``quantization`` (LSB contribution, or None when the format has none).
    ``taus``: a --taus string or an array of cluster sizes m. ``segments``: a list of contiguous pieces
    (still segments) analysed with the pooled AVAR (:mod:`companion.allan.pooled`) instead of ``y``.
    ``tau_min``: cluster times below it are left out of the fit (a known low-pass filter's roll-off;
    a roll-off is also detected from the data, :func:`rolloff_tau`).
    """
    pieces = [np.asarray(y, dtype=float)] if segments is None else [np.asarray(p, dtype=float) for p in segments]
    out = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [], "status": "ok",
           "fit": None, "quantization": None}
    if pieces and all(p.shape[0] and np.all(np.isnan(p)) for p in pieces):
        out["status"] = "absent"
        out["note"] = "this source does not carry this sensor"
        return out
    pieces = [p[np.isfinite(p)] for p in pieces]
    pieces = [p for p in pieces if p.shape[0] >= 8]
    n = int(sum(p.shape[0] for p in pieces))
    if n < 8:
        out["status"] = "too_short"
        out["note"] = f"only {n} samples"
        return out
    allv = np.concatenate(pieces)
    if np.all(allv == allv[0]):
        out["status"] = "constant"
        out["note"] = "all samples equal (" + ("all zero" if allv[0] == 0 else f"{allv[0]:g}") + "): no noise to analyse"
        return out
    from companion.allan.fit import fit_avar  # scipy.optimize/stats: only where a fit runs (issue 14)

    lengths = [int(p.shape[0]) for p in pieces]
    pooled = len(pieces) > 1
    m_fit = pooled_cluster_sizes(lengths, "octave")
    tau_f, avar_f, m_fit, counts = pooled_oavar(pieces, rate_hz, m=m_fit)
    detected = rolloff_tau(tau_f, avar_f) if rate_hz >= MIN_RATE_HZ else 0.0
    cut = max(float(tau_min or 0.0), detected)
    why = "from the log's filter parameter" if (tau_min or 0.0) >= detected else "detected in the data"
    keep = tau_f >= cut * (1 - 1e-9)
    short_note = None
    if keep.sum() < 3:  # too short a record to leave the roll-off out: fit everything, and say so
        if cut > 0 and tau_f.shape[0]:
            short_note = (f"the record is too short to leave the low-pass roll-off (below {cut:.3g} s) out of the "
                          "fit: N may read low")
        keep = np.ones_like(keep)
    edf0 = np.array([edf_simple(int(c) + 2 * int(mm), mm, 0) for c, mm in zip(counts[keep], m_fit[keep])])
    fit = fit_avar(tau_f[keep], avar_f[keep], edf0, effects=effects, n=n, rate_hz=rate_hz, m=m_fit[keep],
                   level=level, segments=lengths if pooled else None)
    from companion.estimators.report import bounds_for_fit

    # effects the fit left out (N, B, K): their 95 % upper bound, as the online report gives it (issue 13)
    bounds = bounds_for_fit(fit, tau_f[keep], avar_f[keep], np.maximum(edf0, 0.5), rate_hz, n)
    m = parse_taus(taus, max(lengths), rate_hz) if isinstance(taus, str) else cluster_sizes(max(lengths), taus)
    tau, avar, m, _ = pooled_oavar(pieces, rate_hz, m=m)
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in fit.terms]
    simple = np.array([edf_simple(max(lengths) + 1, mm, 0) for mm in m])
    if plain:
        edf = pooled_edf(plain, m, lengths, rate_hz) if pooled else edf_model(plain, m, n, rate_hz)
    else:
        edf = simple
    edf = np.where(np.isfinite(edf) & (edf > 0), edf, simple)
    adev = np.sqrt(avar)
    lo, hi = adev_ci(adev, edf, level)
    notes = list(fit.notes)
    terms = fit.terms
    if fit.model_error:
        terms, note = local_white_noise(terms, tau_f[keep], avar_f[keep], edf0, 1.0 / rate_hz)
        if note:
            notes.append(note)
    out.update(tau=tau.tolist(), adev=adev.tolist(), adev_lo=lo.tolist(), adev_hi=hi.tolist(),
               terms=terms, bounds=bounds, edf=edf.tolist(),
               fit={"chi2": fit.chi2, "dof": fit.dof, "criterion": fit.criterion, "score": fit.score,
                    "model_error": fit.model_error, "tau_min": float(tau_f[keep][0]) if keep.any() else None,
                    "points": int(keep.sum()), "notes": notes, "segments": len(pieces)})
    if short_note:
        out["fit"]["notes"].append(short_note)
    if cut > 0 and (~keep).any():
        out["fit"]["notes"].append(f"cluster times below {tau_f[keep][0]:.3g} s left out of the fit (low-pass "
                                   f"roll-off, {why})")
    N = next((t["N"] for t in terms if t["effect"] == "white_noise"), None)
    out["quantization"] = lsb_report(pieces[int(np.argmax(lengths))], rate_hz, lsb, N)
    return out


def rolloff_tau(tau, avar, drop: float = 0.95) -> float:
    """Shortest cluster time not bent down by a low-pass filter, detected from the data: AVAR x tau of a
    white-noise region is flat; a filter makes it smaller at the shortest taus. The reference is the median
    of AVAR x tau over the 3rd-6th octave points; leading points below ``drop`` x that are left out.
    Returns 0 when nothing is bent (or too few points to tell)."""
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    if tau.shape[0] < 7:
        return 0.0
    r = avar * tau
    ref = float(np.median(r[3:7]))
    if not (ref > 0):
        return 0.0
    k = 0
    while k < 3 and r[k] < drop * ref:
        k += 1
    return float(tau[k]) if k else 0.0


def filter_tau(cutoff_hz: float | None, rate_hz: float) -> float:
    """Cluster time from which a 2-pole low-pass filter at ``cutoff_hz`` bends AVAR by < 2 %.

    Simulated (white noise at 1 kHz through a 2-pole Butterworth, logged at the stream's rate): AVAR x tau
    is 1 - 0.14 / (f_c tau), so tau >= 7 / f_c. When the log samples slower than 2.5 f_c the decimation
    leaves the samples nearly white (50 Hz logging of a 20 Hz filter: -3 % at 2 samples, -1 % at 3): 3 samples.
    """
    if not cutoff_hz or cutoff_hz <= 0 or not rate_hz or rate_hz <= 0:
        return 0.0
    if rate_hz <= 2.5 * cutoff_hz:
        return 3.0 / rate_hz
    return 7.0 / cutoff_hz


def local_white_noise(terms: list, tau, avar, edf, tau0: float, share: float = 0.5):
    """N from a local weighted fit of the white-noise region, for a fit with model misfit.

    Under misfit the global fit trades the short-tau points, where the data are most precise, for a bump
    elsewhere. The white-noise region is the run of cluster times from 10 tau0 (clear of a sensor's internal
    filter, output lines and quantisation at the first few samples) on which white noise makes at least
    ``share`` of the fitted model. On it N^2 is refitted with the other fitted terms held fixed (weighted
    least squares of a - other = N^2 / tau, weights w = EDF / (2 a^2)):

        N^2 = sum w (a - other) / tau / sum w / tau^2.

    Its interval is the global one scaled by the ratio. Returns (terms, note or None).
    """
    from companion.allan.terms import avar_term

    wn = next((t for t in terms if t["effect"] == "white_noise"), None)
    if wn is None:
        return terms, None
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in terms]
    tau = np.asarray(tau, dtype=float)
    white = avar_term({"effect": "white_noise", "N": wn["N"]}, tau)
    total = sum(avar_term(t, tau) for t in plain)
    frac = white / np.where(total > 0, total, 1.0)
    ok = (frac >= share) & (tau >= 10.0 * tau0 * (1 - 1e-9))
    idx = np.flatnonzero(ok)
    if idx.shape[0] < 2:
        return terms, None
    stop = idx[0]
    while stop + 1 < tau.shape[0] and ok[stop + 1]:
        stop += 1
    sel = np.arange(idx[0], stop + 1)
    if sel.shape[0] < 2:
        return terms, None
    a, tt, e = np.asarray(avar)[sel], tau[sel], np.asarray(edf)[sel]
    other = (total - white)[sel]
    w = e / (2.0 * a**2)
    n2 = float(np.sum(w * (a - other) / tt) / np.sum(w / tt**2))
    if not n2 > 0:
        return terms, None
    N = math.sqrt(n2)
    ratio = N / wn["N"]
    if abs(ratio - 1) < 1e-4:
        return terms, None
    new = []
    for t in terms:
        if t is wn:
            t = dict(t)
            t["N"] = N
            t["ci95"] = {"N": [c * ratio for c in wn["ci95"]["N"]]}
        new.append(t)
    return new, (f"N from a local weighted fit of the white-noise region ({tt[0]:.3g}-{tt[-1]:.3g} s) because "
                 f"the model misfits: the global fit gave {100 * (1 / ratio - 1):+.1f} %")


class Progress:
    """A one-line progress bar on stderr (only on a terminal, only for long inputs)."""

    def __init__(self, total: int, enabled: bool):
        self.total, self.done = max(total, 1), 0
        self.enabled = enabled and sys.stderr.isatty()
        self.t0 = time.monotonic()

    def step(self, label: str):
        self.done += 1
        if self.enabled:
            k = int(30 * self.done / self.total)
            sys.stderr.write(f"\ranalyze [{'#' * k}{'.' * (30 - k)}] {self.done}/{self.total} {label:<28}")
            sys.stderr.flush()

    def close(self):
        if self.enabled:
            sys.stderr.write(f"\r{' ' * 80}\r")
            sys.stderr.flush()


MIN_RATE_HZ = 10.0  # below: the Allan curve starts too late for N (warning, no Kalibr file without --force)
MIN_SECONDS = 60.0  # below: too few clusters for a usable N (same)


def analyze_stream(stream, axes, taus, progress=None, online=False, ranges=None, filters=None) -> dict:
    """The JSON ``streams`` entry of one :class:`companion.samples.ImuStream`.

    ``ranges``: index ranges to analyse (the still segments, pooled); None: the longest segment.
    ``filters``: {"gyro": Hz, "accel": Hz} low-pass cut-offs of the logged data (their roll-off is kept out
    of the fit). The entry carries ``warnings`` (rate < 10 Hz, < 60 s analysed) and the stream's timing.
    """
    if ranges is None:
        ranges = [stream.longest_segment()] if stream.samples else []
    rate = float(stream.rate_hz)
    used = sum(b - a for a, b in ranges)
    secs = sum(float(stream.t[b - 1] - stream.t[a]) + (1.0 / rate if rate > 0 else 0.0) for a, b in ranges if b > a)
    t = stream.timing
    entry = {"message": stream.key.message, "instance": stream.key.instance, "sysid": stream.key.sysid,
             "compid": stream.key.compid, "rate_hz": rate, "samples": int(used), "duration_s": float(secs),
             "segments": len(stream.segments) or 1, "still_segments": len(ranges),
             "ranges_s": [[float(stream.t[a]), float(stream.t[b - 1])] for a, b in ranges if b > a],
             "timing": {"gaps": t.gaps, "duplicates": t.duplicates, "backwards": t.backwards, "resets": t.resets},
             "filters_hz": dict(filters or {}), "warnings": [], "axes": {}}
    if not (rate >= MIN_RATE_HZ):
        entry["warnings"].append(f"only {rate:.3g} Hz (< {MIN_RATE_HZ:g} Hz): the Allan curve starts at "
                                 f"{1 / rate if rate > 0 else float('inf'):.3g} s, N is aliased with every faster effect")
    if secs < MIN_SECONDS:
        entry["warnings"].append(f"only {secs:.0f} s analysed (< {MIN_SECONDS:g} s): too few clusters for a usable N")
    for axis in axes:
        lsb = stream.gyro_lsb if axis in GYRO_AXES else stream.accel_lsb
        fc = (filters or {}).get("gyro" if axis in GYRO_AXES else "accel")
        if not (rate > 0 and math.isfinite(rate)):
            entry["axes"][axis] = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [],
                                   "status": "too_short", "note": "no sample rate"}
        else:
            col = stream.axis(axis)
            entry["axes"][axis] = analyze_axis(None, rate, taus, lsb=lsb, segments=[col[a:b] for a, b in ranges],
                                               tau_min=filter_tau(fc, rate))
            if online and entry["axes"][axis]["status"] == "ok":
                from companion.estimators import online_terms

                a, b = max(ranges, key=lambda r: r[1] - r[0])
                y = col[a:b]
                entry["axes"][axis]["online"] = online_terms(y[np.isfinite(y)], rate)
        if progress:
            progress.step(f"{stream.key.message}[{stream.key.instance}] {axis}")
    return entry


def stream_filters(stream, meta: dict) -> dict:
    """Low-pass cut-offs (Hz) of a stream's logged data from the log's parameters (empty if unknown)."""
    params = (meta or {}).get("params") or {}
    msg = stream.key.message
    out = {}
    if meta.get("format") == "dataflash" and msg == "IMU":
        for k, p in (("gyro", "INS_GYRO_FILTER"), ("accel", "INS_ACCEL_FILTER")):
            if params.get(p):
                out[k] = float(params[p])
    elif meta.get("format") == "ulog" and msg in ("sensor_combined", "sensor_gyro", "vehicle_imu"):
        for k, p in (("gyro", "IMU_GYRO_CUTOFF"), ("accel", "IMU_ACCEL_CUTOFF")):
            if params.get(p):
                out[k] = float(params[p])
    return out


def _fmt(v: float) -> str:
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    return f"{v:.3g}" if 1e-3 <= abs(v) < 1e5 else f"{v:.2e}"


def format_term(t: dict, axis: str) -> str:
    """'B 28.4 [26.1, 31.0] deg/h' style text of a fitted term in datasheet units."""
    parts = []
    for p in PARAMS[t["effect"]]:
        v = units.to_datasheet(p, t[p], axis)
        s = f"{p} {_fmt(v)}"
        ci = t.get("ci95", {}).get(p)
        if ci:
            s += f" [{_fmt(units.to_datasheet(p, ci[0], axis))}, {_fmt(units.to_datasheet(p, ci[1], axis))}]"
        parts.append(s + " " + units.datasheet_unit(p, axis))
    return ", ".join(parts)


def format_table(report: dict) -> str:
    lines = []
    for st in report["streams"]:
        src = f"{st['source']}: " if len(report.get("sources", [])) > 1 and st.get("source") else ""
        tm = st.get("timing") or {}
        extra = ", ".join(f"{tm[k]} {k}" for k in ("gaps", "duplicates", "backwards", "resets") if tm.get(k))
        lines.append(f"{src}{st['message']}[{st['instance']}] sys{st['sysid']}/comp{st['compid']}: "
                     f"{st['samples']} samples at {st['rate_hz']:.4g} Hz, {st['duration_s']:.1f} s"
                     + (f" in {st['still_segments']} still segments" if st.get("still_segments", 1) > 1 else "")
                     + (f" ({extra} in the stream)" if extra else "")
                     + (f"; filter {', '.join(f'{k} {v:g} Hz' for k, v in st['filters_hz'].items())}"
                        if st.get("filters_hz") else ""))
        for w in st.get("warnings", []):
            lines.append(f"  WARNING: {w}")
        for group, names in (("gyro", GYRO_AXES), ("accel", ACCEL_AXES)):
            axes = [a for a in names if a in st["axes"]]
            if not axes:
                continue
            ref = axes[0]
            u = {p: units.datasheet_unit(p, ref) for p in ("N", "B", "K")}
            lines.append(f"  {group:<5} {'N [' + u['N'] + ']':<28}{'B [' + u['B'] + ']':<26}"
                         f"{'K [' + u['K'] + ']':<26}other terms / notes")
            for a in axes:
                r = st["axes"][a]
                if r["status"] == "absent":
                    continue
                if r["status"] != "ok":
                    lines.append(f"  {a:<5} {r['status']}: {r.get('note', '')}")
                    continue
                cells, other = {}, []
                for t in r["terms"]:
                    p = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}.get(t["effect"])
                    if p:
                        lo, hi = t["ci95"][p]
                        cells[p] = (f"{_fmt(units.to_datasheet(p, t[p], a))} "
                                    f"[{_fmt(units.to_datasheet(p, lo, a))}, {_fmt(units.to_datasheet(p, hi, a))}]")
                    else:
                        other.append(format_term(t, a))
                for t in r.get("bounds") or ():
                    p = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}.get(t["effect"])
                    if p and p not in cells:
                        cells[p] = f"< {_fmt(units.to_datasheet(p, t[p], a))}"
                if r.get("fit") and r["fit"].get("model_error"):
                    other.append(f"misfit: +{100 * r['fit']['model_error']:.0f} % model error")
                for n_ in (r.get("fit") or {}).get("notes", []):
                    if n_.startswith(("N from a local", "cluster times below", "the record is too short")):
                        other.append(n_)
                q = r.get("quantization")
                if q and q.get("note"):
                    other.append(q["note"])
                lines.append(f"  {a:<5} {cells.get('N', '-'):<28}{cells.get('B', '-'):<26}{cells.get('K', '-'):<26} "
                             + "; ".join(other))
                if r.get("online") is not None:
                    lines.append("  " + _online_row(r, a))
    return "\n".join(lines)


def _online_row(r: dict, a: str) -> str:
    """'online N 1.05 [1.04, 1.06] ... B < 31 ...': the online report (companion.estimators.report, the same
    text as `companion run`'s summary): resolved values with 95 % intervals, 95 % upper bounds as '< x'."""
    from companion.estimators.report import cell, extra_text

    cells = {p: cell(r["online"], p, a) for p in ("N", "B", "K")}
    return (f"{'online':<5} {cells['N']:<28}{cells['B']:<26}{cells['K']:<26} "
            + "; ".join(extra_text(r["online"], a)))


def kalibr_yaml(report: dict) -> str:
    """Kalibr imu.yaml from the longest IMU stream: the largest N and K over the three axes of each sensor.

    A K not found by the fit (no random-walk region within the record) is replaced by the upper bound
    sqrt(3 AVAR(tau_max) / tau_max) and said so in a comment.
    """
    st = max(report["streams"], key=lambda s: s["samples"])
    out = {}
    notes = []
    for sensor, axes in (("gyroscope", GYRO_AXES), ("accelerometer", ACCEL_AXES)):
        Ns, Ks = [], []
        for a in axes:
            r = st["axes"].get(a)
            if not r or r["status"] != "ok":
                continue
            terms = {t["effect"]: t for t in r["terms"]}
            if "white_noise" in terms:
                Ns.append(terms["white_noise"]["N"])
            if "random_walk" in terms:
                Ks.append(terms["random_walk"]["K"])
            elif r["tau"]:
                Ks.append(math.sqrt(3.0 * r["adev"][-1] ** 2 / r["tau"][-1]))
                notes.append(f"{a}: no random-walk region in the record; {sensor}_random_walk is an upper bound")
        out[f"{sensor}_noise_density"] = max(Ns) if Ns else 0.0
        out[f"{sensor}_random_walk"] = max(Ks) if Ks else 0.0
        if not Ns:
            notes.append(f"{sensor}: no usable axis; values 0")
    lines = ["# Kalibr IMU noise model written by `companion analyze` (continuous-time, SI):",
             "#   *_noise_density = N [rad/s/sqrt(Hz), m/s^2/sqrt(Hz)], *_random_walk = K [rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz)]",
             f"#   stream {st['message']}[{st['instance']}] sys{st['sysid']}, largest value over the axes"]
    lines += [f"# note: {n}" for n in notes]
    lines.append("rostopic: /imu0")
    lines.append(f"update_rate: {st['rate_hz']:.6g}")
    for k in ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
              "gyroscope_random_walk"):
        lines.append(f"{k}: {out[k]:.6e}")
    return "\n".join(lines) + "\n"


def analyze_source(spec, args, axes, progress_enabled=True) -> tuple[list[dict], dict]:
    """Load one source, select its still segments and analyse every IMU stream: (stream entries, summary).

    The summary holds the source, the inspect notes (the same sentences ``companion inspect`` prints) and
    the still selection (:func:`companion.sources.still.select_still`)."""
    from companion.cli.inspect import notes as inspect_notes
    from companion.sources import load
    from companion.sources.still import select_still

    res = load(spec, config=getattr(args, "config", None), duration=getattr(args, "duration", None),
               time_unit=getattr(args, "time_unit", None))
    streams = res.imu_streams()
    if isinstance(getattr(args, "taus", None), str):
        _report_taus_beyond(args.taus, streams)
    sel = select_still(streams, res.meta, start=getattr(args, "start", None), end=getattr(args, "end", None),
                       use_all=getattr(args, "use_all", False), min_segment_s=getattr(args, "min_still", 10.0))
    summary = {"source": str(spec), "notes": inspect_notes(res), "selection": sel.to_dict(),
               "format": res.meta.get("format", "tlog/csv/live"),
               "params": {k: v for k, v in (res.meta.get("params") or {}).items()
                          if k in ("INS_GYRO_FILTER", "INS_ACCEL_FILTER", "INS_FAST_SAMPLE", "INS_LOG_BAT_OPT",
                                   "INS_LOG_BAT_MASK", "IMU_GYRO_CUTOFF", "IMU_ACCEL_CUTOFF", "IMU_INTEG_RATE")}}
    if not sel.intervals:
        raise CompanionError(f"{spec}: {sel.notes[0] if sel.notes else 'no still data'} ({sel.describe()})")
    total = sum(s.samples for s in streams) * len(axes)
    progress = Progress(len(streams) * len(axes), enabled=progress_enabled and total > 2_000_000)
    entries = []
    try:
        for s in streams:
            ranges = sel.ranges(s)
            if not ranges:  # say so: a stream must never vanish from the table silently
                summary["notes"].append(f"{s.key.label()}: not analysed: {s.samples} samples, no still stretch of "
                                        "at least 16 samples in it (too short for any Allan estimate)")
                continue
            e = analyze_stream(s, axes, args.taus, progress, online=getattr(args, "online", False), ranges=ranges,
                               filters=stream_filters(s, res.meta))
            e["source"] = str(spec)
            entries.append(e)
    finally:
        progress.close()
    return entries, summary


def kalibr_blockers(report: dict) -> list[str]:
    """Why a Kalibr file would be wrong (warnings of the stream it would be written from)."""
    if not report["streams"]:
        return ["no stream analysed"]
    st = max(report["streams"], key=lambda s: s["samples"])
    return [f"{st['message']}[{st['instance']}]: {w}" for w in st.get("warnings", [])]


def run(args) -> int:
    from companion.cli.output import check_output_path, check_plot_path

    for opt, path in (("--json", args.json), ("--kalibr", args.kalibr)):  # outputs checked before the work
        if path:
            check_output_path(path, opt)
    if args.plot:
        check_plot_path(args.plot)
    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    bad = [a for a in axes if a not in AXES]
    if bad or not axes:
        raise CompanionError(f"bad --axes {args.axes!r}: expected a comma list of {', '.join(AXES)}")
    sources = args.source if isinstance(args.source, (list, tuple)) else [args.source]
    report = {"source": str(sources[0]) if len(sources) == 1 else ", ".join(map(str, sources)),
              "sources": [], "streams": []}
    failed = []
    for spec in sources:
        try:
            entries, summary = analyze_source(spec, args, axes, progress_enabled=not args.quiet)
        except CompanionError as exc:
            if len(sources) == 1:
                raise
            failed.append(str(exc))  # the other logs are still analysed; the exit status says it
            continue
        report["sources"].append(summary)
        report["streams"].extend(entries)
    if not report["streams"]:
        raise CompanionError("; ".join(failed) if failed else "no IMU stream analysed")
    report["failed_sources"] = failed
    for summary in report["sources"]:
        print(f"{summary['source']}: {summary['selection']['description']}")
        for n in summary["notes"]:
            print(f"note: {n}")
    report["warnings"] = [f"{st['message']}[{st['instance']}]: {w}" for st in report["streams"] for w in st["warnings"]]
    print(format_table(report))
    if args.json:
        write_text(args.json, to_json(report) + "\n", "JSON")
        print(f"wrote {args.json}")
    if args.plot:
        from companion.plots.adev_plot import plot_report

        for path in plot_report(report, args.plot):
            print(f"wrote {path}")
    if args.kalibr:
        blockers = kalibr_blockers(report)
        if blockers and not args.force:
            raise CompanionError(f"{args.kalibr} not written: {'; '.join(blockers)} (--force writes it anyway)")
        write_text(args.kalibr, kalibr_yaml(report), "Kalibr YAML")
        print(f"wrote {args.kalibr}")
    if failed:
        raise CompanionError(f"{len(failed)} of {len(sources)} sources not analysed: {'; '.join(failed)}")
    return 0


def _report_taus_beyond(spec: str, streams) -> None:
    """--taus cluster times beyond a record are reported (warning), or refused when none is reachable."""
    reachable = False
    for st in streams:
        a, b = st.longest_segment()
        rate = float(st.rate_hz)
        if not (rate > 0 and math.isfinite(rate)):
            continue
        beyond = taus_beyond(spec, b - a, rate)
        asked = taus_beyond(spec, 0, rate)  # every valid seconds value (none for octave etc.)
        if len(beyond) < len(asked) or not asked:
            reachable = True
        if beyond:
            longest = (b - a) // 2 / rate
            print(f"companion analyze: warning: --taus {', '.join(f'{x:g}' for x in beyond)} s beyond "
                  f"{st.key.label()}: its longest segment ({(b - a) / rate:.0f} s) reaches tau {longest:.4g} s; "
                  "not shown", file=sys.stderr)
    if streams and not reachable:
        raise CompanionError(f"--taus {spec}: every cluster time is beyond the record (overlapping Allan deviation "
                             "reaches half the longest gap-free segment)")
