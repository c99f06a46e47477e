"""From MAVLink messages to estimates, health and reports, in message time only.

:class:`Pipeline` routes messages to one :class:`~companion.service.channel.Channel` per IMU (the first IMU
message type seen for an instance is used, other types carrying the same IMU and other system ids are
ignored), compares the IMUs (:mod:`companion.service.imu_group`), reports and keeps the saved state
(:mod:`companion.service.pipeline_state`); the summary is :mod:`companion.service.imu_summary`.

1. Each block is *still* when the vehicle is disarmed (its autopilot's HEARTBEAT ``base_mode`` bit 128
   clear; no HEARTBEAT at all counts as disarmed) AND the motion gate agrees. A block is fed only if the
   next block is still too and the vehicle has been still for ``settle_s`` before it.
2. Every block, still or not, goes through the fault detectors (companion.health.monitor) and, with two
   or more IMUs, the pairwise disagreement test; each transition is a STATUSTEXT and sets
   ``IMU{i}G_HLTH`` / ``IMU{i}G_FLT`` / ``IMU{i}G_FLM`` at once.
3. Fed blocks go to the channel's estimators; while learning, the baseline is taken after ``baseline_s``
   seconds of still data (unless a baseline was loaded).
4. Every ``check_s`` of message time the current terms are reported and tested against the baseline
   (companion.health.degradation), health transitions produce a STATUSTEXT.

A loaded baseline in other units or of another sensor stops the pipeline: :attr:`Pipeline.failed` holds
the one-line reason and further input is ignored (the caller reports it and exits).
"""

from __future__ import annotations

import math
from typing import Callable, Iterable, Mapping

import numpy as np

from companion.health.baseline import Baseline
from companion.health.degradation import DEGRADING, LEARNING
from companion.health.clip_watch import ClipWatch
from companion.health.faults import FaultEvent
from companion.health.hold import FAULT
from companion.health.frozen_watch import FrozenWatch
from companion.mavlink.reporter import (MAV_SEVERITY_CRITICAL, MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING,
                                        Reporter, health_name)
from companion.service.allan_check import bias_extra_var
from companion.service.autopilot_watch import AUTOPILOT_MESSAGES, LinkHealth, on_message as autopilot_message
from companion.service.baseline_match import check_baseline, stream_meta
from companion.service.channel import INT16_MESSAGES, Channel
from companion.service.evidence_log import EvidenceLog
from companion.service.fault_followups import announce_restored, confirm_bias
from companion.service.frozen_hook import not_said_by_watch, say_frozen, watch_rows
from companion.service.pipeline_config import PipelineConfig  # noqa: F401  (re-exported: the pipeline's configuration)
from companion.service.imu_summary import fault_texts, final_terms, send_final, summary_rows, too_slow_note
from companion.service.pipeline_state import load_pipeline_state, pipeline_state
from companion.service.rate_tracker import RATE_SWITCHES_LOGGED
from companion.service.imu_group import ImuGroup
from companion.service.inflight_report import InflightReport
from companion.units import datasheet_unit, to_datasheet

IMU_MESSAGES = ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3", "HIGHRES_IMU")  # the messages decoded as IMU data


