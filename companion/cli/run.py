"""``companion run``: the live loop on the companion computer (or a .tlog replayed through the same pipeline)."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

from companion.errors import CompanionError

DESCRIPTION = """\
Watch the gyros of a vehicle for hours: per IMU and axis, online Allan-variance noise coefficients
(N angle random walk, B bias instability, K rate random walk) learned while the vehicle is still
(disarmed and not moving), sent back on the link as NAMED_VALUE_FLOAT (IMU0GX_N ... in datasheet
units) with a health flag IMU0G_HLTH (0 healthy, 1 degrading or faulty, 2 learning, 3 stale), a fault
code IMU0G_FLT and a STATUSTEXT on every change, e.g. "IMU0 gyro X degrading: N 2.1x baseline".

Every block of samples is also checked for the ways a gyro fails: stuck (frozen), noise jump, bias
jump or drift, spikes, saturation, rate drop, and (with two or three IMUs, also in flight) an IMU
that disagrees with the others, e.g. "IMU0 gyro X stuck" (CRITICAL), "IMU1 gyro X disagrees with
IMU0/IMU2". The run summary lists the active faults.

The baseline (what healthy looks like) is learned from the first --baseline-s seconds of still data or
loaded from a report of `companion analyze` (--baseline FILE). It is kept, with the estimator state,
in the --state file (saved atomically every minute and on Ctrl-C / SIGTERM), so it survives restarts.

