"""The evidence `run` keeps of each alarm, against a simulated vehicle with an injected fault: the alarm IMU's
and its twin's gyro around the alarm (bounded, the fault visible in the faulty axis only), the detector's
statistic crossing its threshold at the alarm, the spectrum showing the noise rise, the sentence; kept in
the state and capped."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.mavlink.reporter import Reporter
from companion.service import evidence_log as el
from companion.service.live_snapshot import report_data, snapshot
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.replay import replay_vehicle
from companion.sim.vehicle import Fault, Schedule, VehicleSimulator
from tests.support.sinks import RecordingSink

MODEL = {"rate_hz": 50.0, "axes": {a: [{"effect": "white_noise", "N": 2e-4}] for a in ("gx", "gy", "gz")}}
FAULT_AT = 100.0


@pytest.fixture(scope="module")
def noisy():
    """Two IMUs at rest; IMU1's Y axis noise 6x from 100 s on; 200 s replayed, baseline from 60 s."""
    sim = VehicleSimulator(MODEL, imus=2, seed=4, schedule=Schedule(),
                           fault=Fault("noise", at=FAULT_AT, size=6.0, imu=1, axis="gy"))
    p = Pipeline(PipelineConfig(baseline_s=60.0), Reporter(RecordingSink(), 1.0))
    replay_vehicle(sim, p, 200.0, lsb=1e-3)
    p.evidence.finish()
    return p


def _item(p, kind):
    items = [i for i in p.evidence.all_items() if i["kind"] == kind]
    assert len(items) == 1, [i["text"] for i in p.evidence.all_items()]
    return items[0]


def test_noise_alarm_evidence_shows_the_fault(noisy):
    it = _item(noisy, "noise")
    assert it["imu"] == 1 and it["axis"] == "gy" and FAULT_AT < it["t_s"] < FAULT_AT + 15
    assert "noise rose to" in it["sentence"] and "20 nats" in it["sentence"]
    roles = {s["imu"]: s for s in it["series"]}
    assert roles[1]["role"] == "alarm" and roles[0]["role"] == "twin"
    for s in it["series"]:
        t = np.array(s["t_s"])
        assert t.size <= 2 * el.WINDOW_S / el.BUCKET_S + 1 and t[0] >= it["t_s"] - el.WINDOW_S - 1
        assert t[-1] > it["t_s"] + 50  # the minute after is in (200 s replayed)
    # the spread (max - min per bucket) of the faulty axis after the alarm against before: about 6x; its twin's
    # axis and the same IMU's other axes unchanged
    def spread_ratio(s, ax):
        t = np.array(s["t_s"])
        w = np.array(s["hi"][ax]) - np.array(s["lo"][ax])
        return np.median(w[t > FAULT_AT + 2]) / np.median(w[t < FAULT_AT - 2])
    assert 4.0 < spread_ratio(roles[1], "gy") < 8.0
    for imu, ax in ((1, "gx"), (1, "gz"), (0, "gy")):
        assert 0.7 < spread_ratio(roles[imu], ax) < 1.4, (imu, ax)
    st = it["statistic"]
    t, v, h, state = (np.array(st[k], dtype=float) for k in ("t_s", "value", "threshold", "state"))
    before = t < it["t_s"] - 0.5
    assert np.all(v[before & (t < FAULT_AT)] < 20.0) and np.all(state[before] == 0)
    assert np.all(h[before] == 20.0) and np.all(state[t > it["t_s"] + 0.5] == 1)
    sp = it["spectrum"]
    assert sp["two_sided"] and sp["t1_s"] - sp["t0_s"] > 5
    assert np.mean(sp["psd"]["gy"]) / np.mean(sp["psd"]["gx"]) > 10  # 6x noise: 36x the PSD over most of the window
    assert it["complete"]


def test_allan_alarm_evidence_and_the_kept_state(noisy):
    it = _item(noisy, "allan")
    st = it["statistic"]
    i = st["t_s"].index(min(st["t_s"], key=lambda x: abs(x - it["t_s"])))
    assert st["threshold"][i] == 1.3 and st["value"][i] > 1.3 and "Allan estimate rose" in it["sentence"]
    saved = json.loads(json.dumps(noisy.state_dict()))
    p2 = Pipeline(PipelineConfig(baseline_s=60.0), Reporter(RecordingSink(), 1.0))
    p2.load_state_dict(saved)
    assert [i["text"] for i in p2.evidence.all_items()] == [i["text"] for i in noisy.evidence.all_items()]
    assert len(json.dumps(saved["evidence"])) < 400_000


