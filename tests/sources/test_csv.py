"""CSV ingestion: values, gzip, column order, and one clear error line for each bad input."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from companion.errors import CompanionError
from companion.sources import load
from companion.sources.connection import parse_connection


def _write(path, text, gz=False):
    if gz:
        with gzip.open(path, "wt") as fh:
            fh.write(text)
    else:
        path.write_text(text)
    return path


def test_csv_and_gz_read_exact(tmp_path):
    rng = np.random.default_rng(4)
    n = 500
    arr = np.column_stack([np.arange(n) / 100.0, rng.normal(size=(n, 6))])
    text = "time_s,gx,gy,gz,ax,ay,az\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in arr) + "\n"
    for gz in (False, True):
        p = _write(tmp_path / ("a.csv.gz" if gz else "a.csv"), text, gz)
        s = load(p).streams[0]
        assert s.key.message == "CSV" and s.samples == n
        np.testing.assert_array_equal(s.t, arr[:, 0])
        np.testing.assert_array_equal(s.gyro, arr[:, 1:4])
        np.testing.assert_array_equal(s.accel, arr[:, 4:7])
        assert s.timing.rate_hz == pytest.approx(100.0)
        assert s.gyro_lsb is None


def test_csv_columns_in_any_order_extra_ignored(tmp_path):
    p = _write(tmp_path / "b.csv", "az,ay,ax,gz,gy,gx,time_s,temp\n6,5,4,3,2,1,0,20\n6,5,4,3,2,1,0.5,20\n")
    s = load(p).streams[0]
    np.testing.assert_array_equal(s.gyro[0], [1, 2, 3])
    np.testing.assert_array_equal(s.accel[0], [4, 5, 6])


@pytest.mark.parametrize("text,expect", [
    ("a,b,c\n1,2,3\n", "missing column"),
    ("time_s,gx,gy,gz,ax,ay,az\n0,1,2,3,4,5,6\n0.1,1,x,3,4,5,6\n", "line 3"),
    ("time_s,gx,gy,gz,ax,ay,az\n0,1,2,3,4,5,6\n0.1,1,3,4,5,6\n", "fewer columns"),
    ("time_s,gx,gy,gz,ax,ay,az\n", "no data rows"),
    ("time_s,gx,gy,gz,ax,ay,az\n0,1,2,3,4,5,nan\n", "non-finite"),
])
def test_csv_errors_one_line(tmp_path, text, expect):
    p = _write(tmp_path / "bad.csv", text)
    with pytest.raises(CompanionError) as ei:
        load(p)
    assert expect in str(ei.value) and "\n" not in str(ei.value)


def test_unreadable_inputs(tmp_path):
    (tmp_path / "x.csv.gz").write_bytes(b"\x00\x01 not gzip")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x81\n\x00")
    for p, expect in [(tmp_path / "x.csv.gz", "gzip"), (tmp_path / "missing.csv", "no such file"),
                      (tmp_path / "missing.tlog", "no such file"), (tmp_path / "bin.csv", "not a text CSV")]:
        with pytest.raises(CompanionError, match=expect):
            load(p)


@pytest.mark.parametrize("spec", ["foo:bar", "http://x", "udpin:nohost", "/usr/bin/python.elf", "tcp:1.2.3.4:99999",
                                  "flight.txt"])
def test_unknown_connection_strings_rejected(spec):
    with pytest.raises(CompanionError):
        parse_connection(spec)
    with pytest.raises(CompanionError):
        load(spec, duration=0.1)


def test_connection_strings_accepted():
    assert parse_connection("udpin:0.0.0.0:14550") == ("net", "udpin:0.0.0.0:14550")
    assert parse_connection("tcp:localhost:5760")[0] == "net"
    assert parse_connection("COM3", baud=57600) == ("serial", "COM3")
    with pytest.raises(CompanionError, match="no such serial device"):
        parse_connection("/dev/ttyDOESNOTEXIST0")
