"""A noise or spike fault at rest that clears: the Allan estimators are put back as they stood at its onset, so
the terms `run` reports (and its degradation flag) come back with the gyro instead of carrying the burst for
the estimators' memory; a raised Allan flag whose rise the curves no longer show clears."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.health.degradation import DEGRADING, HEALTHY, DetectorConfig, HealthDetector
from companion.mavlink.reporter import Reporter
from companion.samples import StreamKey
from companion.service.pipeline import Pipeline, PipelineConfig
from tests.support.sinks import RecordingSink

FS = 50.0
N = 2e-4  # rad/s/sqrt(Hz): 1.4 mrad/s per sample at 50 Hz, a float (HIGHRES_IMU) stream
KEY = StreamKey(1, 1, "HIGHRES_IMU", 0)


def record(seed, total, burst=None, factor=3.0, spikes=False):
    """White gyro noise of density N at rest, with a burst ``(t0, t1)`` on gz: its noise ``factor`` times
    larger, or (``spikes``) 0.5 rad/s spikes every 0.5 s."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(total * FS)) / FS
    g = rng.normal(0.0, N * math.sqrt(FS), (t.size, 3))
    if burst is not None:
        bad = (t >= burst[0]) & (t < burst[1])
        if spikes:
            idx = np.flatnonzero(bad)[::int(FS / 2)]
            g[idx, 2] += 0.5
        else:
            g[bad, 2] *= factor
    acc = np.tile([0.0, 0.0, -9.80665], (t.size, 1)) + rng.normal(0.0, 0.02, (t.size, 3))
    return t, g, acc


def feed(p, t, g, acc, lo=0.0, hi=math.inf):
    sel = np.flatnonzero((t >= lo) & (t < hi))
    for i in range(0, sel.size, 500):
        j = sel[i:i + 500]
        p.on_samples(KEY, t[j], g[j], acc[j])


def pipeline():
    p = Pipeline(PipelineConfig(baseline_s=200.0), Reporter(RecordingSink(), 1.0))
    p.on_heartbeat(1, 2, 3, 0)
    return p


def texts(p, after=-math.inf):
    return [(t, s) for t, s in p.transitions if t >= after]


def gz_n(p):
    ch = p.channels[0]
    return next(x for x in ch.report_terms("gz") if x["effect"] == "white_noise")


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.soak), pytest.param(3, marks=pytest.mark.soak)])
def test_noise_burst_leaves_the_estimates_when_it_clears(seed):
    t, g, acc = record(seed, 900.0, burst=(400.0, 460.0))
    p = pipeline()
    feed(p, t, g, acc)
    said = texts(p)
    onset = [tt for tt, s in said if "gyro Z noise" in s and "cleared" not in s]
    clear = [tt for tt, s in said if "gyro Z noise cleared" in s]
    assert onset and clear, said
    ch = p.channels[0]
    assert ch.restored_s > 60.0  # the burst's still data (and the blocks queued before the detector was sure)
    # no degradation stands after the noise has gone: raised during the burst or not, it is over within the
    # detector's hold_off checks of the clear (the estimators' 600-s memory held it ten minutes before)
    assert p.health(ch) == HEALTHY, said
    late = [s for tt, s in said if tt > clear[-1] + 10.0 * (DetectorConfig().hold_off + 1)]
    assert not any("degrading" in s for s in late), said
    # the reported N is the gyro's own again: within 4 sigma of the truth
    n = gz_n(p)
    assert abs(n["N"] - N) < 4.0 * n["std"]["N"] + 0.02 * N, (n, N)
    row = p.summary()[0]
    assert any("taken back out of the Allan estimates" in x for x in row["notes"])
    # the summary's final analysis (analyze's figure) leaves the burst's still samples out as well
    fin = row["final"]
    assert fin["kept_s"] == pytest.approx(ch.fed_s) and all(b <= 400.0 or a >= 460.0 for a, b in fin["ranges_s"])
    fn = next(x for x in fin["axes"]["gz"]["terms"] if x["effect"] == "white_noise")
    assert fn["ci95"]["N"][0] - 0.02 * N < N < fn["ci95"]["N"][1] + 0.02 * N, (fn, N)


def test_the_estimates_show_the_fault_while_it_lasts():
    t, g, acc = record(4, 520.0, burst=(400.0, 520.0), factor=2.0)
    p = pipeline()
    feed(p, t, g, acc)
    assert any("gyro Z noise" in s for _, s in texts(p))
    assert p.channels[0]._before_fault is not None
    assert gz_n(p)["N"] > 1.15 * N  # fed as usual while active: N follows the noisier gyro


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_spike_burst_is_put_back_too():
    t, g, acc = record(5, 800.0, burst=(400.0, 430.0), spikes=True)
    p = pipeline()
    feed(p, t, g, acc)
    said = texts(p)
    assert any("spike" in s for _, s in said), said
    ch = p.channels[0]
    assert ch.restored_s > 25.0
    n = gz_n(p)
    assert abs(n["N"] - N) < 4.0 * n["std"]["N"] + 0.02 * N, (n, N)


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_state_saved_during_the_fault_keeps_the_estimators_of_its_onset():
    t, g, acc = record(6, 900.0, burst=(400.0, 460.0))
    p = pipeline()
    feed(p, t, g, acc, hi=430.0)
    assert p.channels[0]._before_fault is not None
    state = json.loads(json.dumps(p.state_dict()))
    q = Pipeline(PipelineConfig(baseline_s=200.0), Reporter(RecordingSink(), 1.0))
    q.load_state_dict(state)
    q.on_heartbeat(1, 2, 3, 0)
    feed(q, t, g, acc, lo=430.0)
    assert any("gyro Z noise cleared" in s for _, s in texts(q))
    assert q.channels[0].restored_s > 25.0
    assert q.health(q.channels[0]) == HEALTHY, texts(q)


def test_a_raised_flag_clears_on_checks_that_do_not_show_the_rise():
    cfg = DetectorConfig()
    d = HealthDetector(0, cfg)
    base = {"N": (1.0, 0.01)}
    for _ in range(cfg.hold_on):
        d.check("gz", {"N": (1.5, 0.01)}, base)
    assert d.state == DEGRADING
    # N 1.01x: above the baseline, not a rise the curves show (left out of `current`)
    for i in range(cfg.hold_off):
        assert d.state == DEGRADING
        out = d.check("gz", {}, base, unshown={"N": (1.01, 0.01)})
    assert d.state == HEALTHY and out and "back to normal" in out[0].text()
    # while healthy such checks change nothing, nor do they count towards raising
    d2 = HealthDetector(0, cfg)
    d2.check("gz", {"N": (1.5, 0.01)}, base)
    d2.check("gz", {}, base, unshown={"N": (1.5, 0.01)})
    d2.check("gz", {"N": (1.5, 0.01)}, base)
    assert d2.state == HEALTHY
    d2.check("gz", {"N": (1.5, 0.01)}, base)
    assert d2.state == DEGRADING
