"""Build the project's FMUs with pythonfmu, finish their model descriptions, cache them.

An FMU carries what it runs: pythonfmu's runtime (pythonfmu puts it there), the project's code
(`hoh_cosim` and `plant_models`, sources and package data, under `resources/`) and a
`resources/requirements.txt` naming what its host's Python must have installed (the kind's
`requires`, with the project's own version bounds); the model description's text says the same.
A host without hoh-cosim runs it; a host that lacks a requirement gets one line naming it
(`hoh_cosim.fmi.host`).

`ensure_fmus` returns an up-to-date FMU for each component kind, building only what is missing or
stale. An FMU is stale when its fingerprint changes: the hash of its entry script, every Python source
of `hoh_cosim` and `plant_models` as installed, and the versions of pythonfmu and Python. The cache
lives inside the project (`.fmu-cache/` beside `fmus/`) when we run from a checkout, otherwise in the
user's cache directory; `HOH_COSIM_FMU_CACHE` overrides both.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import platform
import shutil
import sys
import tempfile
import zipfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import hoh_cosim
import plant_models
from hoh_cosim.control.block import variable_step
from hoh_cosim.errors import ConfigError, HohError, RunError
from hoh_cosim.fmi.host import REQUIREMENTS, python_line
from hoh_cosim.fmi.model_description import finish_model_description
from hoh_cosim.fmi.slave import INPUT_STARTS, PARAMETERS, block_interface
from hoh_cosim.kinds import KINDS, input_starts
from hoh_cosim.params import leaves

__all__ = [
    "FMI_VERSIONS",
    "build_fmu",
    "default_cache_dir",
    "ensure_fmus",
    "fmu_name",
    "fmu_scripts_dir",
    "host_requirements",
    "project_root",
]


def _checkout_fmus() -> Path | None:
    """`fmus/` of the source checkout this package was imported from (editable installs)."""
    candidate = Path(hoh_cosim.__file__).resolve().parents[2] / "fmus"
    return candidate if (candidate / "hoh_estimator.py").is_file() else None


def fmu_scripts_dir() -> Path:
    """Where the FMU entry scripts are: the checkout's `fmus/`, else the copy in the package."""
    checkout = _checkout_fmus()
    if checkout is not None:
        return checkout
    packaged = Path(hoh_cosim.__file__).resolve().parent / "_fmus"
    if (packaged / "hoh_estimator.py").is_file():
        return packaged
    raise HohError("the FMU entry scripts are missing: neither fmus/ nor hoh_cosim/_fmus exists")


def project_root() -> Path | None:
    """The project checkout we run from, if any: the checkout of the package, else the current
    directory when it is one."""
    checkout = _checkout_fmus()
    if checkout is not None:
        return checkout.parent
    cwd = Path.cwd()
    if (cwd / "fmus" / "hoh_estimator.py").is_file() and (cwd / "pyproject.toml").is_file():
        return cwd
    return None


def default_cache_dir() -> Path:
    if os.environ.get("HOH_COSIM_FMU_CACHE"):
        return Path(os.environ["HOH_COSIM_FMU_CACHE"])
    root = project_root()
    if root is not None:
        return root / ".fmu-cache"
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return base / "hoh-cosim" / "fmus"


def fmu_name(kind: str) -> str:
    """The FMU's model identifier: the entry script's class name, e.g. HohEstimator."""
    special = {"ft150": "FT150", "fse103": "FSE103", "loadcell": "LoadCell"}
    return "Hoh" + special.get(kind, "".join(part.capitalize() for part in kind.split("_")))


def host_requirements(requires: Iterable[str]) -> str:
    """`resources/requirements.txt` for an FMU whose code needs the distributions `requires`:
    the oldest Python (the project's `Requires-Python`), then one line each with the project's own
    version bounds (`numpy>=1.24`)."""
    import importlib.metadata
    import re

    try:
        meta = importlib.metadata.metadata("hoh-cosim")
        declared = importlib.metadata.requires("hoh-cosim") or []
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - always installed
        meta, declared = None, []
    found = re.search(r"(\d+)\.(\d+)", (meta or {}).get("Requires-Python", "") or "")
    oldest = (int(found[1]), int(found[2])) if found else sys.version_info[:2]
    bounds = {}
    for line in declared:
        if ";" in line:  # an extra's
            continue
        name = re.match(r"[A-Za-z0-9_.-]+", line)
        if name:
            bounds[name[0].lower()] = line.replace(" ", "")
    lines = [python_line(oldest)] + [bounds.get(name.lower(), name) for name in requires]
    return "\n".join(lines) + "\n"


