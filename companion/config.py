"""The configuration schema: every key of the YAML configuration, its default and its type, in one place.

``companion/examples/default_config.yaml`` documents exactly these defaults (a test keeps them equal). ``PipelineConfig`` and
``LinkConfig`` take their defaults from here; ``DetectorConfig`` (numerical core, which may not import this
module) holds its own and :data:`HEALTH` is read from it; the estimators' keyword defaults are kept equal
to :data:`ESTIMATOR` by a test. :func:`load` reads a configuration file and checks it against the schema: an
unknown key or a value of the wrong type is a one-line :class:`CompanionError` naming the key
(``config: unknown key 'run.blok_s'``). Values are checked further (ranges) where they are used.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from companion.errors import CompanionError, not_text


@dataclass(frozen=True)
class Key:
    """One setting: its default and its type (number, int, bool, str, list, mapping; ``none``: null allowed)."""

    default: object
    type: str
    none: bool = False
    choices: tuple = ()


_EFFECTS = ["quantization", "white_noise", "bias_instability", "random_walk", "ramp", "gauss_markov", "sinusoid"]

ESTIMATOR = {
    "kind": Key("octave", "str", choices=("octave", "miao")),
    "effects": Key(_EFFECTS, "list"),
    "phases": Key(16, "int"),
    "max_tau_s": Key(20000.0, "number"),
    "min_edf": Key(1.0, "number"),
    "fit": Key("model", "str", choices=("model", "diag", "gls", "fit_avar")),
    "gls_max_ratio": Key(256, "int"),
    # the data's 2-pole low-pass cut-off (Hz) when the log or link does not say it (INS_GYRO_FILTER,
    # IMU_GYRO_CUTOFF); null: the autopilot's parameter when known, else a roll-off the data show
    "filter_hz": Key(None, "number", none=True),
    "miao": {
        "b": Key(0.99, "number"),
        "x0": Key({}, "mapping"),
        "p0_rel": Key(1.0, "number"),
        "q0_rel": Key(1.0e-4, "number"),
        "r0": Key(None, "number", none=True),
        "init_samples": Key(100, "int"),
        "noise_mean": Key(True, "bool"),
    },
}

def _keys_of(cls) -> dict:
    """Schema keys from a dataclass of the numerical core, which holds its own defaults (the core may not
    import this adapter module); the type follows the default's."""
    from dataclasses import fields

    kinds = {float: "number", int: "int", bool: "bool", str: "str", tuple: "list", list: "list"}
    out = {}
    for f in fields(cls):
        v = f.default
        out[f.name] = Key(list(v) if isinstance(v, tuple) else v, kinds[type(v)])
    return out


def _health_keys() -> dict:
    from companion.health.degradation import DetectorConfig

    return _keys_of(DetectorConfig)


#: the degradation test (companion.health.degradation.DetectorConfig holds the defaults)
HEALTH = _health_keys()


def _fault_keys() -> dict:
    from companion.health.evidence_rules import FaultLimits

    return _keys_of(FaultLimits)


#: the fault detectors' magnitude floors (companion.health.evidence_rules.FaultLimits holds the defaults)
FAULTS = _fault_keys()

#: keys of the run section that configure the link (companion.mavlink.link.LinkConfig)
LINK = {
    "rate_hz": Key(100.0, "number"),
    "messages": Key(["RAW_IMU", "SCALED_IMU2", "SCALED_IMU3"], "list"),
    "compid": Key(191, "int"),
    "heartbeat_s": Key(1.0, "number"),
    "stale_s": Key(3.0, "number"),
    "retry_s": Key(5.0, "number"),
    "loss_warn": Key(0.05, "number"),
    "loss_window_s": Key(30.0, "number"),
}

#: keys of the run section that the command itself uses (reports, the state file)
RUNNER = {
    "report_period_s": Key(1.0, "number"),
    "state_file": Key(None, "str", none=True),
    "save_period_s": Key(60.0, "number"),
}