A log file (.tlog, ArduPilot DataFlash .bin, PX4 .ulg, .csv; each optionally .gz) is replayed through the
very same pipeline as fast as possible (message time only: the estimates do not depend on the replay
speed; a log's armed state becomes heartbeats) and a summary is printed. See docs/run.md.
"""

EPILOG = """\
examples:
  companion run --source udpin:0.0.0.0:14550                   listen for a GCS/router forward
  companion run --source /dev/ttyAMA0 --baud 921600 --state /var/lib/companion/state.json
  companion run --source tcp:127.0.0.1:5760 --baseline healthy_analyze.json
  companion run --source flight.tlog --baseline-s 300          replay a log, print the summary
  companion run --source udpin:127.0.0.1:14551 --duration 60 --out-tlog session.tlog

watch it in MAVProxy:   graph NAMED_VALUE_FLOAT[IMU0GX_N].value
            in Mission Planner: Ctrl-F > Tuning > MAV_IMU0GX_N
"""

#: Printed on stderr (also with --quiet) once a live link is open and SIGINT/SIGTERM are handled:
#: supervisors and tests wait for it instead of a fixed time.
READY_LINE = "companion run: listening on"

LINK_KEYS = ("rate_hz", "messages", "compid", "heartbeat_s", "stale_s", "retry_s", "loss_warn", "loss_window_s")
RUN_KEYS = ("report_period_s", "state_file", "save_period_s")


def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="live gyro health on the companion computer (NAMED_VALUE_FLOAT reports)",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--source", required=True, metavar="CONN",
                   help="udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:, a serial device, or a log to replay "
                        "(.tlog, DataFlash .bin, PX4 .ulg, .csv; each optionally .gz)")
    p.add_argument("--baud", type=int, default=None, help="serial baud rate (default 115200)")
    p.add_argument("--config", metavar="FILE", help="YAML configuration (sections run:, estimator:, streams:)")
    p.add_argument("--time-unit", choices=("s", "ms", "us"), default=None, dest="time_unit",
                   help="unit of a CSV's time column (default s; a column evidently in ms/us is refused)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--baseline-s", type=float, metavar="S", help="learn the baseline from the first S s of still data (default 600)")
    g.add_argument("--baseline", metavar="FILE", help="baseline from a `companion analyze` JSON/YAML report or a saved baseline")
    p.add_argument("--baseline-force", action="store_true",
                   help="use --baseline even when it was measured on another stream (message, rate, sensor LSB, "
                        "units); without it a mismatch is an error")
    p.add_argument("--state", metavar="FILE", help="state file (default: run.state_file, else "
                   "$XDG_STATE_HOME/companion/run_state.json on a live link, none for a replay)")
    p.add_argument("--no-state", action="store_true", help="do not read or write a state file")
    p.add_argument("--relearn", action="store_true", help="ignore the baseline kept in the state file and learn a new one")
    p.add_argument("--sysid", type=int, help="system id of the vehicle (default: the first one sending IMU data)")
    p.add_argument("--rate", type=float, metavar="HZ", help="IMU message rate to ask the autopilot for (default 100)")
    p.add_argument("--report-period", type=float, metavar="S", help="seconds of message time between two reports of a value (default 1)")
    p.add_argument("--out-tlog", metavar="FILE", help="record what was received and sent (or, for a replay, the reports) to a tlog")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S wall-clock seconds (default: run until Ctrl-C/SIGTERM)")
    p.add_argument("--quiet", action="store_true", help="only warnings and the final summary")
    # i14: MAVLink 2 signing (companion/mavlink/signing.py, docs/run.md#signed-links)
    p.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing with this 32-byte key (raw or 64 hex "
                   "digits; the autopilot's key, set with SETUP_SIGNING): sign what we send, accept only "
                   "correctly signed frames, count the rejected ones")
    p.add_argument("--accept-unsigned", action="store_true",
                   help="with --signing-key: also accept unsigned frames (wrongly signed ones are still refused)")
    p.set_defaults(func=run)


def _load_yaml_or_json(path: str) -> dict:
    import json

    import yaml

    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such file") from None
    except OSError as exc:
        raise CompanionError(f"{path}: cannot read ({exc.strerror or exc})") from None
    try:
        return json.loads(text)
    except ValueError:
        pass
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CompanionError(f"{path}: neither JSON nor YAML ({str(exc).splitlines()[0]})") from None


def build(args, log):
    """Configuration objects from the config file and the command line (user errors -> CompanionError)."""
    from companion.health.baseline import Baseline
    from companion.mavlink.link import IMU_MESSAGE_IDS, LinkConfig
    from companion.service.pipeline import PipelineConfig
    from companion.sources import load_config
    from companion.sources.decode import ScaleTable

    config = load_config(args.config) if args.config else {}
    run_cfg = dict(config.get("run") or {})
    if not isinstance(config.get("run") or {}, dict):
        raise CompanionError("config: 'run' must be a mapping")
    link_cfg = LinkConfig()
    for k in LINK_KEYS:
        if k in run_cfg:
            v = run_cfg.pop(k)
            setattr(link_cfg, k, tuple(v) if k == "messages" else type(getattr(link_cfg, k))(v))
    for m in link_cfg.messages:
        if m not in IMU_MESSAGE_IDS:
            raise CompanionError(f"config run.messages: unknown message {m!r} (one of {', '.join(IMU_MESSAGE_IDS)})")
    extra = {k: run_cfg.pop(k) for k in RUN_KEYS if k in run_cfg}
    if "estimator" not in run_cfg and isinstance(config.get("estimator"), dict):
        run_cfg["estimator"] = {k: v for k, v in config["estimator"].items() if v is not None}
    try:
        pcfg = PipelineConfig.from_mapping(run_cfg)
    except (ValueError, TypeError) as exc:
        raise CompanionError(f"config: {exc}") from None
    if args.sysid is not None:
        pcfg.sysid = args.sysid
    if getattr(args, "baseline_force", False):
        pcfg.baseline_force = True
    if args.baseline_s is not None:
        if not args.baseline_s > 0:
            raise CompanionError("--baseline-s must be > 0")
        pcfg.baseline_s = args.baseline_s
    if args.rate is not None:
        if not args.rate > 0:
            raise CompanionError("--rate must be > 0")
        link_cfg.rate_hz = args.rate
    period = float(args.report_period if args.report_period is not None else extra.get("report_period_s", 1.0))
    if not period > 0:
        raise CompanionError("--report-period must be > 0")
    baseline = None
    if args.baseline:
        try:
            baseline = Baseline.from_dict(_load_yaml_or_json(args.baseline))
        except ValueError as exc:
            raise CompanionError(f"{args.baseline}: {exc}") from None
        baseline.source = args.baseline
    scales = ScaleTable(config)
    return pcfg, link_cfg, period, extra, baseline, scales


class ReplaySink:
    """Reporter sink for a replay: counts, keeps the latest values, optionally writes a tlog."""

    def __init__(self, writer=None, echo=None):
        self.writer = writer
        self.echo = echo
        self.values: dict[str, float] = {}
        self.sent = 0
        self.texts: list[str] = []
        self.t = 0.0

    def send_named_value_float(self, time_boot_ms, name, value):
        self.values[name] = value
        self.sent += 1
        self.t = time_boot_ms / 1000.0
        if self.writer is not None:
            self.writer.write(self.writer.mav.named_value_float_encode(int(time_boot_ms), name.encode(), float(value)), self.t)

    def send_statustext(self, severity, text):
        self.texts.append(text)
        if self.echo:
            self.echo(f"STATUSTEXT sev={severity} t={self.t:.0f}s: {text}")
        if self.writer is not None:
            self.writer.write(self.writer.mav.statustext_encode(int(severity), text.encode()), self.t)


def _state_path(args, extra, live: bool) -> Path | None:
    if args.no_state:
        return None
    if args.state:
        return Path(args.state)
    if extra.get("state_file"):
        return Path(os.path.expanduser(str(extra["state_file"])))
    if not live:
        return None
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(base) / "companion" / "run_state.json"


def print_summary(pipeline, out=None) -> None:
    out = out or sys.stdout

    rows = pipeline.summary()
    if not rows:
        print("no IMU data from the vehicle", file=out)
        return
    for r in rows:
        c = r["counts"]
        rate = f"{r['rate_hz']:.1f} Hz" if r["rate_hz"] else "rate unknown"
        print(f"IMU{r['imu']} ({r['message']}, {rate}): {r['health']}; {r['still_s']:.0f} s still data used; "
              f"{c['samples']} samples, {c['blocks_moving']} moving blocks, {c['resets']} resets, {c['gaps']} gaps, "
              f"{c['duplicates']} duplicates", file=out)
        for text in r.get("faults") or ():
            print(f"  FAULT: {text}", file=out)
        from companion.estimators.report import summary_line

        for ax, d in r["axes"].items():
            print(f"  {ax}: " + summary_line(d["terms"], ax, d["baseline"]), file=out)
    for t, text in pipeline.transitions:
        print(f"  at {t:.0f} s: {text}", file=out)


def run(args) -> int:
    # i14: signal handling first (a SIGTERM during start-up still saves and exits 0), then the imports
    stop = {"flag": False}

    def on_signal(signum, frame):
        stop["flag"] = True

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run(args, stop)
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _run(args, stop) -> int:
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.state import load_state, save_state

    quiet = args.quiet

    def log(line):
        if not quiet:
            print(f"companion run: {line}", file=sys.stderr, flush=True)

    def warn(line):
        print(f"companion run: warning: {line}", file=sys.stderr, flush=True)

    if args.duration is not None and not args.duration > 0:
        raise CompanionError("--duration must be > 0")
    pcfg, link_cfg, period, extra, baseline, scales = build(args, log)
    src = str(args.source)
    from companion.service.replay import is_replay_source

    is_replay = is_replay_source(src)
    if not is_replay:
        from companion.sources.connection import parse_connection

        parse_connection(src, args.baud)  # a clear error before anything else
    state_path = _state_path(args, extra, live=not is_replay)
    save_period = float(extra.get("save_period_s", 60.0))
    _check_outputs(args, extra, state_path)  # i14: every output path checked before the work starts
    args.signing = _signing_key(args, is_replay, warn)

    writer = None
    try:
        if args.out_tlog:
            from companion.mavlink.tlog_writer import TlogWriter

            try:
                writer = TlogWriter(args.out_tlog, sysid=pcfg.sysid or 1, compid=link_cfg.compid)
            except OSError as exc:
                raise CompanionError(f"{args.out_tlog}: cannot write ({exc.strerror or exc})") from None
        if is_replay:
            from companion.service.replay import replay_log, replay_tlog

            sink = ReplaySink(writer, echo=None if quiet else print)
            reporter = Reporter(sink, period)
            pipeline = Pipeline(pcfg, reporter, baseline, log, scales)
            _restore(pipeline, state_path, args, load_state, warn, log)
            if src.lower().endswith((".tlog", ".tlog.gz")):
                totals = replay_tlog(src, pipeline, scales, stop=lambda: stop["flag"])
            else:
                totals = replay_log(src, pipeline, stop=lambda: stop["flag"], time_unit=getattr(args, "time_unit", None))
            log(f"replayed {totals['frames']} frames ({totals['imu_samples']} IMU samples, {totals['bad_frames']} bad frames), "
                f"{sink.sent} NAMED_VALUE_FLOAT, {len(sink.texts)} STATUSTEXT")
            if not pipeline.channels:
                raise CompanionError(f"{src}: no IMU data to replay")
        else:
            pipeline, link = _live(args, src, pcfg, link_cfg, period, baseline, scales, state_path, save_period,
                                   writer, stop, log, warn)
        if state_path is not None:
            _save(pipeline, state_path, save_state, warn)
        print_summary(pipeline)
        if not is_replay:  # i14: link health (loss, reordering, late, rejected frames) per source
            for line in link.stats.summary_lines():
                print(line)
        return 0
    finally:
        if writer is not None:
            writer.close()


def _signing_key(args, is_replay, warn):
    """i14: the signing key (bytes) of --signing-key, or None."""
    if args.accept_unsigned and not args.signing_key:
        raise CompanionError("--accept-unsigned needs --signing-key")
    if not args.signing_key:
        return None
    if is_replay:
        raise CompanionError("--signing-key applies to live links, not to a replayed log")
    from companion.mavlink.signing import load_signing_key

    return load_signing_key(args.signing_key, warn)


def _check_outputs(args, extra, state_path) -> None:
    """--out-tlog and a state file named by the user (--state, run.state_file) follow the CLI's one rule
    (companion.cli.output.check_output_path: existing directory, writable, refused otherwise); only the
    default state location ($XDG_STATE_HOME/companion) is created when missing."""
    from companion.cli.output import check_output_path

    if args.out_tlog:
        check_output_path(args.out_tlog, "--out-tlog")
    if state_path is None:
        return
    if args.state or extra.get("state_file"):
        check_output_path(state_path, "--state" if args.state else "run.state_file")
    else:
        try:
            state_path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CompanionError(f"default state file {state_path}: cannot create its directory "
                                 f"({exc.strerror or exc}); give --state FILE or --no-state") from None
        check_output_path(state_path, "state file")


def _restore(pipeline, state_path, args, load_state, warn, log) -> None:
    if state_path is None:
        return
    if load_state(state_path, pipeline.load_state_dict, warn):
        if args.relearn and not pipeline.baseline_fixed:
            pipeline.baseline = None
            for ch in pipeline.channels.values():
                ch.make_estimators(learning=True)
        log(f"state restored from {state_path}" + (" (baseline dropped: --relearn)" if args.relearn else ""))


def _save(pipeline, state_path, save_state, warn) -> None:
    try:
        save_state(state_path, pipeline.state_dict())
    except OSError as exc:
        warn(f"cannot save state to {state_path} ({exc.strerror or exc})")


def _live(args, src, pcfg, link_cfg, period, baseline, scales, state_path, save_period, writer, stop, log, warn):
    from companion.health.detector import STALE
    from companion.mavlink.link import Link
    from companion.mavlink.reporter import MAV_SEVERITY_WARNING, Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.state import load_state, save_state
    from companion.sources.connection import open_connection

    conn = open_connection(src, args.baud, source_system=pcfg.sysid or 1, source_component=link_cfg.compid,
                           mavlink2=args.signing is not None)
    try:
        if args.signing is not None:  # i14
            from companion.mavlink.signing import setup_signing

            setup_signing(conn, args.signing, accept_unsigned=args.accept_unsigned)
            log("MAVLink 2 signing on: sending signed frames, accepting "
                + ("signed and unsigned" if args.accept_unsigned else "only correctly signed") + " frames")
        link = Link(conn, link_cfg, pcfg.sysid, log=log)
        if writer is not None:
            link.recorder = writer
        reporter = Reporter(link, period)
        pipeline = Pipeline(pcfg, reporter, baseline, log, scales)
        _restore(pipeline, state_path, args, load_state, warn, log)
        if pipeline.sysid is not None and link.sysid is None:
            link.set_sysid(pipeline.sysid)
        # i14: the readiness line, printed even with --quiet: the socket/port is open and signals are handled
        print(f"{READY_LINE} {src}", file=sys.stderr, flush=True)
        t_start = time.monotonic()
        last_save = t_start
        stale = False
        last_stale_report = 0.0
        while not stop["flag"]:
            msg = conn.recv_match(blocking=True, timeout=0.1)
            now = time.monotonic()
            if msg is not None:
                link.count(msg)  # i14: sequence numbers, loss, reordering per source
                if writer is not None:
                    writer.write_raw(msg.get_msgbuf(), time.time())
                if msg.get_type() != "BAD_DATA":
                    used = pipeline.handle(msg)
                    link.on_message(msg, is_vehicle_imu=used)
                    if used and stale:
                        stale = False
                        log("IMU data back")
            link.service()
            if link.last_imu_wall is not None and now - link.last_imu_wall > link_cfg.stale_s:
                if not stale:
                    stale = True
                    warn("IMU data stopped")
                    reporter.statustext("companion: IMU data stopped", MAV_SEVERITY_WARNING)
                if now - last_stale_report >= 1.0:
                    pipeline.send_health_now(STALE)
                    last_stale_report = now
            if state_path is not None and now - last_save >= save_period:
                _save(pipeline, state_path, save_state, warn)
                last_save = now
            if args.duration is not None and now - t_start >= args.duration:
                break
        log(f"stopping: {link.sent} messages sent, {reporter.sent} NAMED_VALUE_FLOAT, {reporter.texts} STATUSTEXT")
        return pipeline, link
    finally:
        try:
            conn.close()
        except Exception:
            pass
