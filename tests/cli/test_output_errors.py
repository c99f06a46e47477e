"""Bad output paths, plot formats, links and models: one clear line on stderr before any work (not a traceback after an hour of analysis).

The rule for every file the CLI writes: its directory must exist (nothing is created), it must not be a
directory and must be writable; plots need a format matplotlib writes. All checked before the work, so
these runs take well under a second even though the source is a 20-minute log.
"""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from companion.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = str(ROOT / "tlogs" / "sample.tlog")
MODEL = str(ROOT / "companion" / "examples" / "sample_model.yaml")


def one_line_error(capsys, argv, *needles):
    rc = main(argv)
    cap = capsys.readouterr()
    assert rc == 2, cap
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("companion: error: "), cap.err
    for n in needles:
        assert n in lines[0], lines[0]
    assert "Traceback" not in cap.err
    return cap


MISSING = "/nonexistent-dir-companion/sub"


@pytest.mark.parametrize("argv, option", [
    (["inspect", SAMPLE, "--json", f"{MISSING}/s.json"], "--json"),
    (["analyze", SAMPLE, "--json", f"{MISSING}/r.json"], "--json"),
    (["analyze", SAMPLE, "--kalibr", f"{MISSING}/imu.yaml"], "--kalibr"),
    (["analyze", SAMPLE, "--plot", f"{MISSING}/a.png"], "--plot"),
    (["simulate", MODEL, "--duration", "10", "--out", f"{MISSING}/x.csv"], "--out"),
    (["gap", SAMPLE, "--model", MODEL, "--axis", "gx", "--out-model", f"{MISSING}/m.yaml"], "--out-model"),
    (["gap", SAMPLE, "--model", MODEL, "--axis", "gx", "--json", f"{MISSING}/g.json"], "--json"),
    (["compensate", SAMPLE, "--axis", "gx", "--out", f"{MISSING}/c.csv"], "--out"),
    (["compensate", SAMPLE, "--axis", "gx", "--json", f"{MISSING}/c.json"], "--json"),
    (["run", "--source", SAMPLE, "--state", "/dev/null/sub/s.json"], "--state"),
    (["run", "--source", SAMPLE, "--out-tlog", f"{MISSING}/r.tlog"], "--out-tlog"),
])
def test_missing_output_directory_is_refused_before_the_work(argv, option, capsys):
    one_line_error(capsys, argv, option, "does not exist")
    assert not Path(MISSING).exists()  # the same rule everywhere: nothing is created


@pytest.mark.parametrize("cmd", [
    ["analyze", SAMPLE], ["gap", SAMPLE, "--model", MODEL, "--axis", "gx"], ["compensate", SAMPLE, "--axis", "gx"],
])
def test_plot_format_and_directory_checked_up_front(cmd, capsys, tmp_path):
    one_line_error(capsys, cmd + ["--plot", str(tmp_path / "adev.pgn")], "'.pgn' is not a plot format", ".png")
    one_line_error(capsys, cmd + ["--plot", str(tmp_path)], "is a directory")
    one_line_error(capsys, cmd + ["--plot", str(tmp_path / "adev")], "no extension")
    assert list(tmp_path.iterdir()) == []
    assert not Path(str(tmp_path) + ".png").exists()


def test_refused_tcp_link_is_one_clean_line(capsys):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cap = one_line_error(capsys, ["run", "--source", f"tcp:127.0.0.1:{port}", "--no-state"],
                         "cannot open link", "refused")
    assert cap.out == ""  # pymavlink's "[Errno 111] Connection refused sleeping" kept off stdout


@pytest.mark.parametrize("argv", [
    ["run", "--source", "udpout:nosuchhost.invalid:14550", "--no-state"],
    ["inspect", "tcp:nosuchhost.invalid:5760", "--duration", "1"],
])
def test_unresolvable_host_is_named(argv, capsys):
    cap = one_line_error(capsys, argv, "cannot resolve host 'nosuchhost.invalid'")
    assert cap.out == ""


def _model(tmp_path, term_yaml):
    p = tmp_path / "m.yaml"
    p.write_text(f"rate_hz: 100.0\naxes:\n  gx:\n    - {term_yaml}\n")
    return str(p)


def test_simulate_refuses_a_sinusoid_above_nyquist(tmp_path, capsys):
    m = _model(tmp_path, "{effect: sinusoid, amplitude: 1.0e-3, freq_hz: 70.0}")
    one_line_error(capsys, ["simulate", m, "--duration", "10", "--out", str(tmp_path / "x.csv")],
                   "Nyquist", "50", "30 Hz")
    assert not (tmp_path / "x.csv").exists()


def test_simulate_accepts_the_bias_instability_cut_off(tmp_path, capsys):
    m = _model(tmp_path, "{effect: bias_instability, B: 2.0e-5, f0: 5.0}")
    assert main(["simulate", m, "--duration", "10", "--out", str(tmp_path / "x.csv")]) == 0
    assert (tmp_path / "x.csv").read_text().count("\n") == 1001
    bad = _model(tmp_path, "{effect: bias_instability, B: 2.0e-5, f0: 80.0}")
    one_line_error(capsys, ["simulate", bad, "--duration", "10", "--out", str(tmp_path / "y.csv")], "f0")


def test_taus_beyond_the_record_are_reported_or_refused(tmp_path, capsys):
    m = _model(tmp_path, "{effect: white_noise, N: 1.0e-3}")
    csv = tmp_path / "w.csv"
    assert main(["simulate", m, "--duration", "100", "--out", str(csv)]) == 0
    capsys.readouterr()
    assert main(["analyze", str(csv), "--axes", "gx", "--taus", "0.1,1,5000", "--json", str(tmp_path / "r.json")]) == 0
    err = capsys.readouterr().err
    assert "--taus 5000 s beyond" in err and "reaches tau 50 s" in err
    one_line_error_lines = main(["analyze", str(csv), "--axes", "gx", "--taus", "5000"])
    cap = capsys.readouterr()
    assert one_line_error_lines == 2 and "every cluster time is beyond the record" in cap.err
