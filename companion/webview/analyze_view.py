"""The data of the analyze report page from ``analyze``'s report (SI): per stream and axis the Allan deviation
with its 95 % band and the fitted model, the fitted terms and the upper bounds in datasheet units (the same
words as the console table), and the evidence of the fault detectors' alarms."""

from __future__ import annotations

import numpy as np

from companion import units
from companion.allan.terms import avar_model
from companion.analysis.report_table import format_term


def _bounds_text(r: dict, axis: str) -> str:
    out = []
    for t in r.get("bounds") or ():
        for p, v in t.items():
            if p in ("N", "B", "K", "Q", "R") and isinstance(v, (int, float)):
                out.append(f"{p} < {units.fmt_value(units.to_datasheet(p, v, axis))} {units.datasheet_unit(p, axis)}")
    return ", ".join(out)


def axis_view(r: dict, axis: str) -> dict | None:
    """One axis of a stream: the curve, the model over it, the words."""
    if r.get("status") != "ok" or not r.get("tau"):
        return None
    tau = np.asarray(r["tau"], dtype=float)
    model = np.sqrt(np.maximum(avar_model(r.get("terms") or [], tau), 0.0)) if r.get("terms") else None
    return {"adev": {"tau_s": r["tau"], "adev": r["adev"], "lo": r.get("adev_lo"), "hi": r.get("adev_hi"),
                     "model": None if model is None else model.tolist()},
            "terms_text": "; ".join(format_term(t, axis) for t in r.get("terms") or ()),
            "bounds_text": _bounds_text(r, axis)}


def analyze_view(report: dict, evidence: list[dict] | None = None, evidence_note: str = "") -> dict:
    """The page's data (webview.pages.analyze_report_html)."""
    streams = []
    for st in report["streams"]:
        axes = {}
        for ax, r in st["axes"].items():
            v = axis_view(r, ax)
            if v is not None:
                axes[ax] = v
        label = (f"{st.get('source', '')}: " if len(report.get("sources", [])) > 1 else "") + \
            f"{st['message']}[{st['instance']}] sys{st['sysid']}/comp{st['compid']}"
        desc = f"{st['samples']} samples at {st['rate_hz']:.4g} Hz, {st['duration_s']:.1f} s"
        streams.append({"label": label, "description": desc, "warnings": list(st.get("warnings") or []), "axes": axes})
    notes = [f"{s['source']}: {s['selection']['description']}" for s in report.get("sources", [])]
    notes += [n for s in report.get("sources", []) for n in s.get("notes", [])]
    return {"source": report["source"], "notes": notes, "streams": streams, "evidence": evidence or [],
            "evidence_note": evidence_note}
