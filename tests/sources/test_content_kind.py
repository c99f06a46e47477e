"""A file's kind from its content, the name as a hint: a log renamed to another kind's suffix is read by what
it holds with one note naming both; a Git LFS pointer or an empty file is refused with what it is; a DataFlash
text log (Mission Planner .log) is read; a gzip file is opened through gzip whatever its name."""

from __future__ import annotations

import gzip
import shutil

import numpy as np
import pytest

from companion.cli.main import main
from companion.errors import CompanionError
from companion.sources import kind_of, load
from companion.sources.kind import content_kind, decide

N = 3000


def _data():
    rng = np.random.default_rng(7)
    t = 1.0 + np.arange(N) / 100.0
    g = rng.normal(0.0, 0.004, (N, 3))
    a = np.array([0.0, 0.0, -9.80665]) + rng.normal(0.0, 0.02, (N, 3))
    return t, g, a


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """One small log of each kind, named by its kind."""
    from companion.mavlink.tlog_writer import write_imu_tlog
    from companion.sim.dataflash_writer import write_imu_log
    from companion.sim.ulog_writer import write_ulog
    from companion.sources.csvfile import write_csv

    d = tmp_path_factory.mktemp("logs")
    t, g, a = _data()
    write_imu_tlog(d / "f.tlog", t, g, a)
    write_imu_log(d / "f.bin", t, g, a)
    write_ulog(d / "f.ulg", t, g, a)
    write_csv(str(d / "f.csv"), t, g, a)
    return d


@pytest.mark.parametrize("name, kind", [("f.tlog", "tlog"), ("f.bin", "dataflash"), ("f.ulg", "ulog"),
                                        ("f.csv", "csv")])
def test_content_names_every_kind_and_agrees_with_the_name(logs, name, kind):
    assert content_kind(logs / name).kind == kind
    assert decide(logs / name).note is None


@pytest.mark.parametrize("src, renamed, word", [
    ("f.bin", "flight.tlog", "a DataFlash log; read as DataFlash"),
    ("f.ulg", "flight.bin", "a PX4 ULog; read as ULog"),
    ("f.tlog", "flight.bin", "a MAVLink telemetry log (tlog); read as tlog"),
    ("f.csv", "flight.ulg", "a CSV file; read as CSV"),
])
def test_a_renamed_log_is_read_by_its_content_with_one_note(logs, tmp_path, capsys, src, renamed, word):
    """A .bin renamed .tlog gave "no IMU data", a .ulg renamed .bin "not a DataFlash log"."""
    p = tmp_path / renamed
    shutil.copy(logs / src, p)
    ref = load(logs / src)
    res = load(p)
    assert [(s.key, s.samples) for s in res.imu_streams()] == [(s.key, s.samples) for s in ref.imu_streams()]
    note = f"{renamed}: the content is {word}"
    assert res.meta["notes"].count(note) == 1
    assert main(["inspect", str(p)]) == 0
    out = capsys.readouterr().out
    assert out.count(note) == 1


def test_a_gzip_log_without_gz_in_its_name_is_read_through_gzip(logs, tmp_path):
    for src, name in (("f.bin", "g.bin"), ("f.tlog", "g.tlog"), ("f.ulg", "g.ulg"), ("f.csv", "g.csv")):
        with gzip.open(tmp_path / name, "wb") as fh:
            fh.write((logs / src).read_bytes())
        c = content_kind(tmp_path / name)
        assert c.gzip and c.kind == kind_of(logs / src)
        assert load(tmp_path / name).imu_streams()[0].samples == N


def test_a_gzip_log_is_sniffed_in_its_decompressed_start(logs, tmp_path):
    p = tmp_path / "flight.tlog.gz"
    with gzip.open(p, "wb") as fh:
        fh.write((logs / "f.bin").read_bytes())
    assert decide(p).kind == "dataflash"
    assert decide(p).note == "flight.tlog.gz: the content is a DataFlash log; read as DataFlash"


