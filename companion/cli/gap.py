"""``companion gap``: where a noise model and a measurement disagree, what effect is missing, the fix."""

from __future__ import annotations

import argparse
import math
import sys

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
  companion gap flight.tlog --model imu_model.yaml --axis gx
  companion gap adis.csv.gz --model datasheet.yaml --axis gy --json gap.json --out-model fixed.yaml --plot gap.png
  companion gap raw.csv --model m.yaml --axis gz --lsb 1e-3     rate rounded to 1 mrad/s (int16 RAW_IMU)

MEASURED is a .tlog or a .csv/.csv.gz (time_s,gx,gy,gz,ax,ay,az; rad/s, m/s^2); the longest gap-free
segment of the longest IMU stream is used. The model's rate_hz should match the data (a warning otherwise).
"""


def register(subparsers) -> None:
    p = subparsers.add_parser("gap", help="find where a noise model and a measurement disagree, name the missing "
                              "effect, fix the model", description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("measured", metavar="MEASURED", help=".tlog or .csv/.csv.gz with IMU data")
    p.add_argument("--model", required=True, metavar="MODEL.yaml", help="noise model YAML (SI units)")
    p.add_argument("--axis", required=True, choices=AXES, help="axis to compare")
    p.add_argument("--json", metavar="OUT", help="write the result as JSON ('-' for stdout)")
    p.add_argument("--out-model", metavar="NEW.yaml", help="write the updated model (other axes unchanged)")
    p.add_argument("--plot", metavar="PNG", help="write the gap figure")
    p.add_argument("--lsb", type=float, metavar="RAD_S",
                   help="output step of the data in SI (default: the format's, e.g. 1e-3 for RAW_IMU gyro, or "
                        "detected from the values)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulations (default 0)")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (streams: scale overrides)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column evidently in ms/us is refused)")
    p.set_defaults(func=run)


def _load_axis(spec, axis, config, time_unit=None):
    from companion.sources import load

    res = load(spec, config=config, time_unit=time_unit)
    streams = res.imu_streams() if hasattr(res, "imu_streams") else [s for s in res.streams if s.is_imu]
    if not streams:
        raise CompanionError(f"{spec}: no IMU stream")
    st = max(streams, key=lambda s: s.samples)
    from companion.sources.still import longest_still_range

    a, b = longest_still_range(res, st, warn=lambda m: print(f"warning: {m}", file=sys.stderr))
    y = st.axis(axis)[a:b]
    lsb = st.gyro_lsb if axis in GYRO_AXES else st.accel_lsb
    rate = st.rate_hz
    if not (rate and math.isfinite(rate) and rate > 0):
        raise CompanionError(f"{spec}: cannot determine the sample rate of {st.key.label()}")
    return y, rate, lsb, st.key.label()


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


def run(args) -> int:
    from companion.gap import run_gap
    from companion.sim.model import NoiseModel, load_model, save_model
    from companion.cli.output import check_output_path, check_plot_path

    for opt, path in (("--json", None if args.json == "-" else args.json), ("--out-model", args.out_model)):
        if path:
            check_output_path(path, opt)
    if args.plot:
        check_plot_path(args.plot)
    model = load_model(args.model)
    if args.axis not in model.axes:
        raise CompanionError(f"{args.model}: no terms for axis {args.axis} (has: {', '.join(model.axes) or 'none'})")
    y, rate, lsb, label = _load_axis(args.measured, args.axis, args.config, getattr(args, "time_unit", None))
    if args.lsb is not None:
        if not (args.lsb > 0 and math.isfinite(args.lsb)):
            raise CompanionError(f"--lsb must be a positive number, got {args.lsb}")
        lsb = args.lsb
    if y.shape[0] < 64:
        raise CompanionError(f"{args.measured}: only {y.shape[0]} samples on {args.axis}; need at least 64")
    r = run_gap(y, rate, model.axes[args.axis], axis=args.axis, lsb=lsb, seed=args.seed)
    text = format_report(r, args.measured, label)
    if abs(model.rate_hz - rate) > 0.02 * rate:
        text += (f"\nnote: the model's rate_hz {model.rate_hz:g} differs from the data's {rate:.4g} Hz; the "
                 "comparison uses the data's rate")
    if args.json != "-":
        print(text)
    if args.json:
        doc = r.to_dict()
        doc["source"] = str(args.measured)
        doc["stream"] = label
        s = to_json(doc, indent=2)
        if args.json == "-":
            print(s)
        else:
            write_text(args.json, s + "\n", "JSON")
    if args.out_model:
        axes = {a: [dict(t) for t in ts] for a, ts in model.axes.items()}
        axes[args.axis] = [{k: v for k, v in t.items() if k != "ci95"} for t in r.terms_after]
        try:
            save_model(NoiseModel(rate_hz=model.rate_hz, axes=axes), args.out_model,
                       header=f"updated by companion gap from {args.measured}, axis {args.axis}: "
                              f"gap {r.gap_before:.3g} -> {r.gap_after:.3g}")
        except OSError as exc:
            raise CompanionError(f"cannot write {args.out_model}: {exc.strerror or exc}") from None
    if args.plot:
        from companion.plots.gap_plot import plot_gap

        try:
            plot_gap(r, args.plot)
        except OSError as exc:
            raise CompanionError(f"cannot write {args.plot}: {exc.strerror or exc}") from None
    return 0
