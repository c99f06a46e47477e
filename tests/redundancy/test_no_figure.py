"""A condition axis with no figure says so: never a bare "bound" without a bound (analyze's table)."""

from __future__ import annotations

import numpy as np

from companion.analysis.condition_table import condition_lines
from companion.redundancy.fit_points import axis_entry
from companion.redundancy.redundant import _bounded

# Allan points of a 2-Hz pair difference of int16 gyros (ahmadkhanfar_test.tlog, gx): below the rounding's share
TAU = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
AVAR = np.array([-1.17e-07, -6.36e-08, -3.25e-08, -1.54e-08, -7.19e-09])
EDF = np.array([26.5, 22.0, 12.5, 5.7, 1.9])


def test_no_positive_point_is_no_figure_with_its_reason():
    e = axis_entry(TAU, AVAR, EDF, rate_hz=2.0, n=70, tau_min=4.0)
    assert e["status"] == "no_figure" and not e["bounds"] and not e["terms"], e
    assert any("positive Allan variance" in n for n in e["notes"]), e["notes"]
    each = _bounded(e)  # two IMUs: each at most the pair's figure, and here there is none
    assert each["status"] == "no_figure" and each["notes"] == e["notes"]
    line = condition_lines({"ground": {"seconds": 20.0, "method": "pair difference", "axes": {"gx": each}}})[-1]
    assert "positive Allan variance" in line and "bound;" not in line, line


def test_a_positive_pair_still_gives_its_bound():
    e = axis_entry(TAU, np.abs(AVAR), EDF, rate_hz=2.0, n=70, tau_min=0.5)
    assert e["status"] != "no_figure"
    assert _bounded(e)["bounds"] or e["terms"]
