"""Noise-model YAML: round trip, and one clear error naming the line/key for every kind of bad input."""

from pathlib import Path

import pytest

from companion.cli.main import main
from companion.errors import CompanionError
from companion.sim.model import NoiseModel, load_model, model_from_dict, save_model


def write(tmp_path, text):
    p = tmp_path / "m.yaml"
    p.write_text(text)
    return p


def test_round_trip(tmp_path):
    m = NoiseModel(100.0, {"gx": [{"effect": "white_noise", "N": 1e-3}, {"effect": "gauss_markov", "sigma": 1e-4, "tau_c": 20.0}],
                           "az": [{"effect": "random_walk", "K": 3e-6}]})
    save_model(m, tmp_path / "o.yaml", header="made by a test")
    back = load_model(tmp_path / "o.yaml")
    assert back == m
    assert (tmp_path / "o.yaml").read_text().startswith("# made by a test")


def test_pyyaml_string_numbers_accepted(tmp_path):
    m = load_model(write(tmp_path, "rate_hz: 50\naxes:\n  gz:\n    - {effect: white_noise, N: 1e-3}\n"))
    assert m.axes["gz"][0]["N"] == 1e-3 and m.rate_hz == 50.0


@pytest.mark.parametrize("text,needle", [
    ("rate_hz: 100\naxes:\n  gx:\n    - {effect: pink, N: 1.0}\n", "line 4: axes.gx[0]: unknown effect 'pink'"),
    ("rate_hz: 100\naxes:\n  gx:\n    - {effect: white_noise, N: 1.0}\n    - {effect: gauss_markov, sigma: 1.0}\n",
     "line 5: axes.gx[1]: effect 'gauss_markov' needs parameter 'tau_c'"),
    ("rate_hz: 100\naxes:\n  gq:\n    - {effect: white_noise, N: 1.0}\n", "axes.gq: unknown axis"),
    ("rate_hz: -1\naxes:\n  gx: []\n", "rate_hz: must be a positive number"),
    ("axes:\n  gx: []\n", "rate_hz: missing"),
    ("rate_hz: 100\naxes:\n  gx:\n    - {effect: white_noise, N: abc}\n", "parameter 'N' must be a finite number"),
    ("rate_hz: 100\naxes: [\n", "invalid YAML"),
    ("rate_hz: 100\nrate: 3\naxes:\n  gx: []\n", "rate: unknown key"),
])
def test_errors_name_line_and_key(tmp_path, text, needle):
    with pytest.raises(CompanionError, match=".*" + needle.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")):
        load_model(write(tmp_path, text))


def test_model_from_dict_rejects_non_mapping():
    with pytest.raises(CompanionError):
        model_from_dict([1, 2])


def test_simulate_cli_bad_model_exits_2(tmp_path, capsys):
    p = write(tmp_path, "rate_hz: 100\naxes:\n  gx:\n    - {effect: pink}\n")
    assert main(["simulate", str(p), "--duration", "1", "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown effect 'pink'" in err and "line 4" in err


def test_a_binary_file_given_as_model_config_or_baseline_is_one_error_line(tmp_path, capsys):
    """A log passed where a YAML file belongs (``simulate flight.tlog``) ended in a UnicodeDecodeError
    traceback; now one line naming the file, the byte that is not UTF-8, and what belongs there."""
    tlog = tmp_path / "flight.tlog"
    tlog.write_bytes(b"\x00\x05\x8f\x2a\xd7\xfe\x01" * 40)  # a tlog's 8-byte time and a MAVLink frame's bytes
    sample = str(Path(__file__).resolve().parents[2] / "tlogs" / "sample.tlog")
    calls = [
        (["simulate", str(tlog), "--duration", "1", "--out", str(tmp_path / "x.csv")], "a noise model is a YAML file"),
        (["gap", sample, "--model", str(tlog)], "a noise model is a YAML file"),
        (["analyze", sample, "--config", str(tlog)], "a configuration is a YAML file"),
        (["run", "--source", sample, "--no-state", "--baseline", str(tlog)], "a baseline is a JSON/YAML report"),
    ]
    for argv, what in calls:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1, (argv, err)
        assert "not a text file (byte 0x8f at offset 2 is not UTF-8)" in err and what in err, (argv, err)
