"""Inputs a new user meets: logs cut after a few messages, and what each command says about them."""

from __future__ import annotations

from companion.cli.main import main
from companion.errors import EXIT_NO_DATA

HEADER = "time_s,gx,gy,gz,ax,ay,az\n"


def test_analyze_of_a_one_sample_log_says_too_few_samples_not_taus(tmp_path, capsys):
    # one row: no stream has a sample rate; the default --taus is not the user's mistake
    csv = tmp_path / "one.csv"
    csv.write_text(HEADER + "0,0.001,0.002,0.003,0,0,-9.8\n")
    assert main(["analyze", str(csv), "--quiet"]) == EXIT_NO_DATA
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("companion: error: "), err
    assert "too few samples" in err[0] and "1 sample" in err[0] and "--taus" not in err[0], err[0]


def test_the_commands_example_config_names_take_config(capsys):
    # `example config` tells which commands read the file: each of them must have --config
    import re

    import pytest

    from companion.cli.example import DESCRIPTION
    from companion.examples import EXAMPLES

    said = re.search(r"--config FILE to\s+(.*?)\)", DESCRIPTION, re.S).group(1)
    said += ", " + re.search(r"\((.*): --config\)", EXAMPLES["config"][1]).group(1)
    names = {n.strip() for n in re.split(r",|\bor\b", said) if n.strip()}
    assert names >= {"run", "analyze"}, names
    for name in sorted(names):
        with pytest.raises(SystemExit):
            main(name.split() + ["--help"])
        assert "--config" in capsys.readouterr().out, name


def test_the_short_record_warning_shows_the_seconds_analysed(tmp_path, capsys):
    # 0.3 s at 2 kHz (a batch-sampler burst): "only 0 s analysed" beside a table of values misleads
    import json

    import numpy as np

    rng = np.random.default_rng(1)
    t = np.arange(600) / 2000.0
    g = rng.normal(0, 0.01, (t.size, 3))
    csv = tmp_path / "burst.csv"
    csv.write_text(HEADER + "\n".join(f"{ti:.6f},{a:.6f},{b:.6f},{c:.6f},0,0,-9.80665"
                                      for ti, (a, b, c) in zip(t, g)) + "\n")
    out = tmp_path / "r.json"
    assert main(["analyze", str(csv), "--all", "--axes", "gx", "--quiet", "--json", str(out)]) == 0
    warn = [w for w in json.loads(out.read_text())["streams"][0]["warnings"] if "analysed" in w]
    assert warn and warn[0].startswith("only 0.3 s analysed"), warn
    assert "whole record (--all), 0.3 s" in capsys.readouterr().out


def test_a_bad_log_taus_is_a_taus_error_in_the_help_s_words(tmp_path, capsys):
    import numpy as np

    g = np.random.default_rng(2).normal(0, 0.01, (3000, 3))
    csv = tmp_path / "w.csv"
    csv.write_text(HEADER + "\n".join(f"{i * 0.01:.2f},{a:.6f},{b:.6f},{c:.6f},0,0,-9.8"
                                      for i, (a, b, c) in enumerate(g)) + "\n")
    for bad in ("log:0", "log:x"):
        assert main(["analyze", str(csv), "--all", "--axes", "gx", "--quiet", "--taus", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"companion: error: bad --taus '{bad}'"), err
        assert "per decade" in err[0] and "K" not in err[0], err[0]


def test_start_after_end_is_refused_in_those_words(tmp_path, capsys):
    missing = str(tmp_path / "not_read.tlog")  # refused before the log is read
    for argv in (["analyze", missing, "--start", "100", "--end", "50"],
                 ["gap", missing, "--datasheet", "MPU-6000", "--start", "100", "--end", "50"],
                 ["analyze", missing, "--start", "nan"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("companion: error: --start"), err


def test_run_and_analyze_say_the_same_of_a_file_no_reader_takes(tmp_path, capsys):
    import os

    os.makedirs(tmp_path / "bin")
    for f in (tmp_path / "noise.dat", tmp_path / "bin" / "tool"):  # under a bin/: never executed, same words
        f.write_bytes(bytes(range(256)) * 20)
        said = []
        for argv in (["analyze", str(f)], ["run", "--source", str(f)], ["inspect", str(f)]):
            assert main(argv) == 2
            said.append(capsys.readouterr().err.strip())
        assert len(set(said)) == 1 and "unknown file type" in said[0], said


def test_json_dash_is_refused_where_it_is_not_standard_output(tmp_path, capsys, monkeypatch):
    # `gap --json -` prints the JSON; `analyze --json -` wrote a file named "-" silently
    monkeypatch.chdir(tmp_path)
    csv = tmp_path / "x.csv"
    csv.write_text(HEADER + "0,0.001,0,0,0,0,-9.8\n")
    for argv in (["analyze", str(csv), "--json", "-"], ["inspect", str(csv), "--json", "-"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--json -: standard output is not supported" in err[0], err
    assert not (tmp_path / "-").exists()


def test_an_empty_file_among_several_sources_is_one_failed_source(tmp_path, capsys):
    import json

    import numpy as np

    g = np.random.default_rng(3).normal(0, 0.01, (3000, 3))
    good = tmp_path / "good.csv"
    good.write_text(HEADER + "\n".join(f"{i * 0.01:.2f},{a:.6f},{b:.6f},{c:.6f},0,0,-9.8"
                                       for i, (a, b, c) in enumerate(g)) + "\n")
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    out = tmp_path / "r.json"
    # as a missing file among several: the others analysed, the empty one named, exit status 2
    assert main(["analyze", str(good), str(empty), "--all", "--axes", "gx", "--quiet", "--json", str(out)]) == 2
    rep = json.loads(out.read_text())
    assert len(rep["streams"]) == 1 and "empty file" in rep["failed_sources"][0]
    assert "1 of 2 sources not analysed" in capsys.readouterr().err
