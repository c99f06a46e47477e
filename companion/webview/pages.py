"""Self-contained HTML pages: the page's data as JSON in the page, our plotting module (plot.js) and the
page code (page.js) inlined; no network, no third-party code. The alarm report of ``run --report``, the
analyze report of ``analyze --report``, the interactive part of the fleet report and the live page of
``run --web`` (docs/reports.md)."""

from __future__ import annotations

import html
import json
import math
from importlib import resources

STYLE = """body{font-family:sans-serif;margin:1.2em;max-width:1100px;color:#111}
table{border-collapse:collapse;margin:.6em 0}td,th{border:1px solid #ccc;padding:2px 7px;font-size:13px;text-align:left}
th{background:#eee}.flag{color:#b00;font-weight:bold}tr.flag td{background:#fde2e2}
section.evidence,section.imu{border-top:1px solid #ccc;margin-top:1em;padding-top:.3em}
.sentence{background:#f4f6fb;border-left:4px solid #1f77b4;padding:.4em .7em}.plotbox{margin:.4em 0}
.note{color:#444;font-size:13px}"""


def _asset(name: str) -> str:
    return resources.files("companion.webview").joinpath(name).read_text(encoding="utf-8")


def clean(obj):
    """JSON-ready copy: nan and inf as None (JSON.parse knows neither), numpy scalars as floats."""
    if isinstance(obj, dict):
        return {str(k): clean(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [clean(v) for v in obj]
    if isinstance(obj, bool) or obj is None or isinstance(obj, (str, int)):
        return obj
    try:
        v = float(obj)
    except (TypeError, ValueError):
        return str(obj)
    return v if math.isfinite(v) else None


def data_json(data) -> str:
    """The page's data as JSON safe inside a <script> element."""
    return json.dumps(clean(data), separators=(",", ":")).replace("</", "<\\/")


def scripts(data, root: str = "report") -> str:
    """The inlined plotting module and page code, the data, and the call that renders them into ``root``."""
    data = dict(data, root=root)
    return (f"<script>{_asset('plot.js')}</script>\n<script>{_asset('page.js')}</script>\n"
            f"<script type=\"application/json\" id=\"companion-data\">{data_json(data)}</script>\n"
            "<script>Companion.start();</script>\n")


def page(title: str, data: dict) -> str:
    """A whole page rendered from ``data`` (its ``kind``: alarms, analyze, live)."""
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{html.escape(title)}</title>"
            f"<style>{STYLE}</style></head>\n<body><div id=\"report\"></div><div id=\"evidence\"></div>\n"
            f"{scripts(data)}</body></html>\n")


def alarm_report_html(data: dict) -> str:
    """The alarm report of ``run --report`` (data: service.live_snapshot.report_data)."""
    return page(f"companion run: {data.get('source', '')}", dict(data, kind="alarms"))


def analyze_report_html(data: dict) -> str:
    """The analyze report (data: webview.analyze_view.analyze_view)."""
    return page(f"companion analyze: {data.get('source', '')}", dict(data, kind="analyze"))


def live_page_html(snapshot: dict) -> str:
    """The live page with the snapshot it starts from (then /data.json every second)."""
    return page("companion run: live", dict(snapshot, kind="live"))


def fleet_section(data: dict) -> str:
    """The interactive part of the fleet report, collapsed at first (the fixed plots above stay as they are)."""
    return ("<details id=\"interactive\"><summary>Interactive plots (zoom, pan, hover) and the evidence of the "
            "flagged IMUs</summary><div id=\"fleet-interactive\"></div></details>\n"
            + scripts(dict(data, kind="fleet"), root="fleet-interactive"))
