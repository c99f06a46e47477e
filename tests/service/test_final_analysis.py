"""``run``'s final report: ``analyze``'s figure on the still samples the run fed its estimators; the samples
follow the estimators (a memory budget, a restart; a transient fault's blocks taken back out:
tests/service/test_transient_faults.py) and the summary says why a figure is missing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.analysis.stream import pieces_entry
from companion.mavlink.reporter import Reporter
from companion.service.final_analysis import final_analysis
from companion.service.pipeline import Pipeline, PipelineConfig
from companion.service.run_session import summary_lines
from companion.service.still_record import StillRecord
from tests.service.test_transient_faults import FS, KEY, feed, record
from tests.support.sinks import RecordingSink

COLS = {"t": 0, "gx": 1, "gy": 2, "gz": 3}


def _block(t0, n=50, value=0.0):
    rows = np.zeros((n, 8))
    rows[:, 0] = t0 + np.arange(n) / FS
    rows[:, 1:4] = value
    return rows


def test_record_pieces_budget_and_trim():
    rec = StillRecord(COLS, max_bytes=3 * 50 * 4 * 8)  # three 1-s blocks of time + 3 axes
    rec.add(_block(0.0, value=1.0), 1.0, junction=False)
    rec.add(_block(1.0, value=2.0), 1.0, junction=False)
    rec.add(_block(5.0, value=3.0), 1.0, junction=True)  # a new piece
    assert [p.shape[0] for p in rec.axis_pieces("gx")] == [100, 50] and rec.kept_s == 3.0
    rec.add(_block(6.0, value=4.0), 1.0, junction=False)  # over the budget: the oldest block goes
    assert rec.dropped_s == 1.0 and rec.kept_s == 3.0
    assert [np.unique(p).tolist() for p in rec.axis_pieces("gx")] == [[2.0], [3.0, 4.0]]
    mark = rec.mark(unfed_blocks=1)  # the last block was still queued at the snapshot
    rec.add(_block(7.0, value=5.0), 1.0, junction=False)  # drops the block of value 2.0 (budget)
    rec.trim(mark)
    assert [np.unique(p).tolist() for p in rec.axis_pieces("gx")] == [[3.0]] and rec.kept_s == 1.0
    assert rec.ranges_s() == [(5.0, 5.0 + 49 / FS)]
    rec.trim(["another record", 0])  # a mark taken before a restart: everything came after it
    assert rec.axis_pieces("gx") == [] and rec.kept_s == 0.0


def _pipeline(**cfg):
    p = Pipeline(PipelineConfig(**{"baseline_s": 200.0, **cfg}), Reporter(RecordingSink(), 1.0))
    p.on_heartbeat(1, 2, 3, 0)
    return p


def test_summary_says_why_there_is_no_final_analysis():
    """15 s still: the 10-s settling and the look-ahead leave 3 s of still samples, too few; the summary says so."""
    t, g, acc = record(2, 15.0)
    p = _pipeline()
    feed(p, t, g, acc)
    text = "\n".join(summary_lines(p))
    assert "final analysis: none, only 3 s of still samples kept (< 10 s)" in text, text


def test_after_a_restart_the_earlier_still_data_are_said_to_be_online_only():
    """A state file carries the estimators, not the samples: after the restart the final analysis covers the
    still data since, and the summary says how many seconds are in the online estimates only."""
    import json

    t, g, acc = record(3, 70.0)
    p = _pipeline()
    feed(p, t, g, acc)
    before = p.channels[0].fed_s
    q = _pipeline()
    q.load_state_dict(json.loads(json.dumps(p.state_dict())))  # what a state file holds
    feed(q, t + 200.0, g, acc)
    fin = final_analysis(q.channels[0])
    assert fin["missing_s"] == pytest.approx(before) and fin["kept_s"] > 50.0, fin
    text = "\n".join(summary_lines(q))
    assert f"{before:.0f} s fed before the restart from the state file are in the online estimates only" in text
    e = fin["axes"]["gx"]
    assert e == pieces_entry(q.channels[0].bank.record.axis_pieces("gx"), fin["rate_hz"], "gx", KEY.message, {},
                             "octave", None)  # analyze's function on the samples kept, nothing else
    assert math.isfinite(e["terms"][0]["N"])