def _packed_code() -> list[tuple[str, Path]]:
    """(name under resources/, file) for the project's code an FMU carries: every file of the
    `hoh_cosim` and `plant_models` packages but compiled caches."""
    files = []
    for package in (hoh_cosim, plant_models):
        root = Path(package.__file__).resolve().parent
        for path in sorted(root.rglob("*")):
            relative = path.relative_to(root.parent)
            if path.is_file() and "__pycache__" not in relative.parts and path.suffix != ".pyc":
                files.append((relative.as_posix(), path))
    return files


def _fingerprint(entry: bytes, requirements: str = "", fmi: int = 2) -> str:
    if fmi == 3:
        import pythonfmu3 as builder
    else:
        import pythonfmu as builder  # type: ignore[no-redef]

    digest = hashlib.sha256()
    digest.update(entry)
    digest.update(requirements.encode())
    for name, path in _packed_code():
        digest.update(name.encode())
        digest.update(path.read_bytes())
    digest.update(
        f"{builder.__name__} {builder.__version__} python {platform.python_version()}".encode()
    )
    return digest.hexdigest()


def _build3(kind: str, out: Path, defaults: Any = None) -> None:
    """The kind's FMI 3.0 FMU (`hoh_cosim.fmi.build3`), carrying what its FMI 2.0 FMU carries."""
    from hoh_cosim.fmi.build3 import build_kind3, pythonfmu_package

    spec = KINDS[kind]
    requirements = host_requirements(spec.requires)
    resources: dict[str, str | bytes] = {REQUIREMENTS: requirements}
    resources.update((name, path.read_bytes()) for name, path in _packed_code())
    resources.update(pythonfmu_package())  # the adapter's interface imports it
    build_kind3(
        kind,
        out,
        defaults,
        description=spec.description + _needs(requirements),
        resources=resources,
    )


def _build(kind: str, script: Path, out: Path, defaults: Any = None) -> None:
    spec = KINDS[kind]
    build_fmu(
        script,
        out,
        spec.block,
        spec.params,
        spec.description,
        input_starts(kind),
        defaults,
        host_requirements(spec.requires),
    )


def build_fmu(
    script: Path,
    out: Path,
    block: type,
    params: type,
    description: str,
    starts: Mapping[str, Any] | None = None,
    defaults: Any = None,
    requirements: str | None = None,
) -> None:
    """Build the FMU of the entry script `script` (a `BlockSlave` subclass wrapping `block` with
    `params`, its inputs starting at `starts`, else 0, its parameters at `defaults`, else the
    block's defaults) with pythonfmu, finish its model description, and put it at `out`
    atomically, mode 0644. With `requirements` (`host_requirements`), the FMU carries the
    project's code and them: it runs in a host that never installed hoh-cosim."""
    from pythonfmu.builder import FmuBuilder

    kind = block.__name__
    with tempfile.TemporaryDirectory(prefix="hoh-fmu-") as tmp:
        log = io.StringIO()
        try:
            with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
                built = Path(FmuBuilder.build_FMU(script, dest=tmp))
        except Exception as exc:
            output = " ".join(log.getvalue().split())[-300:]
            raise RunError(
                f"building the {kind} FMU from {script} failed: {type(exc).__name__}: {exc}"
                + (f" (pythonfmu said: {output})" if output else "")
            ) from None
        specs = block_interface(block, params, starts, defaults)
        finished = Path(tmp) / "finished.fmu"
        with (
            zipfile.ZipFile(built) as src,
            zipfile.ZipFile(finished, "w", zipfile.ZIP_DEFLATED) as dst,
        ):
            for item in src.infolist():
                data = src.read(item)
                if item.filename == "modelDescription.xml":
                    data = finish_model_description(
                        data,
                        specs,
                        description + _needs(requirements),
                        variable_step=variable_step(block),
                        initial_from_parameters=hasattr(block, "initial_outputs"),
                    )
                # pythonfmu stores its entries uncompressed, some with mode 0600: deflate them,
                # readable by all
                item.compress_type = zipfile.ZIP_DEFLATED
                item.external_attr = (0o100644 if not item.is_dir() else 0o40755) << 16
                dst.writestr(item, data)
            starts = {
                str(vr): spec.start
                for vr, spec in enumerate(specs)
                if spec.causality == "input" and spec.start
            }
            resources = {INPUT_STARTS: starts}
            if defaults is not None:
                resources[PARAMETERS] = _parameters_json(params, defaults)
            texts = {name: json.dumps(content, indent=1) for name, content in resources.items()}
            if requirements is not None:
                texts[REQUIREMENTS] = requirements
                texts.update((name, path.read_bytes()) for name, path in _packed_code())
            for name, text in texts.items():
                entry = zipfile.ZipInfo(f"resources/{name}", (1980, 1, 1, 0, 0, 0))
                entry.compress_type, entry.external_attr = zipfile.ZIP_DEFLATED, 0o100644 << 16
                dst.writestr(entry, text)
        # a unique name beside the target, then one rename: a concurrent build or a reader never
        # sees half a file
        fd, part = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent)
        os.close(fd)
        try:
            shutil.copyfile(finished, part)
            os.chmod(part, 0o644)  # mkstemp's file is 0600: the FMU is for every tool and user
            os.replace(part, out)
        except BaseException:
            Path(part).unlink(missing_ok=True)
            raise


