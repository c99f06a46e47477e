"""The stream header of analyze's table."""

from __future__ import annotations

from companion.analysis.report_table import format_table


def _stream(samples, secs):
    return {"message": "vehicle_imu", "instance": 0, "sysid": 0, "compid": 0, "samples": samples,
            "rate_hz": 2.0, "duration_s": secs, "axes": {}, "timing": {"gaps": 1}}


def test_a_stream_with_flight_figures_only_is_not_called_empty():
    head = format_table({"streams": [_stream(0, 0.0)]}).splitlines()[0]
    assert head.startswith("vehicle_imu[0] sys0/comp0: 2 Hz, no still samples"), head
    assert "0 samples" not in head and "(1 gaps in the stream)" in head


def test_a_stream_with_still_samples_keeps_its_counts():
    head = format_table({"streams": [_stream(120, 60.0)]}).splitlines()[0]
    assert "120 samples at 2 Hz, 60.0 s" in head, head
