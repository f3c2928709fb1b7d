"""The README's promises: its commands are the CI's; the architecture page's example of the
controller core runs and prints what it says."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def _blocks(language: str, page: Path = README) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```$", page.read_text(), flags=re.S | re.M)


def test_readme_opens_with_exactly_two_commands():
    text = README.read_text()
    first = _blocks("sh")[0]
    assert text.index("```sh") < text.index("\n## ")  # before the tour
    lines = first.strip().splitlines()
    assert len(lines) == 2
    assert lines[0].endswith("hoh-cosim scenarios/circles.yaml")
    assert "pytest" in lines[1]


def test_the_controller_core_example_runs_and_prints_what_it_says(tmp_path):
    code = _blocks("python", ARCHITECTURE)[0]
    promised = re.search(r"It prints `(.*?)`", ARCHITECTURE.read_text()).group(1)
    script = tmp_path / "example.py"
    script.write_text(code)
    result = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == promised
