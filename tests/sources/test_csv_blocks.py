"""A CSV is read block by block into its columns: the values of one whole read, and an error in a late block
named with the file's line number."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from companion.errors import CompanionError
from companion.sources import csvfile


def _text(n, seed=5):
    rng = np.random.default_rng(seed)
    arr = np.column_stack([np.arange(n) / 100.0, rng.normal(size=(n, 6))])
    rows = [",".join(repr(float(v)) for v in row) for row in arr]
    return arr, rows


@pytest.mark.parametrize("gz", [False, True])
def test_blocks_read_the_values_of_one_read(tmp_path, monkeypatch, gz):
    """Blocks of 1 kB (rows cut across blocks, a last row without a newline), columns in another order with an
    extra one, plain and gzip (whose size trailer gives the room): every value exact."""
    monkeypatch.setattr(csvfile, "BLOCK_BYTES", 1024)
    arr, _ = _text(700)
    header = "extra,az,ay,ax,gz,gy,gx,time_s"
    rows = [",".join(["1"] + [repr(float(v)) for v in row[::-1]]) for row in arr]
    text = header + "\n" + "\n".join(rows)
    p = tmp_path / ("b.csv.gz" if gz else "b.csv")
    if gz:
        with gzip.open(p, "wt") as fh:
            fh.write(text)
    else:
        p.write_text(text)
    raw = csvfile.read_csv(p)
    assert np.array_equal(raw.t, arr[:, 0])
    assert np.array_equal(raw.gyro, arr[:, 1:4]) and np.array_equal(raw.accel, arr[:, 4:7])


def test_columns_grow_past_a_short_size_hint(tmp_path, monkeypatch):
    """A size hint too small for the rows (a gzip trailer counts modulo 4 GiB): the columns grow."""
    monkeypatch.setattr(csvfile, "BLOCK_BYTES", 2048)
    monkeypatch.setattr(csvfile, "MIN_ROW_BYTES", 10_000)
    arr, rows = _text(300)
    p = tmp_path / "c.csv"
    p.write_text("time_s,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n")
    raw = csvfile.read_csv(p)
    assert np.array_equal(raw.t, arr[:, 0]) and np.array_equal(raw.accel, arr[:, 4:7])


def test_bad_value_in_a_late_block_names_the_file_line(tmp_path, monkeypatch):
    monkeypatch.setattr(csvfile, "BLOCK_BYTES", 1024)
    _, rows = _text(400)
    rows[350] = rows[350].replace(",", ",x", 1)
    p = tmp_path / "d.csv"
    p.write_text("time_s,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n")
    with pytest.raises(CompanionError, match="line 352"):
        csvfile.read_csv(p)


@pytest.mark.parametrize("isal", [True, False])
def test_gzip_through_isal_or_the_standard_library(tmp_path, monkeypatch, isal):
    """A gzip CSV reads to the same values through ISA-L and, where isal is absent, through the standard
    library; a gzip stream cut short is the one error line either way."""
    if isal:
        pytest.importorskip("isal")
    else:
        monkeypatch.setitem(__import__("sys").modules, "isal", None)  # import isal raises ImportError
    arr, rows = _text(500)
    p = tmp_path / "g.csv.gz"
    data = gzip.compress(("time_s,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n").encode())
    p.write_bytes(data)
    raw = csvfile.read_csv(p)
    assert np.array_equal(raw.t, arr[:, 0]) and np.array_equal(raw.gyro, arr[:, 1:4])
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(CompanionError, match="not a readable gzip file"):
        csvfile.read_csv(cut)
