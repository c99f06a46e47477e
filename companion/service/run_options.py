"""What one ``companion run`` is asked to do (:class:`RunOptions`, built once from the command line and the
configuration file by :func:`build_options`) and how it talks to its caller (:class:`RunHooks`).

User errors (a bad value, an unknown message, a live-only option on a replay) are one-line
CompanionErrors raised while building, before any work starts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from companion.errors import CompanionError

if TYPE_CHECKING:  # the types only: building the options imports them when a run starts
    from companion.health.baseline import Baseline
    from companion.mavlink.link import LinkConfig
    from companion.service.pipeline_config import PipelineConfig
    from companion.sources.decode import ScaleTable


def _nothing(*_args) -> None:
    return None


@dataclass(frozen=True)
class RunHooks:
    """The caller's side: lines to log (``log``; ``warn`` even when quiet), the stop request, the readiness
    call once a live link is open and signals are handled, and where a replay echoes its STATUSTEXTs."""

    log: Callable[[str], None] = _nothing
    warn: Callable[[str], None] = _nothing
    stop: Callable[[], bool] = lambda: False
    ready: Callable[[str], None] = _nothing
    started: Callable[[object], None] = _nothing  # the pipeline once made (run --web publishes its snapshots)
    echo: Callable[[str], None] | None = None


@dataclass(frozen=True)
class RunOptions:
    """One run: the source (a live link or a log to replay) and everything that shapes it."""

    source: str
    pipeline: PipelineConfig
    link: LinkConfig | None = None  # live links
    report_period: float = 1.0  # seconds of message time between two reports of a value
    baseline: Baseline | None = None  # loaded from a file, None: learn it
    scales: ScaleTable | None = None  # the IMU messages' scales (the configuration's streams:)
    state: Path | None = None  # the state file, None: no state kept
    relearn: bool = False  # drop the baseline kept in the state file
    save_period: float = 60.0  # wall seconds between two state saves on a live link
    baud: int | None = None  # serial links
    signing: bytes | None = field(default=None, repr=False)  # MAVLink 2 signing key (live links)
    accept_unsigned: bool = False
    duration: float | None = None  # wall-clock seconds of a live run, None: until stopped
    gcs: tuple[str, ...] = field(default_factory=tuple)  # ground-station links that get a copy of the reports
    out_tlog: str | None = None  # record what was received and sent (a replay: the reports)
    time_unit: str | None = None  # of a CSV's time column
    is_replay: bool = False  # the source is a log file


def _configs(args, config: dict):
    """(PipelineConfig, LinkConfig, the runner's own keys, report period) from the configuration's run:
    section and the command line."""
    from companion.config import LINK, RUNNER
    from companion.mavlink.link import IMU_MESSAGE_IDS, LinkConfig
    from companion.service.pipeline_config import PipelineConfig

    run_cfg = dict(config.get("run") or {})
    if not isinstance(config.get("run") or {}, dict):
        raise CompanionError("config: 'run' must be a mapping")
    link_cfg = LinkConfig()
    for k in LINK:
        if k in run_cfg:
            v = run_cfg.pop(k)
            setattr(link_cfg, k, tuple(v) if k == "messages" else type(getattr(link_cfg, k))(v))
    for m in link_cfg.messages:
        if m not in IMU_MESSAGE_IDS:
            raise CompanionError(f"config run.messages: unknown message {m!r} (one of {', '.join(IMU_MESSAGE_IDS)})")
    extra = {k: run_cfg.pop(k) for k in RUNNER if k in run_cfg}
    if "estimator" not in run_cfg and isinstance(config.get("estimator"), dict):
        run_cfg["estimator"] = {k: v for k, v in config["estimator"].items() if v is not None}
    try:
        pcfg = PipelineConfig.from_mapping(run_cfg)
    except (ValueError, TypeError) as exc:
        raise CompanionError(f"config: {exc}") from None
    if args.sysid is not None:
        if not 0 <= args.sysid <= 255:  # a MAVLink system id is one byte; 999 would match nothing, silently
            raise CompanionError(f"--sysid must be 0-255 (a MAVLink system id), got {args.sysid}")
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
    default_period = extra.get("report_period_s", RUNNER["report_period_s"].default)
    period = float(args.report_period if args.report_period is not None else default_period)
    if not period > 0:
        raise CompanionError("--report-period must be > 0")
    return pcfg, link_cfg, extra, period


def _check_links(src: str, baud, gcs: tuple[str, ...], is_replay: bool) -> None:
    """A live source and every --gcs link parse (a clear error before anything else); no --gcs on a replay."""
    if is_replay:
        if gcs:
            raise CompanionError("--gcs applies to live links, not to a replayed log")
        return
    from companion.sources.connection import parse_connection

    parse_connection(src, baud)
    for spec in gcs:
        if parse_connection(spec)[0] != "net":
            raise CompanionError(f"--gcs {spec}: expected a network link (udpout:HOST:PORT, tcp:HOST:PORT, ...)")


def _signing_key(args, is_replay: bool, warn) -> bytes | None:
    """The signing key (bytes) of --signing-key, or None."""
    if args.accept_unsigned and not args.signing_key:
        raise CompanionError("--accept-unsigned needs --signing-key")
    if not args.signing_key:
        return None
    if is_replay:
        raise CompanionError("--signing-key applies to live links, not to a replayed log")
    from companion.mavlink.signing import load_signing_key

    return load_signing_key(args.signing_key, warn)


def build_options(args, warn, check_outputs: Callable[[Path | None, dict], None] = _nothing) -> RunOptions:
    """The run's options from the parsed ``companion run`` arguments and the configuration file they name.
    ``check_outputs(state_path, run_keys)`` checks the output paths (the caller's rule) once they are
    known and before the signing key is read."""
    from companion.config import RUNNER
    from companion.service.replay import is_replay_source
    from companion.service.run_session import load_baseline, state_path
    from companion.sources import load_config
    from companion.sources.decode import ScaleTable

    if args.duration is not None and not args.duration > 0:
        raise CompanionError("--duration must be > 0")
    config = load_config(args.config) if args.config else {}
    pcfg, link_cfg, extra, period = _configs(args, config)
    baseline = load_baseline(args.baseline) if args.baseline else None
    scales = ScaleTable(config)
    src = str(args.source)
    is_replay = is_replay_source(src)
    gcs = tuple(getattr(args, "gcs", None) or ())
    _check_links(src, args.baud, gcs, is_replay)
    state = state_path(args.state, extra.get("state_file"), args.no_state, live=not is_replay)
    check_outputs(state, extra)
    return RunOptions(source=src, pipeline=pcfg, link=link_cfg, report_period=period, baseline=baseline,
                      scales=scales, state=state, relearn=args.relearn,
                      save_period=float(extra.get("save_period_s", RUNNER["save_period_s"].default)),
                      baud=args.baud, signing=_signing_key(args, is_replay, warn),
                      accept_unsigned=args.accept_unsigned, duration=args.duration, gcs=gcs,
                      out_tlog=args.out_tlog, time_unit=getattr(args, "time_unit", None), is_replay=is_replay)
