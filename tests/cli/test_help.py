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


def _help(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        main(argv + ["--help"])
    assert exc.value.code == 0
    return " ".join(capsys.readouterr().out.split())  # argparse wraps lines: compare on single spaces


def test_help_names_every_log_format(capsys):
    top = _help([], capsys)
    assert ".bin" in top and ".ulg" in top  # the epilog and inspect's one-liner
    comp = _help(["compensate"], capsys)
    assert ".bin" in comp and ".ulg" in comp


@pytest.mark.parametrize("cmd", [["simulate"], ["sim-autopilot"]])
def test_preset_help_lists_every_shipped_preset(cmd, capsys):
    from companion.sim import PRESET_DIR

    text = _help(cmd, capsys)
    names = sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))
    assert "px4" in names
    assert ", ".join(names) + " or a preset YAML" in text


def test_fleet_simulate_options_have_help(capsys):
    text = _help(["fleet", "simulate"], capsys)
    for opt in ("OUT_DIR folder for the logs", "--vehicles V number of vehicles", "--flights F flights per vehicle",
                "--seed SEED random seed"):
        assert opt in text, opt


def test_directory_and_unknown_source_are_named(tmp_path, capsys):
    assert main(["analyze", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a directory" in err and "fleet analyze" in err
    assert main(["analyze", "nonsense"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown source" in err and ".bin" in err and ".ulg" in err


@pytest.mark.parametrize("argv, abbrev", [
    (["run", "--source", "tlogs/sample.tlog", "--report-p", "3"], "--report-p"),  # --report-period
    (["analyze", "tlogs/sample.tlog", "--qui"], "--qui"),  # --quiet
    (["fleet", "report", "--db", "x.sqlite", "--ht", "r.html"], "--ht"),  # --html
    (["simulate", "companion/examples/sample_model.yaml", "--duration", "10", "--out", "x.csv", "--se", "3"], "--se"),  # --seed
])
def test_an_abbreviated_option_is_refused_not_guessed(argv, abbrev, capsys):
    """Options by their full names only: a prefix is a usage error (exit 2), never read as the option it
    begins, so a script's meaning cannot change when a longer option is added."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert f"unrecognized arguments: {abbrev}" in capsys.readouterr().err