LFS = ("version https://git-lfs.github.com/spec/v1\n"
       "oid sha256:4d7a214614ab2935c943f9e0ff69d22eadbb8f32b1258daaa5e2ca24d17e2393\nsize 2934016\n")


@pytest.mark.parametrize("name", ["flight.tlog", "00000042.BIN", "log.ulg", "imu.csv"])
def test_a_git_lfs_pointer_is_named_not_read(tmp_path, capsys, name):
    """It gave "no IMU data" (as a tlog of 0 frames)."""
    p = tmp_path / name
    p.write_text(LFS)
    with pytest.raises(CompanionError, match="git lfs pull"):
        load(p)
    assert main(["inspect", str(p)]) == 2
    err = capsys.readouterr().err
    assert err == (f"companion: error: {p}: a Git LFS pointer of a 2,934,016 byte file, not the log itself: fetch "
                   "the log with `git lfs pull` (in the repository that holds it) and read it again\n")


def test_unrecognised_content_keeps_the_name_and_its_readers_error(tmp_path, capsys):
    p = tmp_path / "junk.bin"
    p.write_bytes(bytes(range(256)) * 4)
    assert decide(p).kind == "dataflash" and decide(p).note is None
    q = tmp_path / "notes.txt"
    q.write_text("hello\n")
    assert kind_of(q) == "unknown"
    assert main(["inspect", str(q)]) == 2
    assert "unknown file type" in capsys.readouterr().err


def test_a_spec_that_is_no_file_is_classified_by_name(tmp_path):
    assert kind_of(tmp_path / "missing.tlog") == "tlog"
    assert kind_of("udpin:0.0.0.0:14550") == "connection"


def _as_text_log(binary, text):
    """The Mission Planner text form of a binary log: one ``NAME, value, ...`` line per message (DFReader's
    values: scaled formats divided, strings decoded), FMT lines included."""
    from pymavlink import DFReader

    r = DFReader.DFReader_binary(str(binary), zero_time_base=False)
    lines = []
    while True:
        m = r.recv_msg()
        if m is None:
            break
        lines.append(", ".join([m.get_type()] + [str(getattr(m, c)) for c in m.get_fieldnames()]))
    text.write_text("\n".join(lines) + "\n")


def test_a_mission_planner_text_log_is_read_as_its_binary_log(tmp_path, capsys):
    """It gave "unknown file type"; read now with the DataFlash reader's numbers and one note."""
    from companion.sim.dataflash_writer import write_imu_log

    t, g, a = _data()
    write_imu_log(tmp_path / "f.bin", t, np.stack([g, -g]), np.stack([a, a]), params={"INS_GYRO_FILTER": 20},
                  armed=[(5.0, True), (20.0, False)], modes=[(4.0, 5)], messages=["ArduCopter V4.5.0 (abc, def)"])
    p = tmp_path / "2024-05-01 10-00-00.log"
    _as_text_log(tmp_path / "f.bin", p)
    assert p.read_text().startswith("FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns\n")
    ref, res = load(tmp_path / "f.bin"), load(p)
    assert len(res.streams) == 2
    for s, r in zip(res.streams, ref.streams):
        assert s.key == r.key
        np.testing.assert_array_equal(s.t, r.t)
        np.testing.assert_array_equal(s.gyro, r.gyro)
        np.testing.assert_array_equal(s.accel, r.accel)
    assert res.meta["params"] == ref.meta["params"] and res.meta["armed"] == ref.meta["armed"]
    note = "2024-05-01 10-00-00.log: the content is a DataFlash text log (Mission Planner .log); read as DataFlash"
    assert res.meta["notes"][0] == note
    assert main(["inspect", str(p)]) == 0
    assert capsys.readouterr().out.count(note) == 1


def test_an_empty_file_is_named(tmp_path, capsys):
    """It gave "no IMU data" (as a tlog of 0 frames)."""
    p = tmp_path / "flight.tlog"
    p.write_bytes(b"")
    assert main(["inspect", str(p)]) == 2
    assert capsys.readouterr().err == f"companion: error: {p}: empty file (0 bytes): no log to read\n"
