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
