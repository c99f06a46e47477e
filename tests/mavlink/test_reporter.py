"""NAMED_VALUE_FLOAT names, units and cadence; STATUSTEXT; decoded back by pymavlink itself."""

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.mavlink.reporter import NAME_RE, Reporter, health_name, to_report_units, value_name


class ListSink:
    def __init__(self):
        self.nvf = []
        self.texts = []

    def send_named_value_float(self, time_boot_ms, name, value):
        self.nvf.append((time_boot_ms, name, value))

    def send_statustext(self, severity, text, time_boot_ms=None):
        self.texts.append((severity, text))


def test_names_fit_mavproxy_graph():
    for imu in range(10):
        for ax in ("gx", "gy", "gz", "ax", "ay", "az"):
            for p in ("N", "B", "K", "Q", "R"):
                assert NAME_RE.match(value_name(imu, ax, p))
        assert len(health_name(imu)) <= 10
    assert value_name(0, "gx", "N") == "IMU0GX_N"
    assert value_name(2, "az", "B") == "IMU2AZ_B"
    assert health_name(0) == "IMU0G_HLTH"
    with pytest.raises(ValueError):
        health_name(10)  # IMU10G_HLTH would be cut by pymavlink


def test_datasheet_units_against_reference_constants():
    # ../shared/REFERENCE.md: 1 deg/sqrt(h) = 2.909e-4 rad/s/sqrt(Hz); 1 deg/h = 4.848e-6 rad/s;
    # 1 deg/h^1.5 = 8.08e-8 rad/s^1.5
    assert to_report_units("N", "gx", 2.909e-4) == pytest.approx(1.0, rel=1e-3)
    assert to_report_units("B", "gy", 4.848e-6) == pytest.approx(1.0, rel=1e-3)
    assert to_report_units("K", "gz", 8.08e-8) == pytest.approx(1.0, rel=1e-3)


def test_cadence_spread_over_the_period_in_message_time():
    sink = ListSink()
    r = Reporter(sink, period_s=1.0)
    r.set_terms(0, "gx", {"N": 1e-3, "B": 1e-5, "K": 1e-6})
    r.set_health(0, 0)
    t = 100.0
    while t < 110.0:
        r.tick(t)
        t += 0.01
    names = [n for _, n, _ in sink.nvf]
    # 4 names, each once per second over 10 s (+-1 at the edges), never two in the same 10 ms tick
    for n in ("IMU0GX_N", "IMU0GX_B", "IMU0GX_K", "IMU0G_HLTH"):
        assert 9 <= names.count(n) <= 11
    stamps = [ms for ms, _, _ in sink.nvf]
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert min(gaps) >= 240 and max(gaps) <= 260  # 1 s / 4 names
    # a jump of message time (replay, reboot) sends at most one period's worth
    before = len(sink.nvf)
    r.tick(5000.0)
    assert len(sink.nvf) - before <= 4
    r.tick(3.0)  # time went back (reboot): no burst, no error
    assert len(sink.nvf) - before <= 5


def test_nan_values_are_not_sent_and_statustext_cut():
    sink = ListSink()
    r = Reporter(sink, 1.0)
    r.set_terms(0, "gx", {"N": math.nan})
    assert r.tick(1.0) == 0
    r.statustext("x" * 80)
    assert len(sink.texts[0][1]) == 50 and sink.texts[0][0] == 4


def test_pymavlink_decodes_what_we_send():
    """Through a real pymavlink encoder: the receiver sees the same name and value (float32)."""
    out = []

    class F:
        def write(self, buf):
            out.append(bytes(buf))

    mav = mavlink2.MAVLink(F(), srcSystem=1, srcComponent=191)

    class MavSink:
        def send_named_value_float(self, ms, name, value):
            mav.named_value_float_send(ms, name.encode(), value)

        def send_statustext(self, sev, text, time_boot_ms=None):
            mav.statustext_send(sev, text.encode())

    r = Reporter(MavSink(), 1.0)
    r.set_terms(0, "gx", {"N": 2.909e-3})
    r.tick(12.5)
    r.statustext("IMU0 gyro X degrading: N 2.1x baseline")
    rx = mavlink2.MAVLink(None)
    msgs = [rx.parse_char(b) for b in out]
    assert msgs[0].get_type() == "NAMED_VALUE_FLOAT"
    assert msgs[0].name == "IMU0GX_N" and msgs[0].value == pytest.approx(10.0, rel=1e-3)
    assert msgs[0].time_boot_ms == 12500
    assert msgs[1].get_type() == "STATUSTEXT" and msgs[1].severity == 4
    assert msgs[1].text == "IMU0 gyro X degrading: N 2.1x baseline"


def test_a_replay_stamps_a_statustext_with_the_time_of_what_it_reports():
    """A replay's sink took the time of its last NAMED_VALUE_FLOAT for a STATUSTEXT: the first alarms of a
    public PX4 log (before any value was sent) were written at t = 0 s into the replay's tlog and echoed so."""
    from companion.service.run_session import ReplaySink

    said = []
    sink = ReplaySink(echo=said.append)
    r = Reporter(sink, 1.0)
    r.statustext("IMU0 gyro Y spikes 0.11 %", 4, t_s=15.2)
    assert sink.t == 15.2 and said == ["STATUSTEXT sev=4 t=15s: IMU0 gyro Y spikes 0.11 %"]
