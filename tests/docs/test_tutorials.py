"""Every command of every tutorial, run as a reader would run it, so that none goes stale.

Each tutorial's `sh` blocks run in order in one scratch folder of their own, in which the
repository's `scenarios/` and `studies/` are present, with the installed `hoh-cosim` and this
Python first on PATH; a block that fails (non-zero exit) fails the tutorial with its output. A block
whose first line is `# not run: <reason>` (the install, a real robot, the full study) is not run;
`test_docs.py` checks that its commands name real subcommands and options.

Minutes, not seconds: not part of the default run. `pytest -m tutorials tests/docs` runs them
(CI does, after the suite).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.docs.commands import DOCS, ROOT, sh_blocks

TUTORIALS = sorted((DOCS / "tutorials").glob("*.md"))
LINKED = ("scenarios", "studies")
"""The repository's folders a tutorial's commands name, present in its scratch folder."""
BLOCK_TIMEOUT_S = 600


@pytest.mark.tutorials
@pytest.mark.parametrize("page", TUTORIALS, ids=lambda p: p.stem)
def test_every_command_of_the_tutorial_runs(page: Path, tmp_path: Path):
    for name in LINKED:
        (tmp_path / name).symlink_to(ROOT / name)
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    ran = 0
    for block in sh_blocks(page):
        if block.not_run:
            continue
        start = time.monotonic()
        done = subprocess.run(
            ["bash", "-eo", "pipefail", "-c", block.text],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=BLOCK_TIMEOUT_S,
            check=False,
        )
        took = time.monotonic() - start
        assert done.returncode == 0, (
            f"{block.where}: exit {done.returncode} after {took:.0f} s\n"
            f"{block.text}\n--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}"
        )
        ran += 1
    assert ran > 0, f"{page.name}: no command is run"
