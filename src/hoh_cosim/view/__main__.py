"""`python -m hoh_cosim.view`: a kept recording in the browser, or its screenshot.

    python -m hoh_cosim.view screenshot REC.rrd --out shot.png [--wait S] [--chromium PATH]
    python -m hoh_cosim.view serve REC.rrd [--view-port PORT]

Exit 0 with the PNG's path (or, serving, at Ctrl-C); 2 the input is wrong; 1 it failed (no
screenshot, or one in which the arm does not show: kept beside as NAME.failed.png).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from hoh_cosim.errors import HohError, RunError

EXIT_FAILED, EXIT_BAD_INPUT = 1, 2  # as the command line's (hoh_cosim.commands)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m hoh_cosim.view",
        description="A kept Rerun recording of hoh-cosim in the browser, or its screenshot.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    shot = sub.add_parser(
        "screenshot",
        help="render a recording in headless Chromium and save a PNG in which the arm shows",
        description="Serve the recording in Rerun's web viewer on loopback, open it in headless "
        "Chromium (software WebGL) and save a screenshot once the view has settled and the arm "
        "shows.",
    )
    shot.add_argument("recording", metavar="REC.rrd", help="a recording (--record-view)")
    shot.add_argument("--out", required=True, metavar="FILE.png", help="where to save the PNG")
    shot.add_argument(
        "--wait", type=float, default=90.0, metavar="S", help="at most this long (default: 90)"
    )
    shot.add_argument(
        "--chromium", metavar="PATH", help="the browser (default: $CHROMIUM, else chromium)"
    )
    serve = sub.add_parser(
        "serve",
        help="serve a recording in the web viewer until Ctrl-C",
        description="Serve the recording in Rerun's web viewer with the view's layout; the "
        "address is printed.",
    )
    serve.add_argument("recording", metavar="REC.rrd", help="a recording (--record-view)")
    serve.add_argument(
        "--view-port",
        type=int,
        default=9090,
        metavar="PORT",
        help="the web viewer's port (default: 9090)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "screenshot":
            from hoh_cosim.view.screenshot import take_screenshot

            print(
                f"wrote {take_screenshot(args.recording, args.out, chromium=args.chromium, wait_s=args.wait)}"
            )
            return 0
        from hoh_cosim.view.screenshot import serve_recording

        stream, url = serve_recording(args.recording, args.view_port)
        print(f"view: {url} (Ctrl-C ends)", flush=True)
        try:
            while True:
                time.sleep(0.5)
        except KeyboardInterrupt:
            stream.disconnect()
        return 0
    except RunError as exc:
        print(f"hoh-cosim: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except HohError as exc:
        print(f"hoh-cosim: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
