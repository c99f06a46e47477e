"""The IMUs of one vehicle as a group (PX4's DataValidatorGroup to the channel's DataValidator): pairwise
disagreement (companion.health.disagreement) on the time both IMUs cover, and naming the IMU at fault.

Inputs: after every block of an IMU, :meth:`ImuGroup.compare` with that IMU and the others (their recent
blocks and still noise references, :class:`companion.service.channel.Channel`); outputs: the
``disagree`` FaultEvents of the named IMUs (the caller reports them). With three or more IMUs the odd one
out is named (its pairs disagree, the others agree); with two both are suspects unless only one of them
has another fault (:meth:`ImuGroup.name` again when another fault appears), or the vehicle rests and only one
of them reads away from its own mean at rest before (``rest``: each IMU's still block means, learned while no
pair holds evidence against it; at rest the true rate is 0, so the IMU whose reading moved is the one at
fault, at any rate, where the bias test needs 5 samples a block); that naming stays until the pair agrees. The named IMUs' fault state
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
REST_TAU_BLOCKS = 60.0  # still blocks of the EWMA of an IMU's mean rate at rest
REST_MIN_BLOCKS = 10  # still blocks before that mean is used


def _period(t: np.ndarray) -> float:
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


class ImuGroup:
    def __init__(self, reset_s: float, limits=None):
        self.reset_s = float(reset_s)
        self.limits = limits  # magnitude floors of the disagreement test (health.evidence_rules.FaultLimits)
        self.pairs: dict[tuple[int, int], PairDisagreement] = {}
        self.pair_done: dict[tuple[int, int], float] = {}
        self.disagree: dict[tuple[int, str], str] = {}  # (imu, axis) -> detail of an active disagreement
        self.rest: dict[int, tuple[np.ndarray, int]] = {}  # imu -> (mean rate at rest, still blocks in it)
        self.now: dict[int, tuple[np.ndarray, bool]] = {}  # imu -> (last block's mean rate, still and disarmed)
        self.blamed: dict[tuple[int, int, int], int] = {}  # (i, j, axis) -> the IMU of the pair named at rest

    def active(self) -> bool:
        return bool(self.disagree)

    def detail(self, imu: int, axis: str) -> str:
        return self.disagree.get((imu, axis), "another IMU")

    def compare(self, imu: int, channels: Mapping[int, "object"], armed: bool, still: bool = False) -> list[FaultEvent]:
        """Compare IMU ``imu`` with every other over the time both have covered since the pair's last test
        (``still``: its last block was judged still); returns the disagreement events of the named IMUs."""
        ch = channels[imu]
        events: list[FaultEvent] = []
        if ch.recent:
            self._at_rest(imu, ch.recent[-1][1].mean(axis=0), still and not armed)
            if still and not armed and len(channels) == 2 and any(p.state == FAULT for p in self.pairs.values()):
                events += self.name(channels, armed)  # the rest may tell which of the two it is
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
                odd = self._rest_odd(i, j, a)
                if other_faults[i] and not other_faults[j]:
                    named = {i: [j]}
                elif other_faults[j] and not other_faults[i]:
                    named = {j: [i]}
                elif odd is not None:
                    named = {odd: [j if odd == i else i]}
                else:
                    named = {i: [j], j: [i]}
            elif len(imus) == 2:
                self.blamed.pop((*imus, a), None)
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

    def _at_rest(self, imu: int, mean: np.ndarray, still: bool) -> None:
        """Each IMU's mean rate at rest: the still blocks' means while no pair holds evidence against it."""
        self.now[imu] = (mean, still)
        if not still or any(imu in key and p.evidence() for key, p in self.pairs.items()):
            return
        ref, n = self.rest.get(imu, (mean, 0))
        w = 1.0 / min(n + 1, REST_TAU_BLOCKS)
        self.rest[imu] = (ref + w * (mean - ref), n + 1)

    def _rest_odd(self, i: int, j: int, a: int) -> int | None:
        """The IMU of the pair (i, j) whose axis ``a`` reads away from its own mean at rest while the other
        does not, both at rest now (once found, kept while the pair disagrees on that axis); None if unknown."""
        if (i, j, a) in self.blamed:
            return self.blamed[(i, j, a)]
        if not all(k in self.now and self.now[k][1] and self.rest.get(k, (None, 0))[1] >= REST_MIN_BLOCKS
                   for k in (i, j)):
            return None
        off = {k: abs(float(self.now[k][0][a] - self.rest[k][0][a])) for k in (i, j)}
        floor = 0.5 * (self.limits.disagree if self.limits is not None else math.radians(5.0))
        for k, o in ((i, j), (j, i)):
            if off[k] >= floor and off[o] <= 0.25 * off[k]:
                self.blamed[(i, j, a)] = k
                return k
        return None

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
