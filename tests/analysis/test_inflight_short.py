"""A short flight (analysis.inflight.MIN_FIGURE_SECONDS of aligned data) gets in-flight figures whose 95 %
intervals hold the truth: the coverage over many simulated flights of known per-IMU N, and the figure in
``analyze``'s report of a log that flies only that long."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.analysis.inflight import MIN_FIGURE_SECONDS
from companion.redundancy import ImuTrack, redundant_noise
from tests.redundancy.synthetic import RATE, flight

DEG = math.radians(1.0) / 60.0


def _n(entry: dict):
    """(N, lo, hi, is_bound) of an axis entry's white noise, or None."""
    for t in entry.get("terms", []):
        if t["effect"] == "white_noise":
            return t["N"], t["ci95"]["N"][0], t["ci95"]["N"][1], False
    for b in entry.get("bounds", []):
        if b["effect"] == "white_noise":
            return b["N"], 0.0, b["N"], True
    return None


def _coverage(imus: int, seeds: range, seconds: float) -> tuple[int, int, int]:
    """(axes whose 95 % interval or bound holds the truth, axes, axes with a figure) over simulated flights
    of ``seconds`` with per-IMU N uniform in 0.5-3 deg/sqrt(h) and time offsets up to 2 ms; with two IMUs
    the pair's figure (truth sqrt(N_a^2 + N_b^2)), with three each IMU's share by the hat."""
    hit = total = figures = 0
    for s in seeds:
        rng = np.random.default_rng(4700 + s)
        n_true = rng.uniform(0.5, 3.0, imus) * DEG
        t, g, _ = flight(s, n_true, seconds=seconds, offsets=list(rng.uniform(0.0, 0.002, imus)))
        res = redundant_noise([ImuTrack(t, g[i], RATE) for i in range(imus)], [(t[0], t[-1])],
                              min_seconds=MIN_FIGURE_SECONDS)
        truth = [math.hypot(*n_true)] if imus == 2 else list(n_true)
        ents = [res.pairs[0]["axes"]] if imus == 2 else [p["axes"] for p in res.per_imu]
        for tv, axes in zip(truth, ents):
            for e in axes.values():
                total += 1
                v = _n(e)
                if v is None:
                    continue
                figures += 1
                hit += v[1] <= tv <= v[2]
    return hit, total, figures


def test_pair_interval_holds_the_truth_at_the_minimum_span():
    """Two IMUs, MIN_FIGURE_SECONDS of flight, 30 flights (90 axes): a figure on every axis, and the 95 %
    interval holds the truth on >= 87 % of them (95 % expected; the binomial sd over 90 axes is 2.3 %)."""
    hit, total, figures = _coverage(2, range(30), MIN_FIGURE_SECONDS + 0.5)
    assert figures == total == 90
    assert hit / total >= 0.87, (hit, total)


@pytest.mark.soak
def test_hat_interval_holds_the_truth_at_the_minimum_span():
    """Three IMUs, MIN_FIGURE_SECONDS of flight, 60 flights (540 axes): each share's interval or bound holds
    the truth on >= 91 % of the axes (95 % expected; binomial sd 1 %)."""
    hit, total, figures = _coverage(3, range(60), MIN_FIGURE_SECONDS + 0.5)
    assert figures == total
    assert hit / total >= 0.91, (hit, total)


def test_a_short_flight_gets_figures_in_the_report(armed_flight):
    """A DataFlash log of two IMUs armed throughout and flying for 14 s (12 s once the edges are trimmed,
    below the 30 s the redundancy module asks by default): each IMU gets an in-flight figure (at most the
    pair's) on every axis, and the pair's figure holds its truth within its interval's reach."""
    res = armed_flight(seed=11, n_true=[1.0 * DEG, 2.0 * DEG], seconds=14.0, offsets=[0.0, 0.001])
    entries, n_true = res.entries, res.n_true
    assert len(entries) == 2
    for e in entries:
        f = e["flight"]
        assert MIN_FIGURE_SECONDS <= f["seconds"] < 30.0 and f["method"].startswith("pair difference")
        for ax, r in f["axes"].items():
            v = _n(r)
            assert v is not None and v[3], (ax, f["notes"])
        pair = f["pairs"][0]["N"]
        for ax, n in pair.items():
            assert n is not None and n >= 0.5 * math.hypot(*n_true), (ax, n)


