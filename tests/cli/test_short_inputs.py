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
