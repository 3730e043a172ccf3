"""Render the built documentation's main pages in headless Chromium to PNG files, to look
at them as a user would (navigation, search box, code blocks, figures, tables).

    mkdocs build -d site && python docs/screenshot.py site shots/

Needs Chromium (Debian: apt install chromium). The site is served on 127.0.0.1 (a free
port) for the time of the screenshots, as `mkdocs serve` would, so that its search runs;
the server stops with the last one.
"""

from __future__ import annotations

import functools
import http.server
import shutil
import subprocess
import sys
import threading
from pathlib import Path

PAGES = ("index.html", "getting-started/index.html", "tutorials/one-scenario/index.html",
         "results/reproduction/index.html", "reference/scenario/index.html",
         "reference/api/index.html")  # fmt: skip


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def shoot(site: Path, out: Path, pages=PAGES, timeout: float = 60.0) -> list[Path]:
    """Screenshots of `pages` of the built `site` into `out` (1280 x 1600 each)."""
    browser = chromium()
    if browser is None:
        raise SystemExit("no Chromium found (Debian: apt install chromium)")
    out.mkdir(parents=True, exist_ok=True)
    handler = functools.partial(_Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{server.server_address[1]}/"
    shots = []
    try:
        for page in pages:
            name = page.replace("/index.html", "").replace("/", "-").replace(".html", "")
            target = out / f"{name}.png"
            subprocess.run(
                [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                 "--window-size=1280,1600", "--virtual-time-budget=3000",
                 f"--screenshot={target}", base + page],
                check=True, capture_output=True, timeout=timeout,
            )  # fmt: skip
            shots.append(target)
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)
    return shots


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # no request log on the terminal
        pass


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit("usage: python docs/screenshot.py SITE_DIR OUT_DIR")
    for shot in shoot(Path(sys.argv[1]), Path(sys.argv[2])):
        print(shot)
