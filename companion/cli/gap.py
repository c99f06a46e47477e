"""``companion gap``: where a noise model and a measurement disagree, what effect is missing, the fix."""

from __future__ import annotations

import argparse
import math

import numpy as np

from companion.cli.output import to_json, write_text
from companion.errors import CompanionError
from companion.samples import AXES, GYRO_AXES

DESCRIPTION = """\
Compare a noise model (YAML, as written by 'companion analyze'/'simulate' or by hand from a datasheet)
with measured data on one axis, and fix the model:

  1. measured Allan deviation with its 95 % band;
  2. the model's Allan deviation, analytic and confirmed by simulating the model;
  3. the tau ranges where the measurement leaves the model's band (table);
  4. every effect the model lacks (quantization, white_noise, bias_instability, random_walk, ramp,
     gauss_markov, sinusoid) added, each model term recalibrated, and each effect with a recalibrated
     term: all fitted to the same data and ranked by one score (deviance removed minus the penalty of the
     documented test level, scaled for the correlated long-tau Allan points); the best is taken when its
     corrected likelihood ratio passes that level, and the runner-up is printed beside it (so a ramp and
     a 5x larger random walk are weighed against each other, not tested one after the other); a named
     sinusoid is checked against the periodogram; a random walk that won over a long Gauss-Markov comes
     with that Gauss-Markov as the alternative the record is too short to rule out;
  5. repeated until no significant gap remains; gap before/after (G = 1 on average for a right model,
     noise floor 2) against the analytic curves and against fresh simulations.

If the model already fits within the noise, it says so and adds nothing. See docs/gap.md."""

EPILOG = """\
examples:
  companion gap flight.bin --datasheet MPU-6000 --imu 0         datasheet model vs the log's still segments
  companion gap flight.ulg --datasheet ICM-42688 --axis gz --plot gap.png
  companion gap flight.tlog --model imu_model.yaml --axis gx
  companion gap adis.csv.gz --model datasheet.yaml --axis gy --json gap.json --out-model fixed.yaml
  companion gap raw.csv --model m.yaml --axis gz --lsb 1e-3     rate rounded to 1 mrad/s (int16 RAW_IMU)

MEASURED is anything 'companion analyze' reads (.bin, .ulg, .tlog, .csv, .csv.gz); the still segments are
selected as analyze selects them (armed state, motion; --start/--end/--all) and pooled. Besides the seven
terms the candidates include the autopilot's low-pass filter with the logger's decimation (cut-off from
INS_GYRO_FILTER / INS_MPU6K_FILTER / IMU_GYRO_CUTOFF or --cutoff, else fitted) and, when the log has a temperature channel,
a temperature-driven rate checked against that channel. With --datasheet the first line says which
datasheet term the measurement contradicts and by how much.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("gap", help="find where a noise model and a measurement disagree, name the missing "
                              "effect, fix the model", description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("measured", metavar="MEASURED", help="log with IMU data: .bin, .ulg, .tlog, .csv (.gz)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--model", metavar="MODEL.yaml", help="noise model YAML (SI units)")
    src.add_argument("--datasheet", metavar="NAME", help="start from a gyro's datasheet figures (" +
                     ", ".join(_datasheet_names()) + ")")
    p.add_argument("--axis", choices=AXES, help="axis to compare (default: every gyro axis of the model)")
    sel = p.add_mutually_exclusive_group()
    sel.add_argument("--imu", type=int, metavar="I", help="IMU instance to use (default: the IMU stream with the "
                     "most still samples)")
    sel.add_argument("--stream", metavar="LABEL", help="IMU stream by its label or message name, e.g. IMU[1], "
                     "sensor_combined, RAW_IMU")
    p.add_argument("--json", metavar="OUT", help="write the result as JSON ('-' for stdout)")
    p.add_argument("--out-model", metavar="NEW.yaml",
                   help="write the sensor's updated model at the data's rate_hz (other axes' terms unchanged; the "
                   "log's rate rounding and filter are not written: docs/gap.md)")
    p.add_argument("--plot", metavar="PNG", help="write the gap figure (one per axis: NAME_gx.png ... when several)")
    p.add_argument("--lsb", type=float, metavar="RAD_S",
                   help="output step of the data in SI (default: the format's, e.g. 1e-3 for RAW_IMU gyro, or "
                        "detected from the values)")
    p.add_argument("--cutoff", type=float, metavar="HZ", help="low-pass cut-off of the logged data (default: the "
                   "log's INS_GYRO_FILTER / IMU_GYRO_CUTOFF, else fitted)")
    p.add_argument("--start", type=float, metavar="S", help="ignore data before this time (s)")
    p.add_argument("--end", type=float, metavar="S", help="ignore data after this time (s)")
    p.add_argument("--all", dest="use_all", action="store_true", help="use the whole record, not only still "
                   "segments")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulations (default 0)")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column evidently in ms/us is refused)")
    p.set_defaults(func=run)


def _datasheet_names() -> list[str]:
    try:
        from companion.datasheets import names

        return names()
    except Exception:  # the help text must not fail on a broken install
        return []


def _pick_stream(spec, streams, sel, args):
    """The IMU stream asked for (--imu/--stream), else the one with the most still samples."""
    if args.imu is not None:
        hits = [s for s in streams if s.key.instance == args.imu]
        if not hits:
            raise CompanionError(f"{spec}: no IMU instance {args.imu} (has: "
                                 f"{', '.join(s.key.label() for s in streams)})")
        return max(hits, key=lambda s: s.samples)
    if args.stream:
        want = args.stream.lower()
        hits = [s for s in streams if s.key.label().lower().startswith(want) or s.key.message.lower() == want]
        if not hits:
            raise CompanionError(f"{spec}: no IMU stream {args.stream!r} (has: "
                                 f"{', '.join(s.key.label() for s in streams)})")
        return hits[0]
    return max(streams, key=lambda s: sum(b - a for a, b in sel.ranges(s)))


def load_measured(spec, args):
    """Load any input ``analyze`` reads, select the still segments (:func:`companion.sources.still.select_still`,
    the same selection as ``companion analyze``), pick the stream. Returns (stream, ranges, selection, meta)."""
    from companion.sources import load
    from companion.sources.still import select_still

    res = load(spec, config=getattr(args, "config", None), time_unit=getattr(args, "time_unit", None))
    streams = res.imu_streams()
    if not streams:
        raise CompanionError(f"{spec}: no IMU stream")
    sel = select_still(streams, res.meta, start=args.start, end=args.end, use_all=args.use_all)
    if not sel.intervals:
        raise CompanionError(f"{spec}: {sel.notes[0] if sel.notes else 'no still data'} ({sel.describe()})")
    st = _pick_stream(spec, streams, sel, args)
    ranges = sel.ranges(st)
    if not ranges:
        raise CompanionError(f"{spec}: {st.key.label()} has no samples in the still segments ({sel.describe()})")
    rate = st.rate_hz
    if not (rate and math.isfinite(rate) and rate > 0):
        raise CompanionError(f"{spec}: cannot determine the sample rate of {st.key.label()}")
    return st, ranges, sel, res.meta


def log_cutoff(stream, meta) -> float | None:
    """The gyro low-pass cut-off of the logged data from the log's parameters (None if unknown)."""
    from companion.analysis.stream import stream_filters

    return stream_filters(stream, meta).get("gyro")


