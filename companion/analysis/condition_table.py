"""The ground and flight rows of ``analyze``'s table: per condition, its seconds and method, then N, B and K
per gyro axis in datasheet units (a bound as '< x'), as the still rows show them."""

from __future__ import annotations

from companion import units
from companion.units import fmt_interval
from companion.units import fmt_value as _fmt

_PARAM = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}


def _cells(r: dict, a: str) -> dict:
    cells = {}
    for t in r.get("terms", []):
        p = _PARAM.get(t["effect"])
        if p:
            lo, hi = t["ci95"][p]
            cells[p] = fmt_interval(units.to_datasheet(p, t[p], a), units.to_datasheet(p, lo, a),
                                    units.to_datasheet(p, hi, a))
    for t in r.get("bounds") or ():
        p = _PARAM.get(t["effect"])
        if p and p not in cells:
            cells[p] = f"< {_fmt(units.to_datasheet(p, t[p], a))}"
    return cells


def condition_lines(st: dict) -> list[str]:
    """The table lines of a stream entry's ``ground`` and ``flight`` (none when the entry has neither)."""
    lines = []
    for c in ("ground", "flight"):
        d = st.get(c)
        if not d or (not d.get("axes") and not d.get("intervals_s")):  # no such condition in the log
            continue
        lines.append(f"  {c}: {d.get('seconds', 0.0):.0f} s, {d.get('method', '')}")
        for n in d.get("notes", []):
            lines.append(f"    note: {n}")
        for a, r in d.get("axes", {}).items():
            cells = _cells(r, a)
            other = [n for n in r.get("notes", [])]
            if not cells and r.get("status") not in (None, "ok"):
                other.insert(0, str(r.get("status")))
            lines.append(f"  {a:<5} {cells.get('N', '-'):<28}{cells.get('B', '-'):<26}{cells.get('K', '-'):<26} "
                         + "; ".join(other))
    return lines
