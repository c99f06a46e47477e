"""Implausible records of a damaged log are noise, not IMUs: a DataFlash IMU record whose instance byte is
damaged showed in `inspect` as an extra IMU stream of one sample (`IMU 44`)."""

from __future__ import annotations

import numpy as np
import pytest

from companion.cli.main import main
from companion.sources import load
from companion.sources import dataflash as df
from companion.sim.dataflash_writer import write_imu_log

N = 2000
I_OFFSET = 3 + 8  #: the 4.x IMU record: header (3 bytes), TimeUS (uint64), then the instance byte I


def _two_imu_log(path):
    rng = np.random.default_rng(11)
    t = 1.0 + np.arange(N) / 100.0
    g = rng.normal(0.0, 0.004, (2, N, 3))
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (2, N, 3))
    write_imu_log(path, t, g, a)


def _set_instance(path, records: dict[int, int]):
    """Overwrite the instance byte of IMU records (index in file order -> new instance)."""
    log = df.open_log(path)
    offsets = log.offsets[log.names["IMU"]]
    buf = bytearray(path.read_bytes())
    for j, inst in records.items():
        buf[int(offsets[j]) + I_OFFSET] = inst
    path.write_bytes(bytes(buf))


@pytest.mark.parametrize("damage, why", [
    ({100: 44}, "instance 44 is outside 0-9"),
    ({100: 5}, "1 sample(s) beside 2000 of another instance"),
])
def test_a_damaged_instance_is_noise_not_an_imu(tmp_path, capsys, damage, why):
    p = tmp_path / "d.bin"
    _two_imu_log(p)
    _set_instance(p, damage)
    res = load(p)
    assert [(s.key.instance, s.samples) for s in res.streams] == [(0, N - 1), (1, N)]
    inst = next(iter(damage.values()))
    note = f"d.bin: 1 IMU record(s) with instance {inst} skipped as damaged records ({why}), not an IMU"
    assert note in res.meta["notes"]
    assert main(["inspect", str(p)]) == 0
    out = capsys.readouterr().out
    assert f"IMU         {inst} " not in out and f"note: {note}" in out


def test_a_short_log_of_one_imu_keeps_its_few_samples(tmp_path):
    """The few-samples rule needs another instance with 100x as many: a short log is not noise."""
    p = tmp_path / "short.bin"
    t = 1.0 + np.arange(5) / 100.0
    write_imu_log(p, t, np.zeros((2, 5, 3)) + 0.001, np.zeros((2, 5, 3)) + 9.8)
    assert [(s.key.instance, s.samples) for s in load(p).streams] == [(0, 5), (1, 5)]
