"""The autopilot's ERR events as ``run``, ``analyze`` and ``inspect`` print them."""

from __future__ import annotations

from types import SimpleNamespace

from companion.health.autopilot_view import AutopilotEvent, AutopilotView, event_lines, view_lines
from companion.sources.autopilot_health import check_report


def _view(events):
    return AutopilotView("dataflash", events=events, fields=["ERR"])


def test_a_repeated_err_is_printed_once_with_its_count():
    # a 2014 PXF rover log: 21 ERR MAIN records without a time of their own, all at one time
    ev = [AutopilotEvent(52.4, "MAIN", 1)] * 21 + [AutopilotEvent(60.0, "EKFCHECK", 0)]
    lines = check_report(_view(ev), {0: []}, [0])["lines"]
    errs = [x for x in lines if " ERR " in x]
    assert len(errs) == 2, lines
    assert errs[0].startswith("52.4 s ERR MAIN:") and errs[0].endswith("(21 times)"), errs[0]
    assert errs[1] == "60.0 s ERR EKFCHECK: resolved"
    assert [x for x in view_lines(_view(ev)) if " ERR " in x] == [f"autopilot: {x}" for x in errs]


def test_more_than_ten_different_errs_are_counted_not_dropped():
    ev = [AutopilotEvent(float(i), "EKFCHECK", i % 2) for i in range(25)]
    lines = event_lines(ev)
    assert len(lines) == 11 and lines[-1] == "15 more ERR events", lines


def test_run_names_a_gyro_that_read_zero_throughout_beside_the_autopilot():
    # the run ends 4 for it (service.outcome); the cross-check line must not say "nothing found"
    from companion.service.autopilot_watch import report

    rows = [{"imu": 0, "health": "learning", "faults": [], "all_zero": True},
            {"imu": 1, "health": "learning", "faults": [], "all_zero": False}]
    pipe = SimpleNamespace(summary=lambda: rows, autopilot_view=_view([AutopilotEvent(1.0, "MAIN", 1)]))
    lines = report(pipe)["lines"]
    assert "exactly 0" in lines[0] and "nothing found" not in lines[0], lines
    assert "nothing found" in lines[1], lines
