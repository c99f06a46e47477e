"""The read-only web page of ``run --web [HOST:]PORT``: a small HTTP server in a thread of the run (Python's
http.server, no external assets). ``/`` is the page with the latest snapshot in it, ``/data.json`` the snapshot
without the evidence (the page polls it every second), ``/evidence.json`` the alarms' evidence (fetched when
an alarm is added or completed). The pipeline's thread hands snapshots over with :meth:`LiveServer.publish`;
the server only reads the bytes it was given. Bound to 127.0.0.1 unless a host is given."""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from companion.errors import CompanionError
from companion.webview.pages import clean, live_page_html

DEFAULT_HOST = "127.0.0.1"


def parse_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, port); CompanionError with the accepted form otherwise (port 0: any free)."""
    host, sep, port = str(text).rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]") or DEFAULT_HOST
    try:
        p = int(port)
    except ValueError:
        p = -1
    if not 0 <= p <= 65535:
        raise CompanionError(f"--web {text!r}: expected [HOST:]PORT with a port 0-65535, e.g. 8080 or 0.0.0.0:8080")
    return host, p


class _Handler(BaseHTTPRequestHandler):
    server_version = "companion"

    def do_GET(self):  # noqa: N802 (http.server's name)
        path = self.path.split("?", 1)[0]
        owner: LiveServer = self.server.owner
        body, kind = owner.content(path)
        if body is None:
            self.send_error(404, "not here: / , /data.json , /evidence.json")
            return
        self.send_response(200)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, fmt, *args):  # the run's console is for the run
        pass


class LiveServer:
    """Bound at construction (a port in use or a bad address is a CompanionError before any work);
    :meth:`start` serves in a daemon thread."""

    def __init__(self, host: str, port: int):
        try:
            self.httpd = ThreadingHTTPServer((host, port), _Handler)
        except OSError as exc:
            raise CompanionError(f"--web {host}:{port}: cannot serve there ({exc.strerror or exc})") from None
        except (OverflowError, ValueError) as exc:
            raise CompanionError(f"--web {host}:{port}: {exc}") from None
        self.httpd.daemon_threads = True
        self.httpd.owner = self
        self._lock = threading.Lock()
        self._snap: dict = {"imus": [], "alarms": [], "evidence": [], "transitions": [], "running": True}
        self._data = self._evidence = b""
        self.publish(self._snap)
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/"

    def publish(self, snap: dict, running: bool = True) -> None:
        """The latest snapshot (service.live_snapshot.snapshot), from the pipeline's thread."""
        snap = clean(dict(snap, running=running))
        t = [m.get("t_s") for m in snap.get("imus", []) if m.get("t_s") is not None]
        snap["t_s"] = max(t) if t else None
        light = {k: v for k, v in snap.items() if k != "evidence"}
        data = json.dumps(light, separators=(",", ":")).encode()
        evidence = json.dumps(snap.get("evidence", []), separators=(",", ":")).encode()
        with self._lock:
            self._snap, self._data, self._evidence = snap, data, evidence

    def content(self, path: str) -> tuple[bytes | None, str]:
        with self._lock:
            snap, data, evidence = self._snap, self._data, self._evidence
        if path in ("/", "/index.html"):
            return live_page_html(snap).encode(), "text/html; charset=utf-8"
        if path == "/data.json":
            return data, "application/json"
        if path == "/evidence.json":
            return evidence, "application/json"
        return None, ""

    def start(self) -> None:
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="companion-web", daemon=True)
        self._thread.start()

    def close(self) -> None:
        if self._thread is not None:
            self.httpd.shutdown()
        self.httpd.server_close()
