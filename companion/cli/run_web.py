"""``run --report HTML`` and ``run --web [HOST:]PORT``: the alarm report written at the end of a run, and the
live page served while it runs (companion.webview; docs/reports.md)."""

from __future__ import annotations

import sys
import time

#: printed on stderr (also with --quiet) once the page is served: supervisors and tests wait for it
WEB_READY = "companion run: web page at"


def add_arguments(p) -> None:
    p.add_argument("--report", metavar="HTML",
                   help="write the alarm report at the end: every alarm with its evidence (the gyro of the IMU and "
                        "of its twins a minute around it, the detector's statistic against its threshold, the "
                        "spectrum), one self-contained HTML file (docs/reports.md)")
    p.add_argument("--web", metavar="[HOST:]PORT",
                   help="serve a read-only live page (health, coefficients, Allan deviation, alarms with evidence) "
                        "on 127.0.0.1:PORT, or HOST:PORT (0.0.0.0: every interface); after a replay it stays up "
                        "until Ctrl-C")


class WebRun:
    """Checked and bound before any work (a bad path, address or a port in use: one error line, exit 2)."""

    def __init__(self, args):
        from companion.cli.output import check_output_path

        self.report = getattr(args, "report", None)
        if self.report:
            check_output_path(self.report, "--report")
        self.server = None
        if getattr(args, "web", None):
            from companion.webview.live_server import LiveServer, parse_address

            self.server = LiveServer(*parse_address(args.web))
            self.server.start()
            print(f"{WEB_READY} {self.server.url}", file=sys.stderr, flush=True)

    def started(self, pipeline) -> None:
        if self.server is not None:
            pipeline.evidence.publish = self.server.publish

    def finish(self, pipeline, source: str, stop, replay: bool) -> None:
        """The report written; the page's last snapshot; after a replay the page stays until ``stop()``."""
        from companion.service.live_snapshot import report_data, snapshot

        if self.report:
            from companion.cli.output import write_text
            from companion.webview.pages import alarm_report_html

            write_text(self.report, alarm_report_html(report_data(pipeline, source)), "HTML report")
            print(f"wrote {self.report}")
        if self.server is None:
            return
        self.server.publish(snapshot(pipeline), running=False)
        if replay:
            print(f"companion run: replay done; the page stays at {self.server.url} until Ctrl-C",
                  file=sys.stderr, flush=True)
            while not stop():
                time.sleep(0.2)

    def close(self) -> None:
        if self.server is not None:
            self.server.close()
