"""Screenshots of the built site in headless Chromium, checked as a reader would look at them.

    mkdocs build --strict && python -m hoh_cosim.docsite screenshot [--site site] [--out DIR]

serves the built site on a free loopback port, has Chromium (Debian's `chromium`, or
`$CHROMIUM`) render the home page and the first tutorial to PNG, and checks each: the page's own
text was laid out (most of the picture is not blank) and the run's figure on it shows (enough
pixels of the plot's blue line, `PLOT_BLUE`). Exit 0 with the PNGs' paths, 1 with the cause.
"""

from __future__ import annotations

import contextlib
import functools
import http.server
import os
import shutil
import subprocess
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from hoh_cosim.view.screenshot import HEADLESS_FLAGS

__all__ = ["PAGES", "PLOT_BLUE", "check_screenshot", "take_screenshots"]

PAGES = {"home": "", "first-cosimulation": "tutorials/first-cosimulation/"}
"""Screenshot name -> the page's path in the site."""
PLOT_BLUE = (0x1F, 0x77, 0xB4)
"""The probe tip's line on the run's path plot (matplotlib's first colour)."""
_FLAGS = (*HEADLESS_FLAGS, "--window-size=1280,4000")


@contextlib.contextmanager
def _served(site: Path) -> Iterator[str]:
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


def check_screenshot(png: Path) -> str | None:
    """None if the screenshot shows a laid-out page with the run's figure, else what is wrong."""
    import matplotlib.image

    pixels = (matplotlib.image.imread(png)[..., :3] * 255).round().astype(int)
    blank = np.all(pixels >= 250, axis=-1).mean()
    if blank > 0.97:
        return f"{png}: {blank:.0%} of the picture is blank: the page did not render"
    blue = np.all(np.abs(pixels - np.array(PLOT_BLUE)) <= 12, axis=-1).sum()
    if blue < 500:
        return f"{png}: {blue} pixels of the plot's line (at least 500 expected): no figure shows"
    return None


def take_screenshots(site: Path, out: Path, chromium: str | None = None) -> list[Path]:
    """Render `PAGES` of the built `site` into `out`; raises RuntimeError with the cause."""
    browser = chromium or os.environ.get("CHROMIUM") or shutil.which("chromium")
    if browser is None:
        raise RuntimeError("no Chromium: install Debian's chromium package or set $CHROMIUM")
    if not (site / "index.html").is_file():
        raise RuntimeError(f"{site}: no index.html: build the site first (mkdocs build)")
    out.mkdir(parents=True, exist_ok=True)
    shots = []
    with _served(site) as url, tempfile.TemporaryDirectory() as profile:
        for name, path in PAGES.items():
            png = out / f"{name}.png"
            png.unlink(missing_ok=True)
            subprocess.run(
                [
                    browser,
                    *_FLAGS,
                    f"--user-data-dir={profile}",
                    f"--screenshot={png}",
                    "--virtual-time-budget=5000",
                    url + path,
                ],
                check=False,
                capture_output=True,
                timeout=120,
            )
            if not png.is_file():
                raise RuntimeError(f"Chromium wrote no screenshot of {url + path}")
            problem = check_screenshot(png)
            if problem:
                raise RuntimeError(problem)
            shots.append(png)
    return shots
