"""What an FMU asks of its host (`hoh_cosim.fmi.host`), and the blocks without numba or pinocchio."""

from __future__ import annotations

import json
import pickle
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hoh_cosim.fmi.build import fmu_scripts_dir, host_requirements
from hoh_cosim.fmi.host import MissingRequirementError, module_name, require
from hoh_cosim.kinds import KINDS, input_starts
from hoh_cosim.presets import load_preset

ROOT = Path(__file__).resolve().parents[2]


def _check(tmp_path: Path, text: str) -> str | None:
    (tmp_path / "entry.py").write_text("")
    (tmp_path / "requirements.txt").write_text(text)
    try:
        require(str(tmp_path / "entry.py"), "HohThing")
    except MissingRequirementError as exc:
        return str(exc)
    return None


def test_a_host_that_has_everything_passes(tmp_path):
    assert _check(tmp_path, "# python >= 3.10\nnumpy>=1.24\nscipy\n") is None


def test_without_a_requirements_file_there_is_nothing_to_check(tmp_path):
    require(str(tmp_path / "entry.py"), "HohThing")  # the project's own fmus/: no file


def test_a_missing_package_is_one_line_with_the_pip_install(tmp_path, capfd):
    said = _check(tmp_path, "# python >= 3.10\nnumpy>=1.24\nno-such-package>=2.0\n")
    assert said == (
        f"HohThing: needs no-such-package, which the host's Python ({platform.python_version()}, "
        f"{sys.executable}) lacks: pip install 'no-such-package>=2.0'"
    )
    # pythonfmu's wrapper shows log messages only with debug logging: the line goes to stderr too
    assert capfd.readouterr().err == said + "\n"


def test_a_package_too_old_and_a_python_too_old_are_named(tmp_path):
    said = _check(tmp_path, "numpy>=999.0\n")
    assert said is not None
    assert said.startswith("HohThing: needs numpy 999.0 or newer, the host's Python (")
    assert said.endswith(f"has {np.__version__}: pip install 'numpy>=999.0'")
    said = _check(tmp_path, "# python >= 3.99\nnumpy\n")
    assert said is not None
    assert said.startswith("HohThing: needs Python 3.99 or newer; the host's Python (")


def test_an_unreadable_line_is_named(tmp_path):
    assert _check(tmp_path, "numpy @ https://x\n") == (
        "HohThing: resources/requirements.txt: cannot read the line 'numpy @ https://x'"
    )


def test_the_requirements_carry_the_projects_bounds():
    lines = host_requirements(("numpy", "scipy")).splitlines()
    assert lines[0] == "# python >= 3.10"
    assert lines[1].startswith("numpy>=")
    assert lines[2].startswith("scipy>=")


# --- every kind on exactly what it declares ------------------------------------------------------

_ONLY = r"""
import importlib.abc, importlib.util, json, pickle, sys
allowed = set(json.loads(sys.argv[1])) | set(sys.stdlib_module_names)
allowed |= {"hoh_cosim", "plant_models", "pythonfmu"}


class Only(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        top = name.split(".")[0]
        if top not in allowed and not top.startswith("_"):
            raise ModuleNotFoundError(f"No module named {name!r} (not declared)", name=name)


sys.meta_path.insert(0, Only())
script, params_file, starts = sys.argv[2], sys.argv[3], json.loads(sys.argv[4])
spec = importlib.util.spec_from_file_location("entry", script)
entry = importlib.util.module_from_spec(spec)
spec.loader.exec_module(entry)
import numpy as np
from hoh_cosim.control.block import make_block
from hoh_cosim.control.kernels import kernels_enabled

slave = next(v for k, v in vars(entry).items() if k.startswith("Hoh"))
with open(params_file, "rb") as f:
    params = pickle.load(f)
block = make_block(slave.block, params, 3)
inputs = {p.name: np.asarray(starts.get(p.name, np.zeros(p.size)), float) for p in block.inputs}
finite = True
for k in range(50):
    out = block.step(k * 1e-3, 1e-3, inputs)
    finite &= all(np.isfinite(np.asarray(v, float)).all() for v in out.values())
print(json.dumps({"finite": bool(finite), "compiled": kernels_enabled(),
                  "numba": "numba" in sys.modules, "pinocchio": "pinocchio" in sys.modules}))
"""


def _modules_of(distributions: tuple[str, ...]) -> list[str]:
    """The top-level modules of `distributions` and of everything they require, as installed."""
    import importlib.metadata as metadata
    import re

    wanted, todo = set(), [d.lower() for d in distributions]
    while todo:
        name = todo.pop()
        if name in wanted:
            continue
        try:
            required = metadata.requires(name) or []
        except metadata.PackageNotFoundError:  # a requirement for another Python (a marker)
            continue
        wanted.add(name)
        for line in required:
            if "extra ==" not in line:
                todo.append(re.match(r"[A-Za-z0-9_.-]+", line)[0].lower().replace("_", "-"))
    found = set()
    for name in wanted:  # a distribution's modules, where it put them (cmeel: under its prefix)
        for file in metadata.distribution(name).files or []:
            parts = file.parts
            if "site-packages" in parts:
                parts = parts[parts.index("site-packages") + 1 :]
            if parts and not parts[0].endswith((".dist-info", ".pth", ".data")):
                found.add(parts[0].removesuffix(".py").split(".")[0])
    return sorted(found | {module_name(d) for d in distributions})


CASES = [pytest.param(kind, None, id=kind) for kind in KINDS] + [
    # the clinical preset: the hold, glide, follow and recovery built too
    pytest.param(kind, "clinical", id=f"{kind}-clinical")
    for kind in ("estimator", "controller")
]


@pytest.mark.parametrize(("kind", "preset"), CASES)
def test_every_kind_runs_on_what_its_fmu_declares(tmp_path, kind, preset):
    spec = KINDS[kind]
    params = spec.params()
    if preset is not None:
        params = getattr(load_preset(preset), kind)
    params_file = tmp_path / "params.pickle"
    params_file.write_bytes(pickle.dumps(params))
    starts = {name: value.tolist() for name, value in input_starts(kind).items()}
    allowed = _modules_of(spec.requires)
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            _ONLY,
            json.dumps(allowed),
            str(fmu_scripts_dir() / f"{spec.fmu_script}.py"),
            str(params_file),
            json.dumps(starts),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.splitlines()[-1])
    assert result["finite"]
    # numba is never declared: without it the blocks take the pure path
    assert not result["numba"]
    assert not result["compiled"]
    assert result["pinocchio"] == (kind == "panda")
