"""Configuration of the live pipeline (``run:`` in the config file): block length, settling, learning,
checks, motion gate thresholds, timestamp rules, estimator and degradation-test settings."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Mapping

from companion.health.detector import DetectorConfig


@dataclass
class PipelineConfig:
    sysid: int | None = None  # vehicle system id; None: the first one sending IMU data
    block_s: float = 1.0
    settle_s: float = 10.0
    baseline_s: float = 600.0
    check_s: float = 10.0
    min_report_s: float = 30.0  # still data an estimator needs before its values are reported
    forgetting_fast_s: float = 600.0
    forgetting_slow_s: float = 7200.0
    accel: bool = False  # also estimate and report the accelerometer axes
    baseline_force: bool = False  # use a loaded baseline even if it does not match the stream (e.g. a swapped board)
    gyro_mean: float = 0.1  # rad/s
    gyro_std_factor: float = 5.0
    accel_shift: float = 0.3  # m/s^2
    accel_std: float = 0.5  # m/s^2
    accel_std_factor: float = 3.0  # accel axis std above this x its still reference = moving (handling)
    accel_std_min: float = 0.05  # m/s^2: ... and above this
    gyro_limit: float = 32.767  # rad/s: range limit of the gyro (int16 mrad/s); a sample there is saturated
    fault_ref_s: float = 30.0  # still data learned as the reference of the fast fault detectors
    reset_s: float = 1.0
    gap_s: float = 0.5
    estimator: dict = field(default_factory=dict)  # passed to make_estimator (e.g. effects, phases, max_tau_s)
    health: DetectorConfig = field(default_factory=DetectorConfig)

    @classmethod
    def from_mapping(cls, cfg: Mapping | None) -> "PipelineConfig":
        out = cls()
        names = {f.name for f in fields(cls)}
        for k, v in dict(cfg or {}).items():
            if k not in names:
                raise ValueError(f"run: unknown key {k!r}")
            if k == "health":
                out.health = DetectorConfig.from_mapping(v)
            elif k == "estimator":
                out.estimator = dict(v or {})
            elif k == "sysid":
                out.sysid = None if v is None else int(v)
            elif k in ("accel", "baseline_force"):
                setattr(out, k, bool(v))
            else:
                out.__setattr__(k, float(v))
                if not float(v) > 0:
                    raise ValueError(f"run: {k} must be > 0, got {v!r}")
        return out
