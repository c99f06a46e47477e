"""Headless Chromium for the page tests: one profile per call (xdist-safe), no network services, a skip mark
where chromium is not installed (.ci/run installs Debian's chromium)."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (.ci/run installs Debian's "
                                    "chromium; locally: apt-get install chromium)")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--hide-scrollbars", "--force-device-scale-factor=1")


def chromium(profile, *args, timeout: float = 180) -> subprocess.CompletedProcess:
    """Chromium on a page with a fresh profile under ``profile`` (a directory path)."""
    return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args],
                          capture_output=True, text=True, timeout=timeout)


def dom(profile, url: str, *extra) -> str:
    """The page's DOM after its scripts ran."""
    r = chromium(profile, "--dump-dom", *extra, url)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def screenshot(profile, url: str, path, width: int = 1000, height: int = 1300):
    """The page as a PNG (RGB array), ``path`` kept for a look."""
    Image = pytest.importorskip("PIL.Image")
    import numpy as np

    r = chromium(profile, f"--screenshot={path}", f"--window-size={width},{height}", url)
    assert r.returncode == 0 and path.is_file(), r.stderr[-2000:]
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def canvases(html: str) -> list[tuple[int, int]]:
    """(width, height) of every plot canvas in a dumped DOM."""
    return [(int(w), int(h)) for w, h in re.findall(r'<canvas class="cplot-canvas" width="(\d+)" height="(\d+)"', html)]


def no_network(html: str) -> bool:
    """No external asset: nothing loaded from http(s) (links in text are fine)."""
    return not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", html) and "@import" not in html
