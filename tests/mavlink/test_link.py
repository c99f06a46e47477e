"""Link health: lost, out-of-order, duplicate and late frames per source from MAVLink sequence numbers, the
loss STATUSTEXT, and the estimator through a lossy relay over loopback (20 % random loss, bursts of loss)."""

from __future__ import annotations

import random
import re

import pytest
from tests.support.relay import N_TRUE, loop_through_relay

from companion.mavlink.link import LinkStats, SourceStats


class Msg:
    def __init__(self, seq, sysid=1, compid=1, mtype="RAW_IMU", t=None):
        self.seq, self.sysid, self.compid, self.mtype = seq & 0xFF, sysid, compid, mtype
        self.time_usec = t
        self.id = 0

    def get_type(self):
        return self.mtype

    def get_seq(self):
        return self.seq

    def get_srcSystem(self):
        return self.sysid

    def get_srcComponent(self):
        return self.compid


def test_sequence_accounting_with_wrap_loss_reorder_and_duplicates():
    rng = random.Random(4)
    st = SourceStats()
    sent = list(range(5000))  # wraps the 8-bit counter many times
    kept = [s for s in sent if rng.random() > 0.2]
    dropped = len(sent) - len(kept)
    # swap a few neighbours (reordering) and repeat a few frames (duplicates)
    for i in range(100, 4000, 400):
        kept[i], kept[i + 1] = kept[i + 1], kept[i]
    out = []
    dups = 0
    for i, s in enumerate(kept):
        out.append(s)
        if i % 500 == 250:  # (never next to a swapped pair)
            out.append(s)
            dups += 1
    for s in out:
        st.on_seq(s & 0xFF)
    assert st.received == len(out)
    assert dups >= 7 and st.duplicates == dups
    assert st.out_of_order == 10
    assert st.lost == dropped
    assert st.loss_fraction() == pytest.approx(dropped / len(sent), abs=1e-3)


def test_late_imu_samples_and_sources_are_separate():
    ls = LinkStats()
    for k, t in enumerate([1_000, 2_000, 3_000, 2_500, 4_000, 4_000]):
        ls.on_message(Msg(k, t=t))
    for k in range(10):
        ls.on_message(Msg(k * 2, sysid=255, compid=190, mtype="HEARTBEAT"))
    a, g = ls.sources[(1, 1)], ls.sources[(255, 190)]
    assert a.late == 1 and a.lost == 0
    assert g.lost == 9 and g.received == 10
    lines = ls.summary_lines()
    assert any(line.startswith("link from 1/1: 6 frames received, 0 lost") for line in lines)


# ---------------------------------------------------------------- over loopback, through a lossy relay
def check_loss_run(out, sim_out, relay, lo, hi):
    m = re.search(r"link from 1/1: (\d+) frames received, (\d+) lost \(([\d.]+) %\)", out)
    assert m, out
    received, lost = int(m.group(1)), int(m.group(2))
    assert received == relay.forwarded  # run read all the relay handed on ...
    assert lost == relay.dropped  # ... and counted exactly what it dropped
    assert lo <= relay.dropped / (relay.dropped + relay.forwarded) <= hi
    assert "companion: link loss" in out  # the warning (sent as STATUSTEXT; logged on stderr)
    for ax in "xyz":
        n = re.search(rf"  g{ax} online: N ([\d.]+) \+- ([\d.]+) ", out)  # what run sent live
        assert n, out
        value, sigma = float(n.group(1)), float(n.group(2))
        # within 5 %, or within twice the 1-sigma the report gives when it widened it: under 20 % burst loss
        # only ~50 s of still blocks are fed, and a chance bump at 1-3 s (2.5 sigma on one axis) makes the fit
        # declare a misfit; N then comes from the local white-noise refit from 10 tau0 on, whose own scatter
        # on 50 s is ~3.5 % (measured -1.5 % on that axis, -6.3 % when the refit weighted its points by
        # 1 / measured AVAR^2, which favours the points that lie low: docs/analysis.md). The reported sigma is
        # the global interval's, scaled and widened (4.6 % when this was written, 5.9 % later, 6.3 % since the
        # selection envelope's lower end allows for a B estimated at zero in the forced model): a useful
        # interval still, and this guards that it stays one
        assert abs(value - N_TRUE) <= max(0.05 * N_TRUE, 2.0 * sigma), (ax, value, sigma)
        assert sigma < 0.07 * N_TRUE, (ax, value, sigma)


@pytest.mark.network
def test_twenty_percent_random_loss(tmp_path):
    # at 20x: the same 150 s and 20 % of loss as the bursts (10x) in half the wall-clock time; the relay counts
    # what it drops whatever the pace, and run reads what it keeps at its own
    out, sim_out, relay = loop_through_relay(tmp_path, speedup=20.0, p=0.2)
    check_loss_run(out, sim_out, relay, 0.17, 0.23)


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
@pytest.mark.network
def test_bursts_of_loss(tmp_path):
    # Gilbert model: bursts of 1/0.08 = 12.5 datagrams on average (125 ms at 100 Hz), 20 % lost overall
    out, sim_out, relay = loop_through_relay(tmp_path, burst=(0.02, 0.08))
    check_loss_run(out, sim_out, relay, 0.12, 0.28)


def test_long_runs_of_loss_are_counted_from_message_time():
    """A run of >= 128 lost frames reads as reordering and one of 256 is invisible in 8-bit sequence
    numbers; the IMU timestamps resolve both (three IMUs and heartbeats interleaved on one sender)."""
    ls = LinkStats()
    seq, frames, dropped = 0, [], 0
    for k in range(20_000):  # 100 Hz, three IMU messages per sample, a heartbeat every 100 samples
        t = 1_000_000 + k * 10_000
        batch = [Msg(0, mtype="RAW_IMU", t=t)] + [Msg(0, mtype=m, t=None) for m in ("SCALED_IMU2", "SCALED_IMU3")]
        for m in batch[1:]:
            m.time_boot_ms = t // 1000
        if k % 100 == 0:
            batch.append(Msg(0, mtype="HEARTBEAT"))
        for m in batch:
            m.seq = seq & 0xFF
            seq += 1
            frames.append(m)
    kept = []
    for i, m in enumerate(frames):
        # outages of 150, 256, 300 and 1000 frames, plus a few single losses
        if 5_000 <= i < 5_150 or 20_000 <= i < 20_256 or 30_000 <= i < 30_300 or 40_000 <= i < 41_000 or i % 997 == 0:
            dropped += 1
        else:
            kept.append(m)
    for m in kept:
        ls.on_message(m)
    st = ls.sources[(1, 1)]
    assert st.out_of_order == 0
    assert st.lost == pytest.approx(dropped, abs=4)
