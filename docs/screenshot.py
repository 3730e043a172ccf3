"""Render the built documentation's main pages in headless Chromium to PNG files, to look
at them as a user would (navigation, search box, code blocks, figures, tables), and measure
in the same browser what a reader could miss (`hidden`).

    mkdocs build -d site && python docs/screenshot.py site shots/

Needs Chromium (Debian: apt install chromium). The site is served on 127.0.0.1 (a free
port) for the time of the screenshots, as `mkdocs serve` would, so that its search runs;
the server stops with the last one.
"""

from __future__ import annotations

import contextlib
import functools
import html
import http.server
import json
import re
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
    out.mkdir(parents=True, exist_ok=True)
    shots = []
    with served(site) as base:
        for page in pages:
            name = page.replace("/index.html", "").replace("/", "-").replace(".html", "")
            target = out / f"{name}.png"
            _browse(["--hide-scrollbars", "--window-size=1280,1600", "--virtual-time-budget=3000",
                     f"--screenshot={target}", base + page], timeout)  # fmt: skip
            shots.append(target)
    return shots


PROBE = """<!doctype html><html><body><pre id="result">not measured</pre>
<iframe id="page" src="/{page}" style="width: {width}px; height: 1600px"></iframe>
<script>
document.getElementById("page").onload = function () {{
  const d = this.contentDocument;
  const cut = [...d.querySelectorAll("pre > code")]
    .filter((c) => c.scrollWidth > c.clientWidth + 1)
    .map((c) => c.textContent.split("\\n")[0]);
  const broken = [...d.querySelectorAll("td:first-child code")]
    .filter((c) => c.getClientRects().length > 1)
    .map((c) => c.textContent);
  document.getElementById("result").textContent = JSON.stringify({{cut, broken}});
}};
</script></body></html>"""


def hidden(site: Path, page: str, width: int = 1280, timeout: float = 60.0) -> dict[str, list]:
    """What a reader of `page` at `width` pixels could miss, measured by the browser:
    ``cut``, the code blocks whose lines run past the block's edge (their first lines), and
    ``broken``, the names in the first column of tables split over two lines."""
    probe = site / "_probe.html"
    probe.write_text(PROBE.format(page=page, width=width))
    try:
        with served(site) as base:
            dom = _browse(["--dump-dom", f"--window-size={width + 40},1700",
                           "--virtual-time-budget=5000", base + probe.name], timeout)  # fmt: skip
    finally:
        probe.unlink()
    found = re.search(r'<pre id="result">(.*?)</pre>', dom, flags=re.S)
    return json.loads(html.unescape(found.group(1)))


@contextlib.contextmanager
def served(site: Path):
    """The built `site` on 127.0.0.1 (a free port) while the block runs, as `mkdocs serve`
    would, so that its search runs; yields the base address."""
    handler = functools.partial(_Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


def _browse(args: list[str], timeout: float) -> str:
    """Run headless Chromium with `args`; its standard output."""
    browser = chromium()
    if browser is None:
        raise SystemExit("no Chromium found (Debian: apt install chromium)")
    done = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", *args],
        check=True, capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip
    return done.stdout


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # no request log on the terminal
        pass


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit("usage: python docs/screenshot.py SITE_DIR OUT_DIR")
    for shot in shoot(Path(sys.argv[1]), Path(sys.argv[2])):
        print(shot)
