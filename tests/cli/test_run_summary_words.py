"""Words of the run summary that a user compares with other commands' output."""

from __future__ import annotations

import numpy as np

from companion.cli.main import main


def test_run_summary_says_which_gaps_it_counts(tmp_path, capsys):
    # 100 Hz with one lost sample every 10: inspect counts 0.02-s intervals as gaps (> 1.5 periods), the run's
    # block cutter only intervals over its gap_s; the summary must say which, or "0 gaps" contradicts inspect
    rng = np.random.default_rng(0)
    t = np.arange(6000) * 0.01
    t = t[np.arange(6000) % 10 != 9]
    g = rng.normal(0, 1e-2, (t.size, 3))
    rows = "\n".join(f"{ti:.3f},{a:.6f},{b:.6f},{c:.6f},0,0,-9.80665" for ti, (a, b, c) in zip(t, g))
    csv = tmp_path / "lossy.csv"
    csv.write_text("time_s,gx,gy,gz,ax,ay,az\n" + rows + "\n")
    assert main(["inspect", str(csv)]) == 0
    listing = capsys.readouterr().out
    assert " 599 " in listing, listing  # inspect's gaps column: every lost sample
    main(["run", "--source", str(csv), "--quiet", "--no-state"])
    head = capsys.readouterr().out.splitlines()[0]
    assert "0 gaps > 0.5 s" in head, head