def format_report(r, source: str, label: str) -> str:
    from companion.gap.explain import describe_term
    from companion.gap.workflow import NOISE_FLOOR_G

    axis = r.axis
    m = r.measured
    out = [f"gap: {source} {label} axis {axis}: {m.n} samples at {m.rate_hz:.4g} Hz, tau {m.tau[0]:.3g}-"
           f"{m.tau[-1]:.4g} s ({len(m.tau)} octave points)"]
    out.append("model before:")
    out += [f"  {describe_term(t, axis)}" for t in r.terms_before] or ["  (no terms)"]
    sim = ""
    if r.gap_sim_before is not None:
        sim = (f"; vs simulated model G_sim = {r.gap_sim_before:.3g} (simulation vs analytic "
               f"{r.sim_check_before:.3g})")
    out.append(f"gap before: G = {r.gap_before:.3g} (noise floor {NOISE_FLOOR_G:g}){sim}")
    if r.regions_before:
        out.append("  where the measurement leaves the model's 95 % band:")
        out.append(f"  {'tau range (s)':>19}  {'measured':>8}  {'worst tau':>9}  {'ADEV ratio':>10}  {'z':>6}")
        for g in r.regions_before:
            out.append(f"  {g.tau_lo:9.3g}-{g.tau_hi:<9.3g}  {g.direction:>8}  {g.worst_tau:9.3g}  "
                       f"{g.worst_ratio:10.3g}  {g.worst_z:6.1f}" + ("  (single point)" if g.points == 1 else ""))
    else:
        out.append("  the measurement stays inside the model's 95 % band everywhere")
    for it in r.iterations:
        ex = it.get("explanations") or []
        top = "; ".join(f"{x['explanation']} {x['score']:.1f}" for x in ex[:3]) or "none fits above zero"
        out.append(f"iteration {it['iteration']}: explanations by score (dD - overdispersion x penalty): {top}; "
                   f"chosen: {it['chosen'] or 'none significant'}")
        nt = it.get("nested")
        if nt:
            kept = "kept" if nt["lr"] < nt["threshold"] else "rejected"
            out.append(f"  gauss_markov vs its {nt['limit']} limit: LR {nt['lr']:.1f} (dD {nt['lr_raw']:.1f} / "
                       f"overdispersion {nt['inflation']:.2f}), {nt['threshold']:.1f} needed: {nt['limit']} {kept}")
        t = it.get("test")
        if t:
            verdict = "significant" if t["lr"] > t["threshold"] else "not significant"
            out.append(f"  evidence for {t['effect']}: LR {t['lr']:.1f} (dD {t['lr_raw']:.1f} / overdispersion "
                       f"{t['inflation']:.2f}), {t['threshold']:.1f} needed: {verdict}")
        ru = it.get("runner_up")
        if t and ru:
            out.append(f"  runner-up {ru['explanation']}: LR {ru['lr']:.1f} (dD {ru['delta_dev']:.1f} / overdispersion "
                       f"{ru['inflation']:.2f}), {ru['penalty']:.1f} needed, score {ru['score']:.1f} against "
                       f"{t.get('score', float('nan')):.1f}")
    for a in r.added:
        out.append("added: " + a["explanation"])
    for e in r.recalibrated:
        if e["verdict"] != "consistent":
            out.append("recalibrated: " + e["text"])
    for n in r.notes:
        out.append("note: " + n)
    if r.terms_after is not r.terms_before:
        out.append("model after:")
        out += [f"  {describe_term(t, axis)}" for t in r.terms_after]
        sim = f"; vs simulated model G_sim = {r.gap_sim_after:.3g}" if r.gap_sim_after is not None else ""
        out.append(f"gap after: G = {r.gap_after:.3g}{sim}")
        if r.regions_after:
            out.append("  remaining disagreements: " + "; ".join(
                f"{g.tau_lo:.3g}-{g.tau_hi:.3g} s {g.direction} (x{g.worst_ratio:.3g})" for g in r.regions_after))
    return "\n".join(out)


