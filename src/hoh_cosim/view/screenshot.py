"""A recording served in Rerun's web viewer on loopback and rendered by headless Chromium.

    python -m hoh_cosim.view screenshot REC.rrd --out shot.png [--wait S] [--chromium PATH]
    python -m hoh_cosim.view serve REC.rrd [--view-port PORT]

`serve_recording` sends a `.rrd`'s chunks to a gRPC server on a free loopback port and serves the
web viewer (with the view's own layout) pointed at it. `take_screenshot` opens that page in
headless Chromium (Debian's `chromium`, or `$CHROMIUM`) with WebGL in software (SwiftShader), and
takes screenshots through the DevTools protocol until two in a row agree and the arm shows: the
viewer is WebAssembly that compiles and streams for seconds after the page's load event, which is
all that `--screenshot` with a `--virtual-time-budget` waits for (it gives the viewer's "loading"
page). The DevTools client is tornado's websocket (tornado comes with Dask's distributed).

`check_screenshot`: the 3D view shows the arm when enough of its pixels have the links' steel blue
(`ARM_RGB`, shaded by the viewer's light), which nothing else in the view has.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hoh_cosim.errors import ConfigError, InputFileError, RunError

__all__ = [
    "ARM_RGB",
    "CHROMIUM_FLAGS",
    "HEADLESS_FLAGS",
    "check_screenshot",
    "serve_recording",
    "take_screenshot",
]

ARM_RGB = (120, 150, 190)
"""The UR5's links in the view (`stream._ARM`)."""
HEADLESS_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)
"""Chromium headless on a closed network, as every screenshot here takes it (the docs' too)."""
CHROMIUM_FLAGS = (
    *HEADLESS_FLAGS,
    # WebGL without a GPU: ANGLE on SwiftShader, Chromium's software renderer
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
)
_MIN_ARM_PIXELS = 2000


def _recording_layout(path: Path) -> tuple[str, bool]:
    """The recording's timeline and whether it is a replay's."""
    from rerun.chunk import RrdReader

    try:
        chunks = list(RrdReader(path).stream())
    except (OSError, ValueError, RuntimeError) as exc:
        raise InputFileError(path, "", f"not a Rerun recording: {exc}") from None
    timelines = {name for c in chunks for name in c.timeline_names}
    timeline = "session_time" if "session_time" in timelines else "sim_time"
    replay = any(c.entity_path == "/plots/command/replayed" and not c.is_static for c in chunks)
    return timeline, replay


def serve_recording(path: str | Path, web_port: int) -> tuple[Any, str]:
    """Serve the recording at `path` in the web viewer on `web_port`: (its stream, the viewer's
    address); served until the stream is disconnected or the process ends."""
    from urllib.parse import quote

    from hoh_cosim.view import require_rerun

    require_rerun("serve")
    import rerun as rr
    from rerun.chunk import RrdReader

    from hoh_cosim.view.stream import free_loopback_port, view_blueprint

    path = Path(path)
    if not path.is_file():
        raise InputFileError(path, "", "no such file")
    timeline, replay = _recording_layout(path)
    try:
        rr.serve_web_viewer(web_port=web_port, open_browser=False)
    except RuntimeError as exc:
        if "in use" in str(exc):
            raise ConfigError(
                f"--view-port {web_port}: the port is in use (another viewer or server listens "
                "there); choose another with --view-port"
            ) from None
        raise RunError(f"Rerun's web viewer did not start: {exc}") from None
    sink = rr.GrpcServerSink(bind_ip="127.0.0.1", port=free_loopback_port())
    stream = rr.RecordingStream("hoh-cosim", recording_id=path.stem)
    stream.set_sinks(sink, default_blueprint=view_blueprint(timeline, replay))
    stream.send_chunks(RrdReader(path).stream())
    stream.flush()
    return stream, f"http://127.0.0.1:{web_port}/?url={quote(sink.uri, safe='')}"


