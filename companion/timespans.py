"""Sets of time intervals [(t0, t1)] (numpy-free): the union of overlapping ones and the difference of two sets,
as the still selection, the frozen spans and the in-flight conditions use them."""

from __future__ import annotations


def merge_intervals(intervals) -> list[tuple[float, float]]:
    """``intervals`` (any order, may overlap) as sorted, non-overlapping intervals."""
    out: list[list[float]] = []
    for a, b in sorted(intervals):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def minus(intervals, cut) -> list[tuple[float, float]]:
    """``intervals`` with the intervals ``cut`` taken out (both sorted, non-overlapping)."""
    out = []
    for a, b in intervals:
        for c, d in cut:
            if d <= a or c >= b:
                continue
            if c > a:
                out.append((a, c))
            a = max(a, d)
            if a >= b:
                break
        if a < b:
            out.append((a, b))
    return out
