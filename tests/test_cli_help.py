"""Every --help must print and exit 0 (a '%' in a help string once crashed the top-level help)."""

import pytest

from companion.cli.main import COMMANDS, main


def test_top_level_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name.replace("_", "-") in out


@pytest.mark.parametrize("name", [c.replace("_", "-") for c in COMMANDS])
def test_subcommand_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    assert "usage: companion " + name in capsys.readouterr().out


def test_no_command_prints_help(capsys):
    assert main([]) == 2
