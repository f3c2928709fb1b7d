"""`python -m hoh_cosim.docsite results [...]`: re-measure the documentation's results pages."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hoh_cosim.docsite.results import measure
from hoh_cosim.docsite.screenshot import take_screenshots


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m hoh_cosim.docsite",
        description="Re-measure the documentation's results: the verification report and the "
        "clinical study, kept under docs/results/data/ for the site's results pages.",
    )
    sub = parser.add_subparsers(dest="what", required=True, metavar="results|screenshot")
    results = sub.add_parser("results", help="run the report and the clinical study")
    results.add_argument("--quick", action="store_true", help="the short versions (a first look)")
    results.add_argument(
        "--seeds", type=int, nargs="+", default=[13, 17], help="population seeds (default: 13 17)"
    )
    results.add_argument("--operators", type=int, default=20, help="operators (default: 20)")
    results.add_argument("--skip-report", action="store_true", help="keep the report as it is")
    results.add_argument("--skip-clinical", action="store_true", help="keep the study as it is")
    shots = sub.add_parser(
        "screenshot", help="the built site's home page and first tutorial in headless Chromium"
    )
    shots.add_argument("--site", type=Path, default=Path("site"), help="(default: site)")
    shots.add_argument(
        "--out", type=Path, default=Path("site-screenshots"), help="(default: site-screenshots)"
    )
    args = parser.parse_args(argv)
    if args.what == "screenshot":
        try:
            for png in take_screenshots(args.site, args.out):
                print(f"wrote {png}")
        except RuntimeError as exc:
            print(f"screenshot: {exc}", file=sys.stderr)
            return 1
        return 0
    measure(
        quick=args.quick,
        seeds=tuple(args.seeds),
        operators=args.operators,
        report=not args.skip_report,
        clinical=not args.skip_clinical,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
