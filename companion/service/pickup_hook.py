"""The pipeline's side of the vibration pick-up test (:mod:`companion.health.pickup`): every ``window_s`` of
flight (the in-flight noise's condition, service/inflight_live.py) one window of all IMUs' recent samples
over one time span, its band powers to the test; the threshold on Z from the test's false-alarm rate per
flight IMU-hour (:func:`companion.service.inflight_alarm.z_threshold`, as the in-flight noise test's)."""

from __future__ import annotations

import numpy as np

from companion.health.pickup import PickupConfig, PickupWatch, band, band_power
from companion.service.inflight_alarm import z_threshold
from companion.service.inflight_align import _held_faulty

MIN_FILL = 0.8  # a window with fewer of its samples (a gap) is left out


def z_on(cfg: PickupConfig, imus: int, per_imu_hour: float) -> float:
    """Z threshold for ``imus`` IMUs (every pair, 3 axes, both ways) at ``per_imu_hour`` false alarms."""
    return z_threshold(per_imu_hour, max(imus, 2), cfg.hold_on, cfg.window_s, cfg.memory_s, cfg.baseline_s)


class PickupHook:
    def __init__(self, per_imu_hour: float, cfg: PickupConfig | None = None):
        self.watch = PickupWatch(cfg)
        self.per_imu_hour = per_imu_hour
        self.t_done: float | None = None
        self._armed = False

    def on_block(self, channels, armed: bool, cond: str | None):
        """After any IMU's block: the flight windows now complete for every IMU; the test's verdicts."""
        if armed and not self._armed:
            self.watch.new_flight()
        self._armed = bool(armed)
        chans = [c for c in channels.values() if c.recent and c.rate_hz]
        held = [c for c in chans if _held_faulty(c)]  # a frozen or clipped gyro's band power is not its pick-up
        for c in held:
            self.watch.drop_imu(c.imu)
        chans = [c for c in chans if c not in held]
        if cond != "flight" or len(chans) < 2 or len(chans) > 3:
            self.t_done = None
            return []
        w = self.watch.cfg.window_s
        end = min(c.recent[-1][0][-1] for c in chans)
        if self.t_done is None or self.t_done > end or self.t_done < end - 10.0 * w:
            self.t_done = end  # a flight (or the data after a gap) starts: windows from here
        if self.t_done + w > end:
            return []
        bands = [band(c.rate_hz) for c in chans]
        if any(b is None for b in bands):
            self.t_done = end
            return []
        lo, hi = max(b[0] for b in bands), min(b[1] for b in bands)
        data = [(np.concatenate([b[0] for b in c.recent]), np.concatenate([b[1] for b in c.recent])) for c in chans]
        z = z_on(self.watch.cfg, len(chans), self.per_imu_hour)
        out = []
        while self.t_done + w <= end:
            w0, self.t_done = self.t_done, self.t_done + w
            powers = {}
            for c, (t, g) in zip(chans, data):
                k0, k1 = np.searchsorted(t, [w0, w0 + w])
                if k1 - k0 < MIN_FILL * w * c.rate_hz:
                    break
                powers[c.imu] = band_power(g[k0:k1], c.rate_hz, lo, hi)
            else:
                out += self.watch.add_window(powers, z)
        return out
