"""The pipeline's side of the in-flight noise (:mod:`companion.service.inflight_live`): feeding it after each
block, the NAMED_VALUE_FLOATs of its figures, its STATUSTEXTs and the health they set.

Names (datasheet units, deg/sqrt(h)), per IMU i and gyro axis X, Y, Z:

* ``IMU{i}G{X}FN`` the IMU's own white noise N in flight (armed and turning), ``IMU{i}G{X}FNS`` its
  1-sigma, -1 when the value is a 95 % upper bound (two IMUs: the pair figure bounds each; three: an
  unresolved share of the three-cornered hat);
* ``IMU{i}G{X}GN``, ``IMU{i}G{X}GNS`` the same on the ground (armed, not turning: motors running).
"""

from __future__ import annotations

from companion.health.degradation import DEGRADING
from companion.mavlink.reporter import MAV_SEVERITY_NOTICE, MAV_SEVERITY_WARNING
from companion.service.inflight_live import CONDITIONS, InflightNoise
from companion.service.pickup_hook import PickupHook
from companion.units import to_datasheet

SUFFIX = {"flight": "FN", "ground": "GN"}


def inflight_name(imu: int, axis: str, cond: str, sigma: bool = False) -> str:
    """``IMU0GXFN`` (flight N of gyro X of IMU 0), ``IMU0GXFNS`` its 1-sigma; ground: ``GN``, ``GNS``."""
    return f"IMU{int(imu)}G{axis[1].upper()}{SUFFIX[cond]}{'S' if sigma else ''}"


class InflightReport:
    def __init__(self, pipeline):
        self.p = pipeline
        self.noise = InflightNoise(block_s=pipeline.cfg.block_s)
        self.pickup = PickupHook(self.noise.cfg.test.per_imu_hour)  # each IMU's vibration against its twins'
        self.said: set = set()  # conditions whose figures were announced in the log

    def on_block(self, ch, t: float) -> None:
        p = self.p
        if p.armed and len(p.channels) == 1 and "one" not in self.said:
            from companion.redundancy.redundant import ONE_IMU

            self.said.add("one")
            p.log(f"IMU{ch.imu} armed: {ONE_IMU}")
        due = self.noise.next_check
        verdicts = self.noise.on_block(ch.imu, p.channels, p.armed, t)
        if due is not None and self.noise.next_check != due:  # a check ran
            self._send()
        for v in verdicts:
            text = v.text()
            p.transitions.append((t, text))
            p.log(text)
            p.reporter.statustext(text, MAV_SEVERITY_WARNING if v.state == DEGRADING else MAV_SEVERITY_NOTICE, t)
            p.evidence.on_inflight(p, v, t)
            for imu in v.imus():
                if imu in p.channels:
                    p._set_state(p.channels[imu])
        for v in self.pickup.on_block(p.channels, p.armed, self.noise.cond):
            text = v.text()
            p.transitions.append((t, text))
            p.log(text)
            p.reporter.statustext(text, MAV_SEVERITY_WARNING if v.state == DEGRADING else MAV_SEVERITY_NOTICE, t)
            if v.who in p.channels:
                p._set_state(p.channels[v.who])

    def _send(self) -> None:
        """The latest figures as NAMED_VALUE_FLOATs (a pair's figure under both IMUs' names, as a bound)."""
        rep = self.p.reporter
        for cond in CONDITIONS:
            figs = self.noise.figures[cond]
            if figs and cond not in self.said:
                self.said.add(cond)
                self.p.log(f"{cond} noise figures from the IMU differences: "
                           + ("three-cornered hat" if any(isinstance(w, int) for w in figs) else "pair figure, a bound of each IMU"))
            for who, axes in figs.items():
                imus = who if isinstance(who, tuple) else (who,)
                for ax, (n, s, bound) in axes.items():
                    for imu in imus:
                        rep.set_value(inflight_name(imu, ax, cond), to_datasheet("N", n, ax))
                        sig = -1.0 if (bound or len(imus) > 1) else to_datasheet("N", s, ax)
                        rep.set_value(inflight_name(imu, ax, cond, sigma=True), sig)

    def summary_lines(self, imu: int) -> list[str]:
        """The summary's lines of one IMU: its own noise in each armed condition (deg/sqrt(h))."""
        out = []
        for cond in CONDITIONS:
            figs = self.noise.figures[cond]
            who = imu if imu in figs else next((w for w in figs if isinstance(w, tuple) and imu in w), None)
            if who is None:
                continue
            secs = max(p.whole_s[cond] for k, p in self.noise.pairs.items() if imu in k)  # this flight
            pair = isinstance(who, tuple)
            parts = []
            for ax, (n, s, bound) in figs[who].items():
                v = to_datasheet("N", n, ax)
                parts.append(f"{ax} N < {v:.3g}" if bound or pair else f"{ax} N {v:.3g} +- {to_datasheet('N', s, ax):.2g}")
            how = (f"the pair IMU{who[0]}-IMU{who[1]}'s figure bounds each" if pair else "three-cornered hat")
            out.append(f"  {cond} (own noise from the IMU differences, {how}; {secs:.0f} s): "
                       + "; ".join(parts) + " deg/sqrt(h)")
        return out

    def degrading(self, imu: int) -> bool:
        return self.noise.degrading(imu) or self.pickup.watch.degrading(imu)

    def state_dict(self) -> dict:
        return dict(self.noise.state_dict(), pickup=self.pickup.watch.state_dict())

    def load_state_dict(self, d) -> None:
        self.noise.load_state_dict(d)
        if isinstance(d, dict) and d.get("pickup") is not None:  # a file without it: learned afresh
            self.pickup.watch.load_state_dict(d["pickup"])