def _axis_path(path, axis, several):
    if not several or path in (None, "-"):
        return path
    from pathlib import Path

    q = Path(path)
    return str(q.with_name(f"{q.stem}_{axis}{q.suffix}"))


def run(args) -> int:
    from companion.gap import run_gap
    from companion.gap.sensor_model import sensor_terms
    from companion.sim.model import NoiseModel, load_model, save_model
    from companion.cli.output import check_output_path, check_plot_path

    for opt, path in (("--json", None if args.json == "-" else args.json), ("--out-model", args.out_model)):
        if path:
            check_output_path(path, opt)
    if args.plot:
        check_plot_path(args.plot)
    from companion.cli.source_options import warn_ignored_options

    warn_ignored_options(args, [args.measured], "gap")
    for opt in ("lsb", "cutoff"):
        v = getattr(args, opt)
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise CompanionError(f"--{opt} must be a positive number, got {v}")
    sheet = None
    if args.datasheet:
        from companion.datasheets import model_terms

        terms, sheet = model_terms(args.datasheet)
        # the datasheet table holds gyro figures only, so its model has the three gyro axes
        model_axes = list(GYRO_AXES)
    else:
        model = load_model(args.model)  # before the data: a wrong model path fails fast
        model_axes = list(model.axes)
    # the axis is checked before the data are read: a wrong --axis fails at once, not after a long load
    axes = [args.axis] if args.axis else [a for a in GYRO_AXES if a in model_axes]
    for a in axes:
        if a in model_axes:
            continue
        if sheet is not None:
            raise CompanionError(f"datasheet {sheet['name']}: no terms for axis {a}; datasheet models are gyro-only "
                                 f"(has: {', '.join(model_axes)}); for an accelerometer axis give --model")
        raise CompanionError(f"{args.model}: no terms for axis {a} (has: {', '.join(model_axes) or 'none'})")
    if not axes:
        raise CompanionError(f"{args.model}: no gyro axis; give --axis")
    st, ranges, sel, meta = load_measured(args.measured, args)
    rate = float(st.rate_hz)
    if sheet is not None:
        model = NoiseModel(rate_hz=rate, axes={a: [dict(t) for t in terms] for a in GYRO_AXES})
        source_model = f"datasheet {sheet['name']} ({sheet['source']}; N from {sheet['si']['N_from']}" + \
            (f", B from {sheet['si']['B_from']}" if sheet["si"]["B"] else ", no bias stability given") + ")"
    else:
        source_model = args.model
    cutoff = args.cutoff if args.cutoff is not None else log_cutoff(st, meta)
    # PX4 sensor_combined carries gyro_rad = integral / integral_dt: each value is a mean over its interval
    integrated = meta.get("format") == "ulog" and st.key.message == "sensor_combined"
    label = st.key.label()
    docs, new_axes, left_out = [], {a: [dict(t) for t in ts] for a, ts in model.axes.items()}, {}
    several = len(axes) > 1
    for axis in axes:
        col = st.axis(axis)
        temp = getattr(st, "temperature", None)
        segs, tsegs = [], []
        for a, b in ranges:
            y = col[a:b]
            ok = np.isfinite(y)
            segs.append(y[ok])
            if temp is not None:
                tsegs.append(np.asarray(temp[a:b], dtype=float)[ok])
        if sum(y.shape[0] for y in segs) < 64 or max(y.shape[0] for y in segs) < 16:
            raise CompanionError(f"{args.measured}: only {sum(y.shape[0] for y in segs)} still samples on {axis}; "
                                 "need at least 64")
        lsb = args.lsb if args.lsb is not None else (st.gyro_lsb if axis in GYRO_AXES else st.accel_lsb)
        r = run_gap(None, rate, model.axes[axis], axis=axis, lsb=lsb, seed=args.seed, cutoff_hz=cutoff,
                    segments=segs, temperature=tsegs or None, integrated=integrated)
        text = format_report(r, args.measured, label)
        if sheet is not None:
            from companion.gap.explain import datasheet_verdict

            text = datasheet_verdict(r.recalibrated, sheet["name"], axis, r.added) + "\n" + text
        text += f"\nmodel: {source_model}"
        text += f"\nstill data used: {sel.describe()}; {label}: {len(ranges)} segment(s), " + \
            ", ".join(f"{st.t[a]:.1f}-{st.t[b - 1]:.1f} s" for a, b in ranges)
        if cutoff:
            text += f"\nlow-pass cut-off of the logged gyro data: {cutoff:g} Hz " + \
                ("(--cutoff)" if args.cutoff is not None else "(the log's parameter)")
        if abs(model.rate_hz - rate) > 0.02 * rate:
            text += (f"\nnote: the model's rate_hz {model.rate_hz:g} differs from the data's {rate:.4g} Hz; the "
                     "comparison uses the data's rate")
        if args.json != "-":
            print(text + ("\n" if several else ""))
        doc = r.to_dict()
        doc.update(source=str(args.measured), stream=label, selection=sel.to_dict(),
                   ranges_s=[[float(st.t[a]), float(st.t[b - 1])] for a, b in ranges], cutoff_hz=cutoff,
                   model_source=source_model)
        if sheet is not None:
            doc["datasheet"] = {k: v for k, v in sheet.items() if k != "si"} | {"si": sheet["si"]}
            doc["verdict"] = text.splitlines()[0]
        docs.append(doc)
        # the sensor's terms only: the log's rate rounding, filter and temperature coupling are derived from
        # the log on every run, and written into the model they would be counted twice when read back
        new_axes[axis], left_out[axis] = sensor_terms(r)
        if args.plot:
            from companion.plots.gap_plot import plot_gap

            path = _axis_path(args.plot, axis, several)
            try:
                plot_gap(r, path)
            except OSError as exc:
                raise CompanionError(f"cannot write {args.plot}: {exc.strerror or exc}") from None
            print(f"wrote {path}")  # every file written is named, as analyze and compensate do
    if args.json:
        s = to_json(docs[0] if not several else {"axes": docs}, indent=2)
        if args.json == "-":
            print(s)
        else:
            write_text(args.json, s + "\n", "JSON")
            print(f"wrote {args.json}")
    if args.out_model:
        # the data's rate: every term was evaluated at it (a bias instability without f0 up to its Nyquist
        # frequency), and `companion simulate` synthesises the model at its rate_hz
        header = [f"updated by companion gap from {args.measured} ({label}), axes {', '.join(axes)}: "
                  + ", ".join(f"{d['axis']} gap {d['gap_before']:.3g} -> {d['gap_after']:.3g}" for d in docs),
                  f"rate_hz: the data's {rate:.6g} Hz" + (f" (the input model had {model.rate_hz:g})"
                                                         if abs(model.rate_hz - rate) > 1e-9 * rate else "")]
        left = [f"{a}: {', '.join(v)}" for a, v in left_out.items() if v]
        if left:
            header.append("not written, properties of the log that gap derives from it on every run: "
                          + "; ".join(left))
        try:
            save_model(NoiseModel(rate_hz=rate, axes=new_axes), args.out_model, header="\n".join(header))
        except OSError as exc:
            raise CompanionError(f"cannot write {args.out_model}: {exc.strerror or exc}") from None
        print(f"wrote {args.out_model}")
        if left:
            print(f"  (the sensor's terms at the data's {rate:.6g} Hz; the log's own, which gap derives from it on "
                  f"every run, not written: {'; '.join(left)})")
    return 0
