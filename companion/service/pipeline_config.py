"""Configuration of the live pipeline (``run:`` in the config file): block length, settling, learning,
checks, motion gate thresholds, timestamp rules, estimator and degradation-test settings.

The keys, their defaults and types live in one place, the schema :data:`companion.config.PIPELINE`; the
fields below take their defaults from it and :meth:`PipelineConfig.from_mapping` checks a mapping against
it (an unknown key or a wrong type is a :class:`CompanionError` naming the key)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Mapping

from companion.config import PIPELINE, check
from companion.errors import CompanionError
from companion.health.degradation import DetectorConfig
from companion.health.evidence_rules import FaultLimits

_D = {k: v.default for k, v in PIPELINE.items() if not isinstance(v, dict)}


@dataclass
class PipelineConfig:
    sysid: int | None = _D["sysid"]  # vehicle system id; None: the first one sending IMU data
    block_s: float = _D["block_s"]
    settle_s: float = _D["settle_s"]
    baseline_s: float = _D["baseline_s"]
    check_s: float = _D["check_s"]
    min_report_s: float = _D["min_report_s"]  # still data an estimator needs before its values are reported
    forgetting_fast_s: float = _D["forgetting_fast_s"]
    forgetting_slow_s: float = _D["forgetting_slow_s"]
    accel: bool = _D["accel"]  # also estimate and report the accelerometer axes
    # use a loaded baseline even if it does not match the stream (e.g. a swapped board)
    baseline_force: bool = _D["baseline_force"]
    gyro_mean: float = _D["gyro_mean"]  # rad/s
    gyro_std_factor: float = _D["gyro_std_factor"]
    accel_shift: float = _D["accel_shift"]  # m/s^2
    accel_std: float = _D["accel_std"]  # m/s^2
    # accel axis std above this x its still reference = moving (handling) ...
    accel_std_factor: float = _D["accel_std_factor"]
    accel_std_min: float = _D["accel_std_min"]  # m/s^2: ... and above this
    gyro_limit: float = _D["gyro_limit"]  # rad/s: range limit of the gyro (int16 mrad/s); a sample there is saturated
    fault_ref_s: float = _D["fault_ref_s"]  # still data learned as the reference of the fast fault detectors
    reset_s: float = _D["reset_s"]  # a timestamp this far behind the last one: a reboot
    gap_s: float = _D["gap_s"]  # a longer interval: a gap (the partial block is dropped)
    estimator: dict = field(default_factory=dict)  # passed to make_estimator (e.g. effects, phases, max_tau_s)
    health: DetectorConfig = field(default_factory=DetectorConfig)
    faults: FaultLimits = field(default_factory=FaultLimits)  # magnitude floors of the fault detectors

    @classmethod
    def from_mapping(cls, cfg: Mapping | None) -> "PipelineConfig":
        """A config from the ``run`` keys of the pipeline, checked against the schema (CompanionError naming
        an unknown key or a wrong type); every number must be > 0."""
        cfg = check(dict(cfg or {}), PIPELINE, "run")
        out = cls()
        for f in fields(cls):
            if f.name not in cfg or (cfg[f.name] is None and f.name in ("health", "faults", "estimator")):
                continue
            v = cfg[f.name]
            if f.name == "health":
                out.health = DetectorConfig.from_mapping(v)
            elif f.name == "faults":
                out.faults = FaultLimits.from_mapping(v)
            elif f.name == "estimator":
                out.estimator = dict(v)
            elif f.name == "sysid" or PIPELINE[f.name].type == "bool":
                setattr(out, f.name, v)
            else:
                if not v > 0:
                    raise CompanionError(f"config: run.{f.name} must be > 0, got {v!r}")
                setattr(out, f.name, float(v))
        return out
