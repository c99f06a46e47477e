"""One configuration schema (companion/config.py): companion/examples/default_config.yaml states exactly its defaults, the
dataclasses built from its sections have the same defaults, and an unknown key or a wrong type is one error
line naming the key."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pytest

from companion import config
from companion.cli.main import main
from companion.errors import CompanionError

ROOT = Path(__file__).resolve().parent.parent


def test_default_yaml_equals_the_schema_defaults():
    assert config.load(ROOT / "companion" / "examples" / "default_config.yaml") == config.defaults()


def _fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


def _plain(v):
    return list(v) if isinstance(v, tuple) else v


def test_dataclass_and_estimator_defaults_equal_the_schema():
    from companion.estimators.miao_shakf import MiaoSHAKF
    from companion.estimators.octave_bank import OctaveBankEstimator
    from companion.mavlink.link import LinkConfig
    from companion.service.pipeline import PipelineConfig

    d = config.defaults()
    run = d["run"]
    link = {k: _plain(v) for k, v in _fields(LinkConfig()).items()}
    assert link == {k: run[k] for k in config.LINK}
    pipe = _fields(PipelineConfig())
    assert {k: _plain(v) for k, v in _fields(pipe.pop("health")).items()} == run["health"]
    assert {k: _plain(v) for k, v in _fields(pipe.pop("faults")).items()} == run["faults"]
    assert pipe.pop("estimator") == {}  # empty: the estimator section's defaults apply
    assert pipe == {k: run[k] for k in config.PIPELINE if k not in ("health", "faults", "estimator")}
    for cls, section in ((OctaveBankEstimator, d["estimator"]), (MiaoSHAKF, d["estimator"]["miao"])):
        sig = inspect.signature(cls.__init__).parameters
        for k, v in section.items():
            if k in sig:
                want = sig[k].default
                want = {} if (k == "x0" and want is None) else _plain(want)
                assert v == want, (cls.__name__, k)


@pytest.mark.parametrize("text, key", [
    ("run:\n  blok_s: 1.0\n", "'run.blok_s'"),
    ("estimator:\n  miao:\n    bb: 0.9\n", "'estimator.miao.bb'"),
    ("runn:\n  block_s: 1.0\n", "'runn'"),
    ("run:\n  block_s: fast\n", "run.block_s must be a number"),
    ("run:\n  accel: 1\n", "run.accel must be a bool"),
    ("run: [1, 2]\n", "run must be a mapping"),
    ("estimator:\n  kind: kalman\n", "estimator.kind must be one of octave, miao"),
])
def test_unknown_key_or_wrong_type_is_one_line_naming_it(tmp_path, capsys, text, key):
    f = tmp_path / "c.yaml"
    f.write_text(text)
    with pytest.raises(CompanionError, match=key.replace(".", r"\.").replace("[", r"\[")):
        config.load(f)
    rc = main(["run", "--source", str(tmp_path / "x.tlog"), "--config", str(f)])
    err = capsys.readouterr().err
    assert rc == 2 and key in err and len(err.strip().splitlines()) == 1


def test_a_valid_partial_file_is_accepted(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("streams:\n  - {message: RAW_IMU, gyro_scale: 1.0e-3}\nrun:\n  sysid: null\n  block_s: 2\n"
                 "  health: {z: 2.5}\n  estimator: {phases: 8}\nestimator:\n  kind: miao\n")
    assert config.load(f)["run"]["block_s"] == 2


@pytest.mark.parametrize("mapping, message", [
    ({"blok_s": 1.0}, "unknown key 'run.blok_s'"),
    ({"health": {"zz": 1.0}}, "unknown key 'run.health.zz'"),
    ({"block_s": "fast"}, "run.block_s must be a number"),
    ({"gap_s": 0}, "run.gap_s must be > 0"),
])
def test_pipeline_config_from_a_mapping_is_checked_against_the_schema(mapping, message):
    """A mapping built in code (not read from a file) goes through the same schema: the key is named."""
    from companion.service.pipeline_config import PipelineConfig

    with pytest.raises(CompanionError, match=message.replace(".", r"\.")):
        PipelineConfig.from_mapping(mapping)
    cfg = PipelineConfig.from_mapping({"block_s": 2, "sysid": 3, "accel": True, "health": {"z": 2.5}})
    assert (cfg.block_s, cfg.sysid, cfg.accel, cfg.health.z, cfg.gap_s) == (2.0, 3, True, 2.5, 0.5)