def check_screenshot(png: str | Path) -> str | None:
    """None if the screenshot shows the arm, else what is wrong."""
    import matplotlib.image

    pixels = (matplotlib.image.imread(str(png))[..., :3] * 255).round().astype(int)
    # the links' colour under the viewer's light: brighter or darker, the same hue
    ratio = np.array(ARM_RGB, dtype=float) / ARM_RGB[2]
    blue = pixels[..., 2].astype(float)
    expected = blue[..., None] * ratio
    arm = (np.all(np.abs(pixels - expected) <= 14, axis=-1)) & (blue >= 60)
    count = int(arm.sum())
    if count < _MIN_ARM_PIXELS:
        return (
            f"{png}: {count} pixels of the arm's colour (at least {_MIN_ARM_PIXELS} expected): "
            "the arm does not show"
        )
    return None


async def _devtools_screenshots(
    browser: str, url: str, size: tuple[int, int], wait_s: float, profile: str
) -> bytes:
    from tornado.httpclient import AsyncHTTPClient
    from tornado.websocket import websocket_connect

    process = subprocess.Popen(
        [
            browser,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            "--remote-debugging-address=127.0.0.1",
            "--remote-debugging-port=0",
            "about:blank",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stderr is not None
        endpoint = None
        deadline = time.monotonic() + 30.0
        while endpoint is None and time.monotonic() < deadline:
            line = await asyncio.to_thread(process.stderr.readline)
            if not line:
                break
            found = re.search(r"DevTools listening on ws://([^/\s]+)/", line)
            if found:
                endpoint = found.group(1)
        if endpoint is None:
            raise RunError(f"{browser} did not start its DevTools endpoint")
        listing = await AsyncHTTPClient().fetch(f"http://{endpoint}/json/list")
        page = next(t for t in json.loads(listing.body) if t["type"] == "page")
        socket = await websocket_connect(page["webSocketDebuggerUrl"], max_message_size=2**28)
        calls = 0

        async def call(method: str, **params: Any) -> dict[str, Any]:
            nonlocal calls
            calls += 1
            await socket.write_message(
                json.dumps({"id": calls, "method": method, "params": params})
            )
            while True:
                message = await socket.read_message()
                if message is None:
                    raise RunError(f"{browser} closed the DevTools connection")
                reply = json.loads(message)
                if reply.get("id") == calls:
                    if "error" in reply:
                        raise RunError(f"{browser}: {method}: {reply['error'].get('message')}")
                    return reply["result"]

        await call(
            "Emulation.setDeviceMetricsOverride",
            width=size[0],
            height=size[1],
            deviceScaleFactor=1,
            mobile=False,
        )
        await call("Page.navigate", url=url)
        previous, shot = b"", b""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            await asyncio.sleep(2.0)
            shot = base64.b64decode((await call("Page.captureScreenshot", format="png"))["data"])
            if shot == previous and _shows_arm(shot):
                break
            previous = shot
        socket.close()
        return shot
    finally:
        process.terminate()
        try:
            process.wait(10.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _shows_arm(png: bytes) -> bool:
    with tempfile.NamedTemporaryFile(suffix=".png") as f:
        f.write(png)
        f.flush()
        return check_screenshot(f.name) is None


def take_screenshot(
    recording: str | Path,
    out: str | Path,
    *,
    chromium: str | None = None,
    wait_s: float = 90.0,
    size: tuple[int, int] = (1600, 1000),
    web_port: int | None = None,
) -> Path:
    """Serve `recording`, render it in headless Chromium and save the PNG at `out` (written
    whole); raises RunError with the cause, also when the arm does not show."""
    from hoh_cosim.view.stream import free_loopback_port

    browser = chromium or os.environ.get("CHROMIUM") or shutil.which("chromium")
    if browser is None:
        raise ConfigError("no Chromium: install Debian's chromium package or set $CHROMIUM")
    out = Path(out)
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: the folder {out.parent} does not exist")
    stream, url = serve_recording(recording, web_port or free_loopback_port())
    try:
        with tempfile.TemporaryDirectory(prefix="hoh-chromium-") as profile:
            png = asyncio.run(_devtools_screenshots(browser, url, size, wait_s, profile))
    finally:
        with contextlib.suppress(Exception):
            stream.disconnect()
    part = out.with_name(f".{out.name}.part")
    part.write_bytes(png)
    problem = check_screenshot(part)
    if problem is not None:
        failed = out.with_name(f"{out.stem}.failed{out.suffix}")
        os.replace(part, failed)
        raise RunError(f"{problem.replace(str(part), str(failed))} (kept for a look)")
    os.replace(part, out)
    return out
