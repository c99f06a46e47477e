"""``analyze --report HTML``: the analysis as one self-contained interactive page, with the fault detectors of
``run`` replayed over each log and the evidence of every alarm (the flagged IMUs; also the JSON's
``evidence`` list when --json is given). docs/reports.md."""

from __future__ import annotations

from pathlib import Path

from companion.errors import CompanionError


def add_argument(p) -> None:
    p.add_argument("--report", metavar="HTML",
                   help="write an interactive HTML report (Allan deviation with zoom/pan/hover, the terms table) and "
                        "replay each log through run's fault detectors: every alarm with its evidence (also in --json "
                        "as 'evidence')")


def evidence(sources, args) -> tuple[list[dict], str]:
    """The alarms' evidence over every log file of ``sources``, and a note on what was not replayed."""
    from companion.service.evidence_replay import alarm_evidence

    items, skipped = [], []
    for spec in sources:
        if not Path(str(spec)).is_file():
            skipped.append(f"{spec}: not a log file (the detectors replay log files only)")
            continue
        try:
            items += alarm_evidence(spec, getattr(args, "time_unit", None))
        except CompanionError as exc:
            skipped.append(str(exc))
    note = "No alarm: the fault detectors of run found nothing over the log(s)." if not items else ""
    return items, "; ".join([note] + skipped if note else skipped)


def write(path: str, report: dict) -> None:
    from companion.cli.output import write_text
    from companion.webview.analyze_view import analyze_view
    from companion.webview.pages import analyze_report_html

    data = analyze_view(report, report.get("evidence"), report.get("evidence_note", ""))
    write_text(path, analyze_report_html(data), "HTML report")
    print(f"wrote {path}")