class Pipeline:
    """Feed it pymavlink messages (:meth:`handle`) or decoded samples (:meth:`on_heartbeat`,
    :meth:`on_samples`, :meth:`on_sample`)."""

    def __init__(self, cfg: PipelineConfig, reporter: Reporter, baseline: Baseline | None = None,
                 log: Callable[[str], None] | None = None, scales=None):
        self.cfg = cfg
        self.reporter = reporter
        self.baseline = baseline  # loaded from a file or restored state; None: learn it
        self.baseline_fixed = baseline is not None
        self.log = log or (lambda line: None)
        self.scales = scales
        self.sysid = cfg.sysid
        self.armed = False
        self.channels: dict[int, Channel] = {}
        self.group = ImuGroup(cfg.reset_s, cfg.faults)
        self.frozen = FrozenWatch()  # dead or frozen axes sample by sample, at any rate (service.frozen_hook)
        self.clip = ClipWatch(cfg.gyro_limit)  # clipped axes sample by sample, streams up to 20 Hz (service.frozen_hook)
        self.watch_said: set = set()  # (imu, kind, axis) the watch announced itself (service.frozen_hook)
        self.inflight = InflightReport(self)  # each IMU's own noise while armed, from the other IMUs
        self.ignored = {"other_sysid": 0, "other_message": 0}
        self.transitions: list[tuple[float, str]] = []
        self._bias_said: dict = {}  # (imu, axis) -> the bias jump size said when it was flagged (deg/s)
        self._final: dict = {}  # (imu, axis) -> ((estimator id, fed_s), summary terms)
        self.rate_log: list[tuple[float, int, float | None, float]] = []  # (t, imu, old rate, new rate) of switches
        # logs replayed into this state (service.state.fingerprint): the same log replayed again into it would
        # feed its data twice
        self.replayed: list[dict] = []
        self.failed: str | None = None  # a user-facing error found in the data (the caller reports it)
        self._learned_here: set[int] = set()  # IMUs whose baseline was learned in this run
        self._restored: dict[int, list] = {}  # IMU -> the per-axis faults active when its state was saved
        self._tick = True
        self._decode = None
        # the autopilot's filter parameters (INS_GYRO_FILTER, IMU_GYRO_CUTOFF, ...) and the log format they
        # belong to (None: MAVLink): each channel's estimators model the low-pass cut-off of its data
        self.params: dict[str, float] = {}
        self.params_format: str | None = None
        self.evidence = EvidenceLog()  # the data around every alarm (service.evidence_log)
        self.autopilot_view, self.autopilot_link = None, LinkHealth()  # the autopilot's own IMU view: a log's, the link's

    # ------------------------------------------------------------------ input
    def raise_if_failed(self) -> None:
        """The caller's step after feeding: a user-facing error the pipeline found in the data (e.g. a
        baseline of another sensor) as one line (CompanionError). The pipeline itself never raises it
        inside the loop; it only stops using the input."""
        if self.failed:
            from companion.errors import CompanionError

            raise CompanionError(self.failed)

    def set_params(self, params: Mapping | None, fmt: str | None = None) -> None:
        """The autopilot's parameters as far as known (a log's, or PARAM_VALUE messages so far), ``fmt`` the
        log format their IMU messages come in ("dataflash", "ulog"; None: MAVLink). The filter parameters
        among them give each channel's low-pass cut-offs (:func:`companion.analysis.filters.filters_from_params`)."""
        from companion.analysis.filters import FILTER_PARAMS

        self.params = {k: float(v) for k, v in (params or {}).items() if k in FILTER_PARAMS}
        self.params_format = fmt
        for ch in self.channels.values():
            self._apply_filters(ch)

    def on_param(self, sysid: int, name: str, value: float) -> None:
        """A PARAM_VALUE of the vehicle: a filter parameter is kept and applied to the channels."""
        from companion.analysis.filters import FILTER_PARAMS

        name = str(name).split("\0", 1)[0]
        if name not in FILTER_PARAMS or (self.sysid is not None and sysid != self.sysid):
            return
        if not math.isfinite(float(value)) or self.params.get(name) == float(value):
            return
        self.set_params(dict(self.params, **{name: float(value)}), self.params_format)

    def _apply_filters(self, ch: Channel) -> None:
        from companion.analysis.filters import filters_from_params

        f = filters_from_params(self.params, ch.message, self.params_format)
        if ch.set_filters(f) and f:
            self.log(f"IMU{ch.imu}: low-pass " + ", ".join(f"{k} {v:g} Hz" for k, v in sorted(f.items()))
                     + " (the autopilot's parameter) modelled in the online noise figures")

    def handle(self, msg) -> bool:
        """One pymavlink message; returns True when it was an IMU sample of the vehicle that was used."""
        mtype = msg.get_type()
        if mtype == "HEARTBEAT":
            self.on_heartbeat(msg.get_srcSystem(), msg.type, msg.autopilot, msg.base_mode)
            return False
        if mtype == "PARAM_VALUE":
            self.on_param(msg.get_srcSystem(), msg.param_id, msg.param_value)
            return False
        if mtype in AUTOPILOT_MESSAGES:
            return autopilot_message(self, msg)
        if mtype not in IMU_MESSAGES:
            return False
        if self._decode is None:
            from companion.sources.decode import imu_sample_from_message

            self._decode = imu_sample_from_message
        s = self._decode(msg, self.scales)
        if s is None or not s.is_imu:
            return False
        return self.on_sample(s.key, s.t_s, s.gyro, s.accel, s.temperature)

    def on_heartbeat(self, sysid: int, mav_type: int, autopilot: int, base_mode: int) -> None:
        if autopilot == 8 or mav_type in (6, 18):  # MAV_AUTOPILOT_INVALID, GCS, onboard controller: not the vehicle
            return
        if self.sysid is not None and sysid != self.sysid:
            return
        self.autopilot_link.on_heartbeat(sysid, autopilot)
        armed = bool(base_mode & 128)
        if armed != self.armed:
            self.log(f"vehicle {'armed' if armed else 'disarmed'}")
        self.armed = armed

    def on_sample(self, key, t: float, gyro, accel, temperature: float | None = None) -> bool:
        """One sample: a one-row :meth:`on_samples`."""
        temp = math.nan if temperature is None else float(temperature)
        return self.on_samples(key, np.array([(t, *gyro, *accel, temp)], dtype=float), None, None) > 0

    def on_samples(self, key, t, gyro, accel, tick: bool = True, temperature=None) -> int:
        """Samples of one IMU in arrival order (arrays (n,), (n, 3), (n, 3); ``temperature`` (n,) degC or
        None where the source has none); returns the number used. ``tick=False``: the reporter's clock is
        left to the caller (:meth:`tick`; a replay interleaving streams), allowed only for samples that
        close no block (:meth:`quiet_run`). Rows are ``(t, gx, gy, gz, ax, ay, az, temperature)``."""
        self._tick = tick
        if gyro is None:  # already rows: the one-row call of on_sample
            rows = t
        else:
            tt = np.asarray(t, dtype=float).reshape(-1)
            temp = (np.full(tt.shape[0], np.nan) if temperature is None
                    else np.asarray(temperature, dtype=float).reshape(-1))
            rows = np.column_stack([tt, np.asarray(gyro, dtype=float).reshape(-1, 3),
                                    np.asarray(accel, dtype=float).reshape(-1, 3), temp])
        ch = self._route(key, rows.shape[0])
        if ch is None:
            return 0
        ch.see(rows[:, 1:4])
        watch_rows(self, ch, rows)
        before = ch.cutter.counts["samples"]
        for ev in ch.cutter.cut(rows):
            kind = ev[0]
            if kind == "samples":
                self._advance(ch, ev[1])
            elif kind == "block":
                self._close_block(ch, ev[1], ev[2])
                self.evidence.on_block(self, ch, ev[1])
                t_end = float(ev[1][-1, 0])
                if ch.check_due(t_end):
                    self._check(ch, t_end)
                if self._tick:
                    self.reporter.tick(t_end)
            elif kind == "reset":
                self.log(f"IMU{ch.imu}: timestamps reset ({ev[1]:.3f} s -> {ev[2]:.3f} s): autopilot reboot")
                ch.on_break()
            else:  # gap
                ch.on_break()
                slower = ch.cutter.slower_rate()
                if slower is not None:  # every interval a gap: a slower stream
                    self._switch_rate(ch, slower, np.array(ch.cutter.gap_t), ch.rate_hz)
            if self.failed:
                break
        return ch.cutter.counts["samples"] - before

    def tick(self, t) -> None:
        """Advance the reporter's clock over the message times ``t`` (in the order they were received)."""
        self.reporter.tick_times(t)

    def quiet_run(self, key, t) -> int:
        """How many of the next samples ``t`` (increasing, no gap) of stream ``key`` can be fed in one
        :meth:`on_samples` call without closing a block or falling due for a check: those change nothing
        but counts, so a replay may feed them in any order with other streams' quiet samples (0: feed the
        next sample alone)."""
        ch = self.channels.get(key.instance)
        t = np.asarray(t, dtype=float)
        if self.failed or key.sysid != self.sysid:
            return t.shape[0] if (self.failed or self.sysid is not None) else 0
        if ch is None or ch.message != key.message:
            return t.shape[0] if ch is not None else 0
        return ch.cutter.quiet_run(t, ch.next_check_t)

    def _route(self, key, n: int = 1) -> Channel | None:
        """The channel of a stream: the vehicle's first system id, the first message type of each IMU."""
        if self.failed:
            return None
        if self.sysid is None:
            self.sysid = key.sysid
            self.log(f"vehicle: system id {key.sysid}")
        elif key.sysid != self.sysid:
            self.ignored["other_sysid"] += n
            return None
        ch = self.channels.get(key.instance)
        if ch is None:
            lsb = None if key.message not in INT16_MESSAGES else (
                self.scales.lookup(key)[0] if self.scales is not None else 1e-3)
            ch = self.channels[key.instance] = Channel(key.instance, key.message, self.cfg, gyro_lsb=lsb)
            self.log(f"IMU{key.instance}: {key.message} from {key.label()}")
            self._apply_filters(ch)
            self._set_state(ch)  # health and fault code sent from the first second, whatever comes later
        elif ch.message != key.message:
            self.ignored["other_message"] += n
            return None
        return ch

    def _advance(self, ch: Channel, tt: np.ndarray) -> None:
        """Samples that close no block: the Allan check when due (at the first sample at or after its time)
        and the reporter's clock (every few samples: it sends by message time, the same either way)."""
        m = tt.shape[0]
        if m == 1:  # one row (the live path)
            t = float(tt[0])
            if ch.check_due(t):
                self._check(ch, t)
            if self._tick:
                self.reporter.tick(t)
            return
        i = 0
        while i < m:
            k = m if ch.next_check_t is None else int(np.searchsorted(tt, ch.next_check_t, side="left"))
            k = max(k, i)
            if k > i:
                self._ticks(ch, tt[i:k])
            if k >= m:
                return
            self._check(ch, float(tt[k]))
            if self._tick:
                self.reporter.tick(float(tt[k]))
            if self.failed:
                return
            i = k + 1

    def _ticks(self, ch: Channel, tt: np.ndarray) -> None:
        if self._tick:
            self.reporter.tick_times(tt)

    # ------------------------------------------------------------------ blocks
    def _off_rate(self, ch: Channel, data: np.ndarray, rate_event: str | None) -> bool:
        """A block whose own rate is off the stream's rate by more than RATE_CHANGE (another client's stream
        request, a log-rate change) is held back from every detector and estimator: the references belong to
        the old rate, a rate change is not a gyro fault. After OFF_RATE_BLOCKS such blocks at one rate the
        channel switches to it (channel.switch_rate: the state of that rate back, or learned afresh)."""
        if rate_event is not None:
            if rate_event == "changed":  # the cutter saw it first (a slow drift of the rate)
                new, old = ch.cutter.rate_hz, ch.cutter.prev_rate_hz
                self._switch_rate(ch, new, data[:, 0], old, keep_window=True)
            ch.rates.off_rate = []
            return rate_event == "changed"
        if ch.rate_hz is None or data.shape[0] < 3:
            return False
        held, new_rate = ch.rates.observe(data[:, 0], ch.rate_hz, ch.time_res, ch.cutter.tol)
        if held:
            ch.settler.drop_lookahead()
        if new_rate is not None:
            self._switch_rate(ch, new_rate, data[:, 0], ch.rate_hz)
        return held

    def _switch_rate(self, ch: Channel, rate: float, t_block: np.ndarray, old: float | None,
                     keep_window: bool = False) -> None:
        back = ch.switch_rate(rate, t_block, keep_window)
        if self._has_baseline(ch):
            ch.bank.stop_learning()  # the IMU's baseline exists: a profile kept from before it learns no other
        self.rate_log.append((float(t_block[-1]), ch.imu, old, ch.rate_hz))
        if ch.rate_switches <= RATE_SWITCHES_LOGGED:
            self.log(f"IMU{ch.imu}: rate changed {old:.1f} -> {ch.rate_hz:.1f} Hz (a stream request, not a gyro fault): "
                     + ("the state kept for this rate is back" if back else "references and estimators learned afresh"))
        if ch.rate_switches == RATE_SWITCHES_LOGGED:
            self.log(f"IMU{ch.imu}: the rate keeps changing (another client's stream requests, or an autopilot that "
                     "slows its streams while the link is busy): further changes are counted in the summary, not logged")
        self._set_state(ch)

    def _close_block(self, ch: Channel, data: np.ndarray, rate_event: str | None) -> None:
        say_frozen(self)
        if self._off_rate(ch, data, rate_event):
            return
        st = ch.stats(data)
        still = (not self.armed) and ch.is_still(data, st, self._peers(ch))
        t_end = float(data[-1, 0])
        if ch.gate.mislearned:
            self._forget_rest(ch, t_end)
        self._report(not_said_by_watch(self, ch, ch.on_block(data, st, still)), t_end)
        if ch.imu in self._restored:
            announce_restored(self, ch, t_end)
        self._report(self.group.compare(ch.imu, self.channels, self.armed, still), t_end)
        self.inflight.on_block(ch, t_end)
        if rate_event == "first":
            if self.baseline_fixed and self._has_baseline(ch):
                self.failed = check_baseline(self.baseline, ch, self.cfg.baseline_force, self.log)
                if self.failed:
                    return
            ch.make_estimators(learning=not self._has_baseline(ch))
            self.log(f"IMU{ch.imu}: {ch.rate_hz:.1f} Hz")
            slow = too_slow_note(ch)
            if slow:
                self.log(slow)
        if ch.rate_hz is None:
            return
        pending, pending_stats = ch.settle(data, st, still)
        if pending is not None:
            self._report(ch.on_quiet(pending_stats, bias_extra_var(self.baseline, ch.imu, self.cfg.block_s), pending), float(pending[-1, 0]))
            confirm_bias(self, ch, float(pending[-1, 0]))
            if ch.feed(pending):
                self._learn_done(ch, float(pending[-1, 0]))

    def _forget_rest(self, ch: Channel, t: float) -> None:
        """The gate's rest reference was learned under vibration: what was fed under it goes, and a baseline
        learned from it in this run is learned again (a loaded or restored one stays)."""
        ch.gate.mislearned = False
        if ch.rate_hz is None:  # nothing learned or fed yet
            return
        relearn = ch.imu in self._learned_here
        if relearn:
            self.baseline.drop_imu(ch.imu)
            self._learned_here.discard(ch.imu)
        refs = ch.forget_rest(learning=not self._has_baseline(ch))
        self.log(f"IMU{ch.imu}: at {t:.1f} s the accelerometer is {ch.gate.ratio:.0f}x quieter than what was taken "
                 f"for rest: the still data so far were vibration; estimators"
                 + (", baseline" if relearn else "") + (" and fault references" if refs else "") + " learned afresh")
        self._set_state(ch)

    def _peers(self, ch: Channel) -> list:
        """The other IMUs' latest blocks, when close in time (the motion consensus)."""
        out = []
        for o in self.channels.values():
            if o is ch or o.last_stats is None or o.last_t is None or ch.last_t is None:
                continue
            if abs(o.last_t - ch.last_t) < 2 * self.cfg.block_s:
                out.append(o.peer())
        return out

    def _has_baseline(self, ch: Channel) -> bool:
        return self.baseline is not None and self.baseline.has_imu(ch.imu)

    def _learn_done(self, ch: Channel, t: float | None = None) -> None:
        if self.baseline is None:
            self.baseline = Baseline("learned")
        for ax, params in ch.learned_terms().items():
            self.baseline.set_axis(ch.imu, ax, params)
            if ax in ch.learned_levels:
                self.baseline.set_levels(ch.imu, ax, *ch.learned_levels[ax])
        self.baseline.meta[ch.imu] = stream_meta(ch)
        self._learned_here.add(ch.imu)
        b = self.baseline.get(ch.imu, "gx") or {}
        n = b.get("N", (math.nan, math.nan))[0]
        # the datasheet unit, as every other figure on the console; SI in brackets for the state file's value
        self.log(f"IMU{ch.imu}: baseline learned from {ch.learned_s:.0f} s of still data (gx N "
                 f"{to_datasheet('N', n, 'gx'):.3g} {datasheet_unit('N', 'gx')} [{n:.3g} rad/s/sqrt(Hz)])")
        self.reporter.statustext(f"IMU{ch.imu} gyro baseline learned", MAV_SEVERITY_NOTICE, t)
        # HLTH 2 means "no baseline yet": not until the next check (up to check_s later) once it exists
        self._set_state(ch)

    # ------------------------------------------------------------------ reports
    def _report(self, events: Iterable[FaultEvent], t: float) -> None:
        for ev in events:
            text = ev.text()
            if ev.kind == "bias_jump" and ev.state == FAULT:
                self._bias_said[(ev.imu, ev.axis)] = ev.value
            self.transitions.append((t, text))
            self.log(text)
            self.evidence.on_fault_event(self, ev, t)
            if ev.state == FAULT:
                sev = MAV_SEVERITY_CRITICAL if ev.critical else MAV_SEVERITY_WARNING
            else:
                sev = MAV_SEVERITY_NOTICE
            self.reporter.statustext(text, sev, t)
            ch = self.channels.get(ev.imu)
            if ch is not None:
                self._set_state(ch)
            if ev.kind != "disagree" and len(self.channels) == 2 and self.group.active():
                # another fault may tell which of the two disagrees
                self._report(self.group.name(self.channels, self.armed), t)

    def _set_state(self, ch: Channel, health: int | None = None) -> None:
        self.reporter.set_health(ch.imu, self.health(ch) if health is None else health)
        self.reporter.set_fault(ch.imu, ch.faults.code(), ch.faults.mask())

    def _check(self, ch: Channel, t: float) -> None:
        strict = self.baseline_fixed and not self.cfg.baseline_force
        reported, transitions, error = ch.check(t, self.baseline, strict)
        if ch.fed_s < self.cfg.min_report_s:
            # at a rate the stream switched to (another client's stream request) the IMU keeps the health it
            # has against its baseline: HLTH 2 means "no baseline yet", not "new rate"
            switched = ch.rate_switches > 0 and self._has_baseline(ch)
            self._set_state(ch, self.health(ch) if ch.faults.active() or switched else LEARNING)
            return
        for ax, terms in reported.items():
            self.reporter.set_online_terms(ch.imu, ax, terms)
        self.evidence.on_check(self, ch, reported, transitions, t)
        for tr in transitions:
            text = tr.text()
            self.transitions.append((t, text))
            self.log(text)
            self.reporter.statustext(text, MAV_SEVERITY_WARNING if tr.state == DEGRADING else MAV_SEVERITY_NOTICE, t)
        if error:
            self.failed = error
            return
        self._set_state(ch)

    def final_terms(self, ch: Channel, ax: str) -> list[dict]:
        """The terms of the summary, computed once per state of the estimators (service.imu_summary)."""
        return final_terms(self, ch, ax)

    def send_final(self) -> int:
        """At the end of a live run: the summary's terms sent at once (service.imu_summary); how many."""
        return send_final(self)

    def report_terms(self, ch: Channel, ax: str, full: bool = False) -> list[dict]:
        return ch.report_terms(ax, full)

    def current_params(self, ch: Channel, ax: str, terms=None) -> dict[str, tuple[float, float]]:
        return ch.current_params(ax, terms)

    def health(self, ch: Channel) -> int:
        """0 healthy, 1 degrading (any fault, even while the Allan baseline is still being learned), 2 learning."""
        h = ch.health(self._has_baseline(ch))
        return DEGRADING if self.inflight.degrading(ch.imu) else h

    def send_health_now(self, state: int | None = None) -> None:
        """Send every IMU's health at once (e.g. STALE when the link is silent: no message time advances)."""
        for imu, ch in sorted(self.channels.items()):
            s = self.health(ch) if state is None else state
            self.reporter.send_now(health_name(imu), float(s), ch.last_t or 0.0)

    def summary(self) -> list[dict]:
        """Per IMU: rate, still data, health, counts, faults, notes and per-axis terms (service.imu_summary)."""
        return summary_rows(self)

    def fault_texts(self, ch: Channel) -> list[str]:
        """The active faults of an IMU in plain words, most severe first (what the STATUSTEXTs said)."""
        return fault_texts(self, ch)

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        """The saved state (service.pipeline_state)."""
        return pipeline_state(self)

    def load_state_dict(self, d: Mapping) -> None:
        """Restore a saved state; raises ValueError (caller warns and starts fresh) if it is not ours."""
        load_pipeline_state(self, d)
