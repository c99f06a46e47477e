"""``companion analyze``: overlapping Allan deviation with 95 % intervals and the fitted noise terms, per IMU
stream and axis, as a table in datasheet units, a JSON report (SI), a plot and a Kalibr imu.yaml."""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from companion import units
from companion.allan.adev import cluster_sizes, oavar
from companion.allan.confidence import adev_ci, edf_model, edf_simple
from companion.allan.fit import fit_avar
from companion.allan.lsb import lsb_report
from companion.allan.terms import PARAMS
from companion.cli.output import to_json, write_text
from companion.errors import CompanionError
from companion.samples import ACCEL_AXES, AXES, GYRO_AXES

DESCRIPTION = """\
Post-flight noise analysis. For every IMU stream of SOURCE (a .tlog, a CSV time_s,gx,gy,gz,ax,ay,az in
rad/s and m/s^2, or a connection string listened to for --duration s) and every axis: the overlapping
Allan deviation with 95 % confidence intervals (EDF from the fitted noise model), and an automatic
weighted fit of the IEEE 952 terms (white noise N, bias instability B, rate random walk K; quantization Q,
ramp R and a Gauss-Markov term only when the data demand them), each with a 95 % interval.
The longest gap-free segment of each stream is analysed. Gyro in deg/sqrt(h), deg/h, deg/h^1.5;
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

--taus: octave (1, 2, 4 ... samples), decade (1, 2, 4, 10, 20, 40 ...), all, log:N (N per decade), or a
comma list of seconds. The fit always uses octave-spaced points with their full covariance; --taus
chooses what the table/JSON/plot show.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("analyze", help="Allan deviation, fitted noise terms with 95 %% intervals, plot, JSON",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", help=".tlog, .csv/.csv.gz, or a connection string (with --duration)")
    p.add_argument("--json", metavar="OUT", help="write the report as JSON (SI units)")
    p.add_argument("--plot", metavar="PNG", help="write the Allan deviation plot (one file per stream if several)")
    p.add_argument("--kalibr", metavar="YAML", help="write a Kalibr imu.yaml (noise densities and random walks)")
    p.add_argument("--taus", default="octave", help="octave|decade|all|log:N|comma list of seconds (default octave)")
    p.add_argument("--axes", default=",".join(AXES), help="axes to analyse (default gx,gy,gz,ax,ay,az)")
    p.add_argument("--duration", type=float, default=None, help="seconds to listen on a live link")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
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


def analyze_axis(y, rate_hz: float, taus="octave", lsb: float | None = None, effects=None, level: float = 0.95) -> dict:
    """Allan analysis of one axis (SI rate samples): the JSON ``axes`` entry.

    Keys: ``tau``, ``adev``, ``adev_lo``, ``adev_hi`` (``level`` interval, EDF from the fitted model),
    ``terms`` (fitted, each with ``ci95``), ``status`` ("ok", "constant", "too_short"), ``fit``
    (chi2, dof, criterion), ``quantization`` (LSB contribution, or None when the format has no LSB).
    ``taus``: a --taus string or an array of cluster sizes m.
    """
    y = np.asarray(y, dtype=float)
    n = int(y.shape[0])
    out = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [], "status": "ok",
           "fit": None, "quantization": None}
    if n < 8:
        out["status"] = "too_short"
        out["note"] = f"only {n} samples"
        return out
    if not np.all(np.isfinite(y)):
        y = y[np.isfinite(y)]
        n = int(y.shape[0])
    if np.all(y == y[0]):
        out["status"] = "constant"
        out["note"] = "all samples equal (" + ("all zero" if y[0] == 0 else f"{y[0]:g}") + "): no noise to analyse"
        return out
    m_fit = cluster_sizes(n, "octave")
    tau_f, avar_f, _, _ = oavar(y, rate_hz, m=m_fit)
    fit = fit_avar(tau_f, avar_f, edf_simple(n + 1, m_fit, 0), effects=effects, n=n, rate_hz=rate_hz, m=m_fit,
                   level=level)
    from companion.estimators.report import bounds_for_fit

    # effects the fit left out (N, B, K): their 95 % upper bound, as the online report gives it (issue 13)
    bounds = bounds_for_fit(fit, tau_f, avar_f, np.maximum(edf_simple(n + 1, m_fit, 0), 0.5), rate_hz, n)
    m = parse_taus(taus, n, rate_hz) if isinstance(taus, str) else cluster_sizes(n, taus)
    tau, avar, m, _ = oavar(y, rate_hz, m=m)
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in fit.terms]
    edf = edf_model(plain, m, n, rate_hz) if plain else edf_simple(n + 1, m, 0)
    edf = np.where(np.isfinite(edf) & (edf > 0), edf, edf_simple(n + 1, m, 0))
    adev = np.sqrt(avar)
    lo, hi = adev_ci(adev, edf, level)
    out.update(tau=tau.tolist(), adev=adev.tolist(), adev_lo=lo.tolist(), adev_hi=hi.tolist(),
               terms=fit.terms, bounds=bounds, edf=edf.tolist(),
               fit={"chi2": fit.chi2, "dof": fit.dof, "criterion": fit.criterion, "score": fit.score,
                    "model_error": fit.model_error,
                    "points": int(len(tau_f)), "notes": fit.notes})
    N = next((t["N"] for t in fit.terms if t["effect"] == "white_noise"), None)
    out["quantization"] = lsb_report(y, rate_hz, lsb, N)
    return out


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


def analyze_stream(stream, axes, taus, progress=None, online=False) -> dict:
    """The JSON ``streams`` entry of one :class:`companion.samples.ImuStream` (longest segment)."""
    a, b = stream.longest_segment()
    rate = float(stream.rate_hz)
    entry = {"message": stream.key.message, "instance": stream.key.instance, "sysid": stream.key.sysid,
             "compid": stream.key.compid, "rate_hz": rate, "samples": int(b - a),
             "duration_s": float(stream.t[b - 1] - stream.t[a]) if b > a else 0.0,
             "segments": len(stream.segments) or 1, "axes": {}}
    for axis in axes:
        lsb = stream.gyro_lsb if axis in GYRO_AXES else stream.accel_lsb
        if not (rate > 0 and math.isfinite(rate)):
            entry["axes"][axis] = {"tau": [], "adev": [], "adev_lo": [], "adev_hi": [], "terms": [],
                                   "status": "too_short", "note": "no sample rate"}
        else:
            entry["axes"][axis] = analyze_axis(stream.axis(axis)[a:b], rate, taus, lsb=lsb)
            if online and entry["axes"][axis]["status"] == "ok":
                from companion.estimators import online_terms

                y = stream.axis(axis)[a:b]
                entry["axes"][axis]["online"] = online_terms(y[np.isfinite(y)], rate)
        if progress:
            progress.step(f"{stream.key.message}[{stream.key.instance}] {axis}")
    return entry


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
        lines.append(f"{st['message']}[{st['instance']}] sys{st['sysid']}/comp{st['compid']}: "
                     f"{st['samples']} samples at {st['rate_hz']:.4g} Hz, {st['duration_s']:.1f} s")
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


def run(args) -> int:
    from companion.sources import load

    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    bad = [a for a in axes if a not in AXES]
    if bad or not axes:
        raise CompanionError(f"bad --axes {args.axes!r}: expected a comma list of {', '.join(AXES)}")
    res = load(args.source, config=args.config, duration=args.duration)
    streams = res.imu_streams()
    total = sum(s.samples for s in streams) * len(axes)
    progress = Progress(len(streams) * len(axes), enabled=not args.quiet and total > 2_000_000)
    report = {"source": str(args.source), "streams": []}
    try:
        for s in streams:
            report["streams"].append(analyze_stream(s, axes, args.taus, progress, online=args.online))
    finally:
        progress.close()
    print(format_table(report))
    if args.json:
        write_text(args.json, to_json(report) + "\n", "JSON")
        print(f"wrote {args.json}")
    if args.kalibr:
        write_text(args.kalibr, kalibr_yaml(report), "Kalibr YAML")
        print(f"wrote {args.kalibr}")
    if args.plot:
        from companion.plots.adev_plot import plot_report

        for path in plot_report(report, args.plot):
            print(f"wrote {path}")
    return 0
