"""The shell commands of the README and the documentation pages, as a reader would copy them.

A fenced block with the language `sh` holds commands, one per line (a trailing backslash
continues one); `#` starts a comment. A block whose first line is `# not run: <reason>` is checked
for naming real commands and options only; every other block is run by
`tests/docs/test_tutorials.py`.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
NOT_RUN = re.compile(r"^# not run: (?P<reason>\S.*)$")
_FENCE = re.compile(r"^(?P<indent> *)```(?P<lang>[\w-]*)")


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # 1-based, the opening fence's
    text: str  # the block's lines, as written
    not_run: str | None  # the reason, for a block that is not run

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def sh_blocks(path: Path) -> list[Block]:
    """Every `sh` block of a Markdown file, in order."""
    blocks: list[Block] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        fence = _FENCE.match(lines[i])
        if fence is None:
            i += 1
            continue
        indent, start = len(fence["indent"]), i
        body: list[str] = []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith("```"):
            body.append(lines[i][indent:])
            i += 1
        i += 1
        if fence["lang"] == "sh":
            first = NOT_RUN.match(body[0]) if body else None
            blocks.append(
                Block(path, start + 1, "\n".join(body), first["reason"] if first else None)
            )
    return blocks


def commands(block: Block) -> list[list[str]]:
    """The block's simple commands as argv lists: continuations joined, comments dropped, `&&`,
    `;` and `|` chains split, a leading `.venv/bin/` dropped from the program's path."""
    out: list[list[str]] = []
    for line in block.text.replace("\\\n", " ").splitlines():
        lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|")
        lexer.whitespace_split = True
        lexer.commenters = "#"
        current: list[str] = []
        for token in lexer:
            if token in ("&&", ";", "|", "||", "&"):
                out.append(current)
                current = []
            else:
                current.append(token)
        out.append(current)
    return [[argv[0].removeprefix(".venv/bin/"), *argv[1:]] for argv in out if argv]


def markdown_pages() -> list[Path]:
    """The README and every page of the site."""
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
