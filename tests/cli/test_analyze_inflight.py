"""`companion analyze` on a log armed throughout (no still data): the table and JSON give each IMU's in-flight
figure, the plot is skipped with a line saying why, and a Kalibr file (a still-noise model) is refused."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.cli.main import main
from tests.redundancy.synthetic import flight

DEG = math.radians(1.0) / 60.0


@pytest.fixture(scope="module")
def armed_log(tmp_path_factory):
    from companion.sim.dataflash_writer import write_imu_log

    t, g, _ = flight(21, np.array([0.7, 1.4, 2.1]) * DEG, seconds=150.0, offsets=[0.0, 0.001, 0.002])
    t = t + 1.0
    accel = np.zeros((3, t.shape[0], 3))
    accel[..., 2] = -9.8
    path = tmp_path_factory.mktemp("armed") / "armed.bin"
    write_imu_log(path, t, np.array(g), accel, layout="4.x", armed=[(0.5, True)])
    return path


def test_table_json_and_plot(armed_log, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["analyze", str(armed_log), "--axes", "gx,gy,gz", "--quiet", "--json", str(out),
                 "--plot", str(tmp_path / "a.png")]) == 0
    text = capsys.readouterr().out
    assert text.count("flight: ") == 3 and "not written: no still data to plot" in text
    assert not (tmp_path / "a.png").exists()
    rep = json.loads(out.read_text())
    for st in rep["streams"]:
        assert st["axes"] == {} and st["flight"]["seconds"] > 100
        assert set(st["flight"]["axes"]) == {"gx", "gy", "gz"}
        for e in st["flight"]["axes"].values():
            assert {"terms", "bounds"} <= set(e) and all("ci95" in t for t in e["terms"])


def test_kalibr_is_refused_without_still_data(armed_log, tmp_path, capsys):
    rc = main(["analyze", str(armed_log), "--axes", "gx,gy,gz", "--quiet", "--kalibr", str(tmp_path / "k.yaml")])
    assert rc != 0 and "not written: no still data" in capsys.readouterr().err
    assert not (tmp_path / "k.yaml").exists()
