"""`companion analyze --online` and `companion run` on the shipped sample log, against the truth of its
model file (companion/examples/sample_model.yaml): the reported values within their 95 % intervals as often as such
intervals hold the truth (the log is one realisation: a binomial count over its intervals, false failure
<= 1e-3 for calibrated intervals; coverage over many seeds is tests/estimators/test_online_report.py's), every
effect absent from the truth reported as a 95 % upper bound, and both commands print the same report."""

from __future__ import annotations

import json
import math
import re

from pathlib import Path

import pytest

from companion import units
from companion.cli.main import main
from companion.sim.model import load_model
from tests.support.stats import coverage_floor

ROOT = Path(__file__).resolve().parents[2]
LSB = 1e-3  # RAW_IMU gyro: int16 mrad/s; dithered rounding adds white noise N_q = LSB sqrt(tau0 / 12)


def truth(repo_root, axis):
    model = load_model(repo_root / "companion" / "examples" / "sample_model.yaml")
    terms = {t["effect"]: t for t in model.axes[axis]}
    n = math.hypot(terms["white_noise"]["N"], LSB * math.sqrt(1.0 / model.rate_hz / 12.0))
    return {"N": n, "B": terms.get("bias_instability", {}).get("B", 0.0),
            "K": terms.get("random_walk", {}).get("K", 0.0), "terms": terms}


@pytest.fixture(scope="module")
def online_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("online") / "r.json"
    rc = main(["analyze", str(ROOT / "tlogs" / "sample.tlog"), "--online", "--axes", "gx,gy,gz",
               "--json", str(out), "--quiet"])
    assert rc == 0
    return json.loads(out.read_text())


def test_analyze_online_within_truth(online_report, repo_root):
    held = []
    for axis in ("gx", "gy", "gz"):
        held += check_axis_against_truth(online_report, repo_root, axis)
    assert sum(held) >= coverage_floor(len(held)), held


def check_axis_against_truth(online_report, repo_root, axis):
    """The structural checks of one axis; returns whether each 95 % interval held the truth."""
    ax = online_report["streams"][0]["axes"][axis]
    tr = truth(repo_root, axis)
    on = {t["effect"]: t for t in ax["online"]}
    held = []
    for e, p in (("white_noise", "N"), ("bias_instability", "B"), ("random_walk", "K")):
        t = on[e]
        lo, hi = t["ci95"][p]
        held.append(lo <= tr[p] <= hi)
        assert t["bound"] is (lo == 0.0)
        if tr[p] == 0.0:
            assert t["bound"], (axis, p, t)  # nothing invented
        assert t["std"][p] >= 0
    # N is not inflated by the Gauss-Markov term of gy (was 4.6x the truth): the term is in the model
    assert abs(on["white_noise"]["N"] - tr["N"]) < 0.02 * tr["N"]
    if "gauss_markov" in tr["terms"]:
        gm, gt = on["gauss_markov"], tr["terms"]["gauss_markov"]
        held.append(gm["ci95"]["sigma"][0] <= gt["sigma"] <= gm["ci95"]["sigma"][1])
        held.append(gm["ci95"]["tau_c"][0] <= gt["tau_c"] <= gm["ci95"]["tau_c"][1])
    else:
        assert "gauss_markov" not in on
    # the offline fit's left-out effects are printed as bounds with the same rule: they contain the truth
    for t in ax["bounds"]:
        p = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}[t["effect"]]
        assert t["bound"] and tr[p] <= t[p]
    if tr["K"] == 0.0:
        assert any(t["effect"] == "random_walk" for t in ax["bounds"])
    return held


def test_run_prints_the_same_report_as_analyze_online(online_report, repo_root, capsys):
    capsys.readouterr()
    rc = main(["run", "--source", str(repo_root / "tlogs" / "sample.tlog"), "--baseline-s", "300", "--quiet",
               "--no-state"])
    assert rc == 0
    text = capsys.readouterr().out
    held = []
    for axis in ("gx", "gy", "gz"):
        line = next(s for s in text.splitlines() if s.strip().startswith(axis + " online:"))  # the online figures
        on = {t["effect"]: t for t in online_report["streams"][0]["axes"][axis]["online"]}
        tr = truth(repo_root, axis)
        for e, p in (("white_noise", "N"), ("bias_instability", "B"), ("random_walk", "K")):
            m = re.search(rf"\b{p} (< )?([0-9.e+-]+)( \+- ([0-9.e+-]+))?", line)
            assert m, (p, line)
            assert bool(m.group(1)) is on[e]["bound"], (axis, p, line, on[e])  # same terms resolved / bounded
            v = units.from_datasheet(p, float(m.group(2)), axis)
            if m.group(1):
                assert tr[p] <= v * 1.001
            else:
                s = units.from_datasheet(p, float(m.group(4)), axis)
                held.append(abs(v - tr[p]) <= 1.96 * s)  # within its 95 % interval of the truth
                # run forgets (600 s / 7200 s memories) and skips the settling time: within the uncertainty
                assert abs(v - on[e][p]) <= 2.5 * max(s, on[e]["std"][p]), (axis, p, line, on[e])
        assert ("gauss_markov" in line) is ("gauss_markov" in on)
    assert "degrading" not in text
    assert sum(held) >= coverage_floor(len(held)), held