def test_snapshot_and_report_data_are_json(noisy):
    snap = json.loads(json.dumps(snapshot(noisy)))
    assert [m["imu"] for m in snap["imus"]] == [0, 1] and snap["imus"][1]["health"] == "degrading"
    n = snap["imus"][0]["axes"]["gx"]["coefficients"][0]
    assert n["param"] == "N" and n["ci95"][0] < n["value"] < n["ci95"][1]
    assert abs(n["value"] / 2e-4 - 1) < 0.1  # the simulated N
    adev = snap["imus"][0]["axes"]["gx"]["adev"]
    assert all(lo <= a <= hi for lo, a, hi in zip(adev["lo"], adev["adev"], adev["hi"]))
    assert [a["kind"] for a in snap["alarms"]] == ["noise", "allan"]
    rep = report_data(noisy, "sim")
    assert len(rep["alarms"]) == 2 and rep["imus"][1]["faults"]


def test_the_kept_alarms_are_capped():
    log = el.EvidenceLog()
    for k in range(el.MAX_KEPT + 7):
        log.on_alarm(None, 0, "gx", "spikes", 1.0, "", f"alarm {k}", float(k))
        log.finish()
    items = log.all_items()
    assert len(items) == el.MAX_KEPT and items[-1]["text"] == f"alarm {el.MAX_KEPT + 6}"
    assert not items[0]["complete"] and not math.isnan(items[0]["t_s"])


#: kind -> (the fault's size, the words of the sentence, the check of the faulty axis' buckets after the alarm
#: against before: spread (max - min) ratio, mean shift in rad/s, or the largest excursion)
#: (a stuck axis at rest is named first by the sample-level frozen watch: its sentence and statistic)
KINDS = {"stuck": (0.0, "read one value", lambda before, after: after["spread"] < 0.2 * before["spread"]),
         "bias_jump": (0.01745, "stepped by", lambda before, after: abs(after["mid"] - before["mid"]) > 0.012),
         "spikes": (0.005, "isolated outliers", lambda before, after: after["peak"] > 0.2 > 5 * before["peak"])}


@pytest.mark.parametrize("kind", ["stuck", pytest.param("bias_jump", marks=pytest.mark.soak),
                                  pytest.param("spikes", marks=pytest.mark.soak)])
def test_each_kind_has_readable_evidence(kind):
    """A stuck axis, a 1 deg/s bias step, 0.5 % spikes of 0.3 rad/s on IMU1 Y at 100 s: one alarm of the kind,
    its sentence, its statistic over the bar at the alarm and the fault visible in the faulty axis only."""
    size, words, shows = KINDS[kind]
    fault = Fault("bias" if kind == "bias_jump" else kind, at=FAULT_AT, size=size, imu=1, axis="gy")
    sim = VehicleSimulator(MODEL, imus=2, seed=4, schedule=Schedule(), fault=fault)
    p = Pipeline(PipelineConfig(baseline_s=60.0), Reporter(RecordingSink(), 1.0))
    replay_vehicle(sim, p, 170.0, lsb=1e-3)
    p.evidence.finish()
    it = _item(p, kind)
    assert it["imu"] == 1 and it["axis"] == "gy" and words in it["sentence"] and FAULT_AT <= it["t_s"] < FAULT_AT + 30
    st = it["statistic"]
    t, state = np.array(st["t_s"], dtype=float), np.array(st["state"])
    assert np.all(state[t < it["t_s"] - 0.5] == 0) and state[t > it["t_s"] + 0.5][:3].tolist() == [1, 1, 1]
    if kind != "bias_jump":  # a CUSUM: the evidence reached the bar in the block before the alarm
        before = np.array(st["value"], dtype=float)[t < it["t_s"] + 0.5]
        assert before.max() >= 0.5 * st["threshold"][0]

    def view(s, ax, sel):
        tc = np.array(s["t_s"])
        lo, hi = np.array(s["lo"][ax])[sel(tc)], np.array(s["hi"][ax])[sel(tc)]
        return {"spread": np.median(hi - lo), "mid": np.median((hi + lo) / 2), "peak": np.max(np.abs(np.r_[lo, hi]))}

    for s in it["series"]:
        for ax in ("gx", "gy", "gz"):
            pre = view(s, ax, lambda tc: tc < FAULT_AT - 1)
            post = view(s, ax, lambda tc: tc > it["t_s"] + 1)
            assert shows(pre, post) == (s["imu"] == 1 and ax == "gy"), (s["imu"], ax, pre, post)
