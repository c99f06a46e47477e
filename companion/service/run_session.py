"""What ``companion run`` does around the pipeline: the replay sink, the state file (where it is, restoring
and saving it), a log replayed end to end, a whole run (:func:`run`: replay or live link, the state saved),
and the summary lines. Argument parsing and printing stay in :mod:`companion.cli.run`."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from companion.errors import CompanionError, NoUsableData, not_text
from companion.service.run_options import RunHooks, RunOptions

if TYPE_CHECKING:
    from companion.mavlink.link import Link
    from companion.service.pipeline import Pipeline


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

    def send_statustext(self, severity, text, time_boot_ms=None):
        if time_boot_ms is not None:  # the time of what it reports, not of the last NAMED_VALUE_FLOAT
            self.t = time_boot_ms / 1000.0
        self.texts.append(text)
        if self.echo:
            self.echo(f"STATUSTEXT sev={severity} t={self.t:.0f}s: {text}")
        if self.writer is not None:
            self.writer.write(self.writer.mav.statustext_encode(int(severity), text.encode()), self.t)


def state_path(explicit: str | None, configured: str | None, no_state: bool, live: bool) -> Path | None:
    """The state file: --no-state none; else --state, the config's run.state_file, and on a live link the
    default $XDG_STATE_HOME/companion/run_state.json (a replay keeps no state unless told)."""
    if no_state:
        return None
    if explicit:
        return Path(explicit)
    if configured:
        return Path(os.path.expanduser(str(configured)))
    if not live:
        return None
    base = os.environ.get("XDG_STATE_HOME") or os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(base) / "companion" / "run_state.json"


def restore(pipeline, path, relearn: bool, warn, log) -> None:
    """Restore the pipeline from the state file, if there is one (``relearn``: drop its baseline)."""
    from companion.service.state import load_state

    if path is None:
        return
    if load_state(path, pipeline.load_state_dict, warn):
        if relearn and not pipeline.baseline_fixed:
            pipeline.baseline = None
            for ch in pipeline.channels.values():
                ch.make_estimators(learning=True)
        log(f"state restored from {path}" + (" (baseline dropped: --relearn)" if relearn else ""))


def save(pipeline, path, warn) -> None:
    """Save the pipeline's state atomically; a failure is a warning (the run goes on)."""
    from companion.service.state import save_state

    try:
        save_state(path, pipeline.state_dict())
    except OSError as exc:
        warn(f"cannot save state to {path} ({exc.strerror or exc})")