def test_slow_telemetry_cut_into_short_pieces_gets_a_figure():
    """5-Hz streams whose flight is cut into 6-s stretches (30 samples, shorter than the pair fit's
    fractional delay needs) with a time offset of a tenth of a sample: every piece is used (the offset left
    to the first-order term) and each axis gets a figure."""
    t, g, _ = flight(3, [1.0 * DEG, 2.0 * DEG], seconds=60.0, offsets=[0.0, 0.02])
    t, g = t[::40], [x[::40] for x in g]
    stretches = [(a, a + 5.9) for a in (0.0, 8.0, 16.0, 24.0, 32.0)]
    res = redundant_noise([ImuTrack(t, g[i], 5.0) for i in range(2)], stretches, min_seconds=MIN_FIGURE_SECONDS)
    assert res.seconds >= 25.0 and res.pairs
    assert all(_n(e) is not None for p in res.per_imu for e in p["axes"].values())


def test_an_imu_left_out_at_rest_keeps_its_flight_figure(tmp_path):
    """Three IMUs, still then flying: the report of an IMU whose still analysis was left out (as when its gyro
    changed alone at rest) still gains an entry, in the streams' order, with its ground/flight figures."""
    from companion.analysis.condition_hook import add_conditions
    from companion.analysis.source import analyze_source
    from companion.sources import load
    from companion.sim.dataflash_writer import write_imu_log

    n_true = np.array([1.0, 1.5, 2.0]) * DEG
    t, g, _ = flight(21, n_true, seconds=100.0, offsets=[0.0, 0.001, 0.0005])
    still = t < 40.0  # at rest: each IMU's own noise only
    rng = np.random.default_rng(2)
    for x in g:
        x[still] = rng.normal(0.0, 1e-3, x[still].shape)
    t = t + 1.0
    accel = np.zeros((3, t.shape[0], 3))
    accel[..., 2] = -9.8
    path = tmp_path / "three.bin"
    write_imu_log(path, t, np.array(g), accel, layout="4.x", armed=[(0.5, False), (42.0, True)])
    entries, summary = analyze_source(str(path), ["gx", "gy", "gz"])
    assert [e["instance"] for e in entries] == [0, 1, 2] and all(e["axes"] for e in entries)
    res = load(str(path))
    kept = [{k: v for k, v in e.items() if k not in ("flight", "ground")} for e in entries if e["instance"] != 1]
    add_conditions(kept, res.imu_streams(), res.meta, {"notes": []})
    assert [e["instance"] for e in kept] == [0, 1, 2]
    left = kept[1]
    assert not left["axes"] and "not analysed at rest" in left["warnings"][0]
    assert left["flight"]["method"].startswith("three-cornered hat") and len(left["flight"]["axes"]) == 3
    assert all(_n(r) is not None for r in left["flight"]["axes"].values())


def test_a_flight_with_bounds_only_is_analysed_by_analyze_and_fleet(tmp_path):
    """Two IMUs logged at 2 Hz, armed and flying for 60 s: too few cluster times to fit, so each axis gets a
    white-noise bound only. ``analyze`` reports it and ``fleet analyze`` records the log as analysed (not
    failed) with those bounds, each at or above its truth."""
    from companion.analysis.source import analyze_source
    from companion.fleet.task import analyze_log
    from companion.sim.dataflash_writer import write_imu_log

    n_true = np.array([1.0, 2.0]) * DEG
    t, g, _ = flight(5, n_true, seconds=60.0)
    t, g = t[::100] + 1.0, [x[::100] for x in g]
    accel = np.zeros((2, t.shape[0], 3))
    accel[..., 2] = -9.8
    path = tmp_path / "slow.bin"
    write_imu_log(path, t, np.array(g), accel, layout="4.x", armed=[(0.5, True)])
    entries, _ = analyze_source(str(path), ["gx", "gy", "gz"])
    assert len(entries) == 2 and all(_n(r) for e in entries for r in e["flight"]["axes"].values())
    out = analyze_log(str(path))
    assert out["status"] == "ok", out["error"]
    flight_rows = [r for r in out["rows"] if r["condition"] == "flight"]
    assert len(flight_rows) == 6
    for r in flight_rows:
        b = [x for x in r["extra"]["bounds"] if x["effect"] == "white_noise"]
        assert b and b[0]["N"] >= n_true[r["imu"]]