#: keys of the run section that configure the pipeline (companion.service.pipeline.PipelineConfig)
PIPELINE = {
    "sysid": Key(None, "int", none=True),
    "baseline_s": Key(600.0, "number"),
    "block_s": Key(1.0, "number"),
    "settle_s": Key(10.0, "number"),
    "check_s": Key(10.0, "number"),
    "min_report_s": Key(30.0, "number"),
    "forgetting_fast_s": Key(600.0, "number"),
    "forgetting_slow_s": Key(7200.0, "number"),
    "accel": Key(False, "bool"),
    "baseline_force": Key(False, "bool"),
    "gyro_mean": Key(0.1, "number"),
    "gyro_std_factor": Key(5.0, "number"),
    "accel_shift": Key(0.3, "number"),
    "accel_std": Key(0.5, "number"),
    "accel_std_factor": Key(3.0, "number"),
    "accel_std_min": Key(0.05, "number"),
    "gyro_limit": Key(32.767, "number"),
    "fault_ref_s": Key(30.0, "number"),
    "reset_s": Key(1.0, "number"),
    "gap_s": Key(0.5, "number"),
    "estimator": ESTIMATOR,  # optional: the top-level estimator section is used when absent
    "faults": FAULTS,
    "health": HEALTH,
}

#: the whole configuration file
SCHEMA = {
    "streams": Key([], "list"),  # per-stream scale overrides, checked entry by entry by sources.decode.ScaleTable
    "estimator": ESTIMATOR,
    "run": {**LINK, **RUNNER, **PIPELINE},
}


def defaults(schema: dict = SCHEMA, documented: bool = True) -> dict:
    """The default configuration as a plain dict (``documented``: without ``run.estimator``, which the
    top-level ``estimator`` section stands for and companion/examples/default_config.yaml does not repeat)."""
    out = {}
    for k, v in schema.items():
        if documented and schema is SCHEMA["run"] and k == "estimator":
            continue
        out[k] = defaults(v, documented) if isinstance(v, dict) else _copy(v.default)
    return out


def _copy(v):
    return list(v) if isinstance(v, list) else dict(v) if isinstance(v, dict) else v


_TYPES = {
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "bool": lambda v: isinstance(v, bool),
    "str": lambda v: isinstance(v, str),
    "list": lambda v: isinstance(v, (list, tuple)),
    "mapping": lambda v: isinstance(v, dict),
}


def check(cfg, schema: dict = SCHEMA, where: str = "") -> dict:
    """Check a configuration mapping against the schema; returns it. Unknown keys and wrong types raise
    :class:`CompanionError` naming the dotted key."""
    if not isinstance(cfg, dict):
        raise CompanionError(f"config: {where or 'the configuration'} must be a mapping, got {_kind(cfg)}")
    for k, v in cfg.items():
        name = f"{where}.{k}" if where else str(k)
        spec = schema.get(k)
        if spec is None:
            raise CompanionError(f"config: unknown key {name!r} (allowed here: {', '.join(schema)})")
        if isinstance(spec, dict):
            if v is not None:
                check(v, spec, name)
            continue
        if v is None:
            if spec.none:
                continue
            raise CompanionError(f"config: {name} must be a {spec.type}, got null")
        if not _TYPES[spec.type](v):
            raise CompanionError(f"config: {name} must be a {spec.type}, got {_kind(v)} {v!r}"[:200])
        if spec.choices and v not in spec.choices:
            raise CompanionError(f"config: {name} must be one of {', '.join(spec.choices)}, got {v!r}")
    return cfg


def _kind(v) -> str:
    return {dict: "mapping", list: "list", str: "string", bool: "bool"}.get(type(v), type(v).__name__)


def load(config) -> dict:
    """``config`` as a dict: None (empty), a dict (built in code, taken as it is), or a path to a YAML file
    (checked against the schema)."""
    if config is None:
        return {}
    if isinstance(config, dict):
        return config
    import yaml

    path = Path(config)
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such config file") from None
    except UnicodeDecodeError as exc:
        raise not_text(path, exc, "a configuration is a YAML file (see config/)") from None
    except OSError as exc:
        raise CompanionError(f"{path}: cannot read config ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise CompanionError(f"{path}: invalid YAML ({str(exc).splitlines()[0]})") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise CompanionError(f"{path}: the configuration must be a YAML mapping")
    try:
        return check(data)
    except CompanionError as exc:
        raise CompanionError(f"{path}: {exc}") from None