def replay(opts: RunOptions, hooks: RunHooks, writer=None):
    """Replay the log ``opts.source`` through a new pipeline (its reports go to a :class:`ReplaySink`, and to
    ``writer`` when given): (pipeline, sink, totals)."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.replay import replay_log, replay_tlog
    from companion.sources.kind import kind_of

    src, state = opts.source, opts.state
    sink = ReplaySink(writer, echo=hooks.echo)
    reporter = Reporter(sink, opts.report_period)
    pipeline = Pipeline(opts.pipeline, reporter, opts.baseline, hooks.log, opts.scales)
    restore(pipeline, state, opts.relearn, hooks.warn, hooks.log)
    check = None
    if state is not None:
        from companion.service.state_match import state_check

        check = state_check(pipeline, src, state)  # on the streams the replay reads, before it feeds them
    hooks.started(pipeline)
    fp = None
    if state is not None:
        from companion.service.state import fingerprint

        try:
            fp = fingerprint(src)
        except OSError:
            pass  # the reader says what is wrong with the file
        if fp is not None and any(r.get("sha256") == fp["sha256"] for r in pipeline.replayed):
            raise CompanionError(f"{src}: the state file {state} already holds this log's data (replayed into it "
                                 "before): replaying it again would count every sample twice and narrow the "
                                 "intervals; give another --state file or --no-state")
    try:
        if kind_of(src) == "tlog":  # frame order with its HEARTBEATs (armed state)
            totals = replay_tlog(src, pipeline, opts.scales, stop=hooks.stop, check=check)
        else:
            totals = replay_log(src, pipeline, stop=hooks.stop, time_unit=opts.time_unit, check=check)
    finally:
        if fp is not None:  # (an interrupted replay fed part of it: that part must not be fed again either)
            pipeline.replayed.append(fp)
    return pipeline, sink, totals


@dataclass
class RunResult:
    """What a run leaves for the summary: the pipeline, and the link of a live run (its health lines)."""

    pipeline: Pipeline
    link: Link | None = None


def _open_writer(opts: RunOptions):
    """The --out-tlog recorder, or None."""
    if not opts.out_tlog:
        return None
    from companion.mavlink.link import LinkConfig
    from companion.mavlink.tlog_writer import TlogWriter

    try:
        return TlogWriter(opts.out_tlog, sysid=opts.pipeline.sysid or 1, compid=(opts.link or LinkConfig()).compid)
    except OSError as exc:
        raise CompanionError(f"{opts.out_tlog}: cannot write ({exc.strerror or exc})") from None


def run(opts: RunOptions, hooks: RunHooks) -> RunResult:
    """One ``companion run``: a log replayed, or a live link until stopped; the state saved at the end."""
    writer = _open_writer(opts)
    try:
        if opts.is_replay:
            pipeline, sink, totals = replay(opts, hooks, writer)
            hooks.log(f"replayed {totals['frames']} frames ({totals['imu_samples']} IMU samples, "
                      f"{totals['bad_frames']} bad frames), {sink.sent} NAMED_VALUE_FLOAT, {len(sink.texts)} STATUSTEXT")
            if not pipeline.channels:
                raise NoUsableData(f"{opts.source}: no IMU data to replay")
            result = RunResult(pipeline)
        else:
            from companion.service.live import run_live

            result = RunResult(*run_live(opts, hooks, writer))
        result.pipeline.evidence.finish()  # alarms whose minute after is not in: kept with what there is
        if opts.state is not None:
            save(result.pipeline, opts.state, hooks.warn)
        return result
    finally:
        if writer is not None:
            writer.close()


def summary_lines(pipeline) -> list[str]:
    """The run summary: per IMU its health, data used and counts, active faults and per-axis estimates,
    then the health transitions."""
    from companion.service.final_analysis import summary_lines as final_lines

    rows = pipeline.summary()
    if not rows:
        return ["no IMU data from the vehicle"]
    out = []
    for r in rows:
        c = r["counts"]
        rate = f"{r['rate_hz']:.1f} Hz" if r["rate_hz"] else "rate unknown"
        k, other_s = r["other_rates"]
        # the figures below are this rate's: still data fed at other rates sit in the estimators kept for them
        other = f" (+ {other_s:.0f} s kept with {k} other rate{'s' if k > 1 else ''})" if other_s >= 1.0 else ""
        # the block cutter's gaps (longer than gap_s), not inspect's (1.5 periods): said, as the counts differ
        gap_s = pipeline.channels[r["imu"]].cutter.rules.gap_s if r["imu"] in pipeline.channels else pipeline.cfg.gap_s
        out.append(f"IMU{r['imu']} ({r['message']}, {rate}): {r['health']}; {r['still_s']:.0f} s still data used{other}; "
                   f"{c['samples']} samples, {c['blocks_moving']} moving blocks, {c['resets']} resets, "
                   f"{c['gaps']} gaps > {gap_s:.2g} s, {c['duplicates']} duplicates")
        for text in r.get("faults") or ():
            out.append(f"  FAULT: {text}")
        for text in r.get("notes") or ():
            out.append(f"  note: {text}")
        out += final_lines(r)  # analyze's figures on the still data, then the online ones (service.final_analysis)
        out += pipeline.inflight.summary_lines(r["imu"])
    for t, text in pipeline.transitions:
        out.append(f"  at {t:.0f} s: {text}")
    from companion.service.autopilot_watch import summary_lines as autopilot_lines

    return out + autopilot_lines(pipeline)


def _load_yaml_or_json(path: str) -> dict:
    import json

    import yaml

    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such file") from None
    except OSError as exc:
        raise CompanionError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise not_text(path, exc, "a baseline is a JSON/YAML report of `companion analyze` or a saved baseline") from None
    try:
        return json.loads(text)
    except ValueError:
        pass
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CompanionError(f"{path}: neither JSON nor YAML ({str(exc).splitlines()[0]})") from None


def load_baseline(path: str):
    """A baseline from a `companion analyze` JSON/YAML report or a saved baseline (user errors: one line)."""
    from companion.health.baseline import Baseline

    try:
        baseline = Baseline.from_dict(_load_yaml_or_json(path))
    except ValueError as exc:
        raise CompanionError(f"{path}: {exc}") from None
    baseline.source = path
    return baseline
