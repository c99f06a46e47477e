"""`companion analyze --online`: online terms next to the offline fit, on the shipped sample log."""

from __future__ import annotations

import json

from companion.cli.main import main


def test_analyze_online_json_and_table(tmp_path, repo_root, capsys):
    out = tmp_path / "r.json"
    rc = main(["analyze", str(repo_root / "tlogs" / "sample.tlog"), "--online", "--axes", "gx,gz",
               "--json", str(out), "--quiet"])
    assert rc == 0
    table = capsys.readouterr().out
    assert "online" in table and "%" in table
    rep = json.loads(out.read_text())
    for axis in ("gx", "gz"):
        ax = rep["streams"][0]["axes"][axis]
        off = {t["effect"]: t for t in ax["terms"]}
        on = {t["effect"]: t for t in ax["online"]}
        assert set(on) <= set(off) | {"quantization", "ramp"}
        # same data, same fit procedure: N agrees to well under 1 % (the sample log is 20 min at 50 Hz)
        assert abs(on["white_noise"]["N"] - off["white_noise"]["N"]) < 0.01 * off["white_noise"]["N"]
        assert all(t["std"][k] >= 0 for t in ax["online"] for k in t["std"])
