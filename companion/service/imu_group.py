"""The IMUs of one vehicle as a group (PX4's DataValidatorGroup to the channel's DataValidator): pairwise
disagreement (companion.health.disagreement) on the time both IMUs cover, and naming the IMU at fault.

Inputs: after every block of an IMU, :meth:`ImuGroup.compare` with that IMU and the others (their recent
blocks and still noise references, :class:`companion.service.channel.Channel`); outputs: the
``disagree`` FaultEvents of the named IMUs (the caller reports them). With three or more IMUs the odd one
out is named (its pairs disagree, the others agree); with two both are suspects unless only one of them
has another fault (:meth:`ImuGroup.name` again when another fault appears). The named IMUs' fault state
gets the ``disagree`` kind (``ImuFaults.set_external``). A pair's disagreement on an axis is held (not
cleared) while either IMU has a fault of ``CAUSES`` on that axis.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from companion.health.disagreement import PairDisagreement
from companion.health.faults import AXES, FaultEvent, Observation
from companion.health.hold import FAULT, OK

MIN_ALIGNED = 10  # samples both IMUs cover before a pair is tested (fewer give no usable block mean)
#: faults that move a gyro's mean rate: while one of them is active on an axis of either IMU of a pair, the
#: pair's disagreement on that axis has its cause and is not cleared (a gyro frozen near the rate of a long
#: hover agrees with the other IMU there: clearing would name the same fault again at the next turn)
CAUSES = ("stuck", "dead", "saturation", "bias_jump", "bias_drift")
SAME_RATE = 1.2  # periods within this ratio: the lower-numbered IMU's instants are the common ones


def _period(t: np.ndarray) -> float:
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


class ImuGroup:
    def __init__(self, reset_s: float, limits=None):
        self.reset_s = float(reset_s)
        self.limits = limits  # magnitude floors of the disagreement test (health.evidence_rules.FaultLimits)
        self.pairs: dict[tuple[int, int], PairDisagreement] = {}
        self.pair_done: dict[tuple[int, int], float] = {}
        self.disagree: dict[tuple[int, str], str] = {}  # (imu, axis) -> detail of an active disagreement

    def active(self) -> bool:
        return bool(self.disagree)

    def detail(self, imu: int, axis: str) -> str:
        return self.disagree.get((imu, axis), "another IMU")

    def compare(self, imu: int, channels: Mapping[int, "object"], armed: bool) -> list[FaultEvent]:
        """Compare IMU ``imu`` with every other over the time both have covered since the pair's last test;
        returns the disagreement events of the named IMUs."""
        ch = channels[imu]
        events: list[FaultEvent] = []
        for other in list(channels.values()):
            if other is ch or not other.recent or not ch.recent:
                continue
            i, j = sorted((ch.imu, other.imu))
            ci, cj = channels[i], channels[j]
            key = (i, j)
            pair = self.pairs.get(key)
            if pair is None:
                pair = self.pairs[key] = PairDisagreement(i, j, self.limits)
            ti = np.concatenate([b[0] for b in ci.recent])
            tj = np.concatenate([b[0] for b in cj.recent])
            t_end = min(ti[-1], tj[-1])
            t_done = self.pair_done.get(key, -math.inf)
            if t_end < t_done - self.reset_s:  # reboot: time starts again
                t_done = -math.inf
            gi_all = np.concatenate([b[1] for b in ci.recent])
            gj_all = np.concatenate([b[1] for b in cj.recent])
            # compared at the instants of the slower stream, the faster one interpolated there: each block's
            # mean then comes from the same instants on both sides. The other way round a 2 Hz snapshot
            # stream (a PX4 log's vehicle_imu) would be interpolated between its snapshots at a 220 Hz
            # stream's instants, and in flight the line between two snapshots half a second apart is no
            # rate: a healthy pair would disagree
            pi_, pj_ = _period(ti), _period(tj)
            base_i = pi_ >= pj_ or pj_ <= SAME_RATE * pi_  # IMU i's instants unless IMU j is clearly slower
            (ts, gs), (tf, gf), pf = ((ti, gi_all), (tj, gj_all), pj_) if base_i else ((tj, gj_all), (ti, gi_all), pi_)
            mask = (ts > t_done) & (ts <= t_end) & (ts >= tf[0])
            if np.count_nonzero(mask) < MIN_ALIGNED:
                continue
            t = ts[mask]
            k = np.clip(np.searchsorted(tf, t), 1, tf.size - 1)
            near = np.minimum(np.abs(tf[k] - t), np.abs(tf[k - 1] - t))
            ok = near <= 1.5 * pf
            if np.count_nonzero(ok) < MIN_ALIGNED:
                self.pair_done[key] = t_end
                continue
            g_slow = gs[mask][ok]
            g_fast = np.column_stack([np.interp(t[ok], tf, gf[:, a]) for a in range(3)])
            gi, gj = (g_slow, g_fast) if base_i else (g_fast, g_slow)
            self.pair_done[key] = t_end
            nv = [ci.faults.noise_ref(ax) for ax in AXES] + [cj.faults.noise_ref(ax) for ax in AXES]
            ready = all(v is not None for v in nv)
            noise_var = (max(nv[:3]) + max(nv[3:])) if ready else None
            obs = Observation(i, y=gi, other=gj, other_imu=j, noise_var=noise_var,
                              noise_other=max(nv[3:]) if ready else None)
            causes = {ax for c in (ci, cj) for kind, ax in c.faults.active() if kind in CAUSES}
            if pair.update(obs, held=[ax in causes for ax in AXES]):
                events += self.name(channels, armed)
        return events

    def name(self, channels: Mapping[int, "object"], armed: bool) -> list[FaultEvent]:
        """From pair states to named IMUs: with three or more the odd one out (its pairs disagree, the
        others agree); with two both are suspects unless only one of them has another fault."""
        imus = sorted(channels)
        events = []
        for a, ax in enumerate(AXES):
            bad = {k for k, p in self.pairs.items() if p.axis_state(a) == FAULT}
            named: dict[int, list[int]] = {}
            if len(imus) == 2 and bad:
                i, j = imus
                other_faults = {k: [f for f in channels[k].faults.active() if f[0] != "disagree"] for k in (i, j)}
                if other_faults[i] and not other_faults[j]:
                    named = {i: [j]}
                elif other_faults[j] and not other_faults[i]:
                    named = {j: [i]}
                else:
                    named = {i: [j], j: [i]}
            elif len(imus) >= 3 and bad:
                partners = {k: sorted(p[0] if p[1] == k else p[1] for p in bad if k in p) for k in imus}
                most = max(len(v) for v in partners.values())
                named = {k: v for k, v in partners.items() if len(v) >= 2 and len(v) == most}
            for k in imus:
                was = (k, ax) in self.disagree
                now = k in named
                if was == now:
                    continue
                pair = self.pairs.get(tuple(sorted((k, named[k][0])))) if now else None
                value = pair.value[a] if pair is not None else math.nan
                detail = "/".join(f"IMU{o}" for o in named[k]) if now else ""
                if now:
                    self.disagree[(k, ax)] = detail
                else:
                    self.disagree.pop((k, ax), None)
                channels[k].faults.set_external("disagree", ax, FAULT if now else OK)
                events.append(FaultEvent(k, ax, "disagree", FAULT if now else OK, value, detail,
                                         critical=armed and now))
        return events

    def state_dict(self) -> dict:
        return {"pairs": {f"{i}-{j}": p.state_dict() for (i, j), p in self.pairs.items()},
                "disagree": [[k, a, d] for (k, a), d in self.disagree.items()]}

    def load_state_dict(self, d: Mapping) -> None:
        pairs = {}
        for key, pd in (d.get("pairs") or {}).items():
            i, j = (int(v) for v in key.split("-"))
            pairs[(i, j)] = PairDisagreement(i, j, self.limits)
            pairs[(i, j)].load_state_dict(pd)
        self.pairs = pairs
        self.disagree = {(int(k), str(a)): str(dt) for k, a, dt in d.get("disagree") or []}