def _needs(requirements: str | None) -> str:
    """What the model description's text adds about the host: the requirements in one line."""
    if requirements is None:
        return ""
    lines = requirements.splitlines()
    python = lines[0].lstrip("# ").replace("python >= ", "Python ")
    return f". Host: {python} or newer with {', '.join(lines[1:])} (resources/{REQUIREMENTS})"


def _parameters_json(params_cls: type, defaults: Any) -> dict[str, Any]:
    """The leaves of `defaults` that differ from the class's defaults."""
    before = {leaf.name: leaf.value for leaf in leaves(params_cls())}
    return {leaf.name: leaf.value for leaf in leaves(defaults) if before[leaf.name] != leaf.value}


FMI_VERSIONS = (2, 3)
"""The FMI versions the FMUs are built for: 2.0 (pythonfmu) and 3.0 (pythonfmu3)."""


def ensure_fmus(
    kinds: Iterable[str],
    cache_dir: Path | None = None,
    force: bool = False,
    defaults: Mapping[str, Any] | None = None,
    fmi: int = 2,
) -> dict[str, Path]:
    """An up-to-date FMU for every kind, building the missing and the stale ones; `defaults`
    gives a kind's parameters other start values than its block's (a preset's): such an FMU is
    kept apart, under `defaults/<its values' hash>/`. `fmi` 3: FMI 3.0 FMUs, kept under `fmi3/`
    of the cache."""
    if fmi not in FMI_VERSIONS:
        raise ConfigError(f"--fmi: expected 2 or 3, got {fmi!r}")
    defaults = defaults or {}
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if fmi == 3:
        cache = cache / "fmi3"
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise HohError(f"{cache}: cannot create the FMU directory: {exc.strerror}") from None
    scripts = fmu_scripts_dir()
    paths: dict[str, Path] = {}
    for kind in kinds:
        script = scripts / f"{KINDS[kind].fmu_script}.py"
        if not script.is_file():
            raise HohError(f"{script}: missing: the entry script of the {kind} FMU")
        out = cache / f"{fmu_name(kind)}.fmu"
        entry = script.read_bytes()
        if fmi == 3:
            from hoh_cosim.fmi.build3 import entry_script3

            entry = entry_script3(fmu_name(kind), KINDS[kind].block, KINDS[kind].params).encode()
        fingerprint = _fingerprint(entry, host_requirements(KINDS[kind].requires), fmi)
        own = defaults.get(kind)
        values = None if own is None else _parameters_json(KINDS[kind].params, own)
        if values:  # other start values: an FMU of their own
            text = json.dumps(values, sort_keys=True)
            key = hashlib.sha256(text.encode()).hexdigest()[:16]
            out = cache / "defaults" / key / out.name
            out.parent.mkdir(parents=True, exist_ok=True)
            fingerprint = hashlib.sha256(f"{fingerprint} {text}".encode()).hexdigest()
        else:
            own = None
        stamp = out.with_suffix(".fmu.sha256")
        if force or not out.is_file() or not stamp.is_file() or stamp.read_text() != fingerprint:
            if fmi == 3:
                _build3(kind, out, own)
            else:
                _build(kind, script, out, own)
            stamp_part = stamp.with_name(f".{stamp.name}.{os.getpid()}")
            stamp_part.write_text(fingerprint)
            os.replace(stamp_part, stamp)
        paths[kind] = out
    return paths


def _main(argv: list[str]) -> None:  # pragma: no cover - used through the CLI
    ensure_fmus(KINDS, Path(argv[0]) if argv else None, force=True)


if __name__ == "__main__":
    _main(sys.argv[1:])
