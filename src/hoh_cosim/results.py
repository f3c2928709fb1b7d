"""Results directories: refused before any work when they cannot be written or are not ours, and
filled beside their destination, then moved into place in one rename, so that a failure or Ctrl-C
leaves nothing half-written that looks like a result."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from hoh_cosim.errors import ConfigError

__all__ = ["FORMATS", "KIND_FILE", "check_out_dir", "check_writable", "replace_dir"]

FORMATS = ("parquet", "csv")  # of a run's signals.*: compact and typed, or text for anything

KIND_FILE = ".hoh-cosim-result"
"""The file in every results directory that names what wrote it ("run", "clinical study", ...):
the kinds share file names (summary.json, report.md, runs.csv), so a file alone cannot tell one
kind's directory from another's, and a result must never replace another kind's."""


def check_writable(directory: Path, option: str) -> None:
    """Refuse, before any work, a directory where nothing can be written: make it (and its
    parents) if need be, then create and remove a file in it. A refusal names the real cause (a
    file where a folder must be, a read-only file system, ...) and leaves no folder made."""
    chain = [directory, *directory.parents]
    missing = chain[: chain.index(_deepest_existing(chain))]
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".hoh-cosim-write-check-", dir=directory)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        base = _deepest_existing(chain)  # where it stopped
        cause = _why_unwritable(base, exc, itself=base == directory)
        for made in missing:  # deepest first
            with contextlib.suppress(OSError):
                made.rmdir()
        raise ConfigError(f"{option}: cannot write in {directory}: {cause}") from None


def _deepest_existing(chain: list[Path]) -> Path:
    return next((p for p in chain if os.path.lexists(p)), chain[-1])


def _why_unwritable(base: Path, exc: OSError, itself: bool) -> str:
    """Why nothing could be made in `base`, the deepest part of the path that exists (`itself`:
    the directory asked for), in words that fit what is there: the operating system's reason alone
    can mislead (creating a folder in /proc says "No such file or directory")."""
    name = "it" if itself else str(base)
    if base.is_symlink() and not base.exists():
        return f"{name} is a link to {os.readlink(base)}, which does not exist"
    if not base.is_dir():
        return f"{name} is a file, not a folder" if base.is_file() else f"{name} is not a folder"
    try:
        read_only = bool(os.statvfs(base).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):  # AttributeError: no statvfs (Windows)
        read_only = False
    if read_only or exc.errno == errno.EROFS:
        return f"{name} is on a read-only file system"
    if exc.errno == errno.ENOENT:
        return f"{name} exists, but no file or folder can be created in it"
    if itself:
        return exc.strerror or str(exc)
    return f"no folder can be created in {name}: {exc.strerror or exc}"


def check_out_dir(out: Path, marker: str = "summary.json", what: str = "run") -> None:
    """Refuse, before anything runs, a destination that a result must not replace: one that is not
    a directory, a non-empty directory that another kind of result wrote (`KIND_FILE`), or, for
    one written before results named their kind, a non-empty directory without `marker`."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        kind = _kind_of(out)
        if kind is not None and kind != what:
            raise ConfigError(
                f"--out {out}: holds a hoh-cosim {kind}, not a {what}; choose another"
            )
        if kind is None and not (out / marker).is_file():
            raise ConfigError(
                f"--out {out}: exists, is not empty and holds no {marker}, so it is not a "
                f"hoh-cosim {what} directory; choose another"
            )
    check_writable(out.absolute().parent, f"--out {out}")


def _kind_of(out: Path) -> str | None:
    try:
        return (out / KIND_FILE).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return None


def replace_dir(out: Path, fill: Callable[[Path], None], what: str) -> None:
    """Call `fill(staging)` on an empty directory beside `out`, name the result's kind `what` in
    it (`KIND_FILE`), then move it into place in one rename: a failure leaves no half-written
    result, and an earlier one at `out` is replaced whole (or put back if the move fails)."""
    out = out.absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    old: Path | None = None
    try:
        fill(staging)
        (staging / KIND_FILE).write_text(what + "\n", encoding="utf-8")
        os.chmod(staging, 0o755)
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
            out.rename(old / out.name)
        staging.rename(out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        if old is not None and not out.exists():
            (old / out.name).rename(out)  # put the earlier result back
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
