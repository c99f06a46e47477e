"""``companion run``: the live loop on the companion computer (or a .tlog replayed through the same pipeline)."""

from __future__ import annotations

import argparse
import signal
import sys
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
    # MAVLink 2 signing (companion/mavlink/signing.py, docs/run.md#signed-links)
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


def print_summary(pipeline, out=None) -> None:
    from companion.service.runner import summary_lines

    for line in summary_lines(pipeline):
        print(line, file=out or sys.stdout)


def run(args) -> int:
    # signal handling first (a SIGTERM during start-up still saves and exits 0), then the imports
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
    from companion.service import runner

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
    state_path = runner.state_path(args.state, extra.get("state_file"), args.no_state, live=not is_replay)
    save_period = float(extra.get("save_period_s", 60.0))
    _check_outputs(args, extra, state_path)  # every output path checked before the work starts
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
            pipeline, sink, totals = runner.replay(src, pcfg, period, baseline, scales, writer, state_path, args.relearn,
                                                   lambda: stop["flag"], log, warn, echo=None if quiet else print)
            log(f"replayed {totals['frames']} frames ({totals['imu_samples']} IMU samples, {totals['bad_frames']} bad frames), "
                f"{sink.sent} NAMED_VALUE_FLOAT, {len(sink.texts)} STATUSTEXT")
            if not pipeline.channels:
                raise CompanionError(f"{src}: no IMU data to replay")
        else:
            from companion.service.live import run_live

            def ready(source):  # printed even with --quiet: the socket/port is open and signals are handled
                print(f"{READY_LINE} {source}", file=sys.stderr, flush=True)

            pipeline, link = run_live(src, args.baud, args.signing, args.accept_unsigned, args.duration, pcfg, link_cfg,
                                      period, baseline, scales, state_path, args.relearn, save_period, writer, stop,
                                      log, warn, ready)
        if state_path is not None:
            runner.save(pipeline, state_path, warn)
        print_summary(pipeline)
        if not is_replay:  # link health (loss, reordering, late, rejected frames) per source
            for line in link.stats.summary_lines():
                print(line)
        return 0
    finally:
        if writer is not None:
            writer.close()


def _signing_key(args, is_replay, warn):
    """The signing key (bytes) of --signing-key, or None."""
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
