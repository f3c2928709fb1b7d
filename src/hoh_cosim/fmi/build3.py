"""Build FMI 3.0 co-simulation FMUs of the blocks with pythonfmu3, beside the FMI 2.0 ones.

The FMU of a block wraps it with `hoh_cosim.fmi.slave3.BlockSlave3`: the variables, values and
behaviour of the FMI 2 FMU (`hoh_cosim.fmi.build`), in FMI 3 terms. What this module adds to
pythonfmu3's build:
- the entry script, written here from the block's and the parameter class's names: FMI 3 scripts
  are generated, not kept in `fmus/`, and their module is `hoh3_<kind>` (`fmu3_module`), distinct
  from the FMI 2 script's `hoh_<kind>`, since every pythonfmu FMU in a process shares one
  interpreter and so one `sys.modules`;
- the model description completed as `hoh_cosim.fmi.model_description` completes the FMI 2 one, so
  that `fmpy validate` finds no problem: descriptions, units and UnitDefinitions (also for the
  independent variable `time`), Float64 start values to 17 digits, the build's start values
  (`starts`, `defaults`), ModelStructure (every output an Output with no dependencies and an
  InitialUnknown, depending on every parameter where the block has `initial_outputs`), the
  capability flags (canHandleVariableCommunicationStepSize as `variable_step(block)` says,
  canGetAndSetFMUState, canSerializeFMUState) and the DefaultExperiment;
- `resources/`: `INPUT_STARTS`, `PARAMETERS` where `defaults` are given, the folders of
  `project_files` (pythonfmu3 copies them) and the files of `resources` (name -> text or bytes).
  With project files the FMU also carries pythonfmu's Python package (as FMI 2 FMUs do), because
  the adapter's interface (`hoh_cosim.fmi.slave`) imports it;
- the FMU written atomically, mode 0644, its entries deflated.

`build_fmu3` builds from a block and its parameter class, `build_kind3` from a registered kind.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from hoh_cosim.control.block import variable_step
from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.fmi.model_description import DEFAULT_EXPERIMENT, unit_element
from hoh_cosim.fmi.slave import VariableSpec, block_interface
from hoh_cosim.fmi.slave3 import FMI3_TYPE, INPUT_STARTS, PARAMETERS, TIME
from hoh_cosim.kinds import KINDS, input_starts
from hoh_cosim.params import leaves

__all__ = [
    "build_fmu3",
    "build_kind3",
    "entry_script3",
    "finish_model_description3",
    "fmu3_module",
    "pythonfmu_package",
]

# fmiModelDescription's children, in the order the FMI 3.0 schema requires
_ORDER = (
    "ModelExchange",
    "CoSimulation",
    "ScheduledExecution",
    "UnitDefinitions",
    "TypeDefinitions",
    "LogCategories",
    "DefaultExperiment",
    "ModelVariables",
    "ModelStructure",
    "Annotations",
)


def fmu3_module(kind: str) -> str:
    """The module name of a kind's FMI 3 entry script: `hoh3_estimator`."""
    return f"hoh3_{kind}"


_SCRIPT = '''"""FMI 3.0 entry script of {model}: `{block}` through the generic adapter.

Written by hoh_cosim.fmi.build3. pythonfmu3 imports this module and instantiates the one class
below that derives from Fmi3Slave. An exception while it is imported would take the host process
down with it, so a failure here is kept and raised when the FMU is instantiated instead, where it
becomes the instantiation's fatal message.
"""

try:
    from hoh_cosim.fmi.host import require

    require(__file__, "{model}")  # what resources/requirements.txt asks of the host, if present
    from {block_module} import {block_name} as _Block
    from {params_module} import {params_name} as _Params
    from hoh_cosim.fmi.slave3 import BlockSlave3 as Fmi3Slave
except Exception as _exc:
    _PROBLEM = str(_exc) if str(_exc).startswith("{model}:") else (
        f"{model}: cannot import its code: {{type(_exc).__name__}}: {{_exc}}"
    )
    from pythonfmu3 import Fmi3Slave as _Fmi3Slave

    class Fmi3Slave(_Fmi3Slave):
        def __init__(self, **kwargs):
            raise ImportError(_PROBLEM)

    _Block = _Params = None


class {model}(Fmi3Slave):
    block = _Block
    params = _Params
'''


def entry_script3(model: str, block: type, params: type) -> str:
    """The FMI 3 entry script of the FMU `model` (its model identifier and class name) wrapping
    `block` with `params`, both importable by module and name."""
    if not model.isidentifier():
        raise ConfigError(f"FMU model identifier: expected a Python identifier, got {model!r}")
    for cls in (block, params):
        if "<" in cls.__qualname__ or "." in cls.__qualname__:
            raise ConfigError(
                f"{cls.__qualname__}: an FMU needs a class defined at the top of its module"
            )
    return _SCRIPT.format(
        model=model,
        block=f"{block.__module__}.{block.__qualname__}",
        block_module=block.__module__,
        block_name=block.__qualname__,
        params_module=params.__module__,
        params_name=params.__qualname__,
    )


def build_kind3(
    kind: str,
    out: Path,
    defaults: Any = None,
    *,
    description: str | None = None,
    project_files: Iterable[str | Path] = (),
    resources: Mapping[str, str | bytes] | None = None,
) -> None:
    """The FMI 3 FMU of the registered `kind` at `out` (its model identifier: the file's name,
    e.g. HohEstimator.fmu), as `hoh_cosim.fmi.build._build` builds its FMI 2 FMU: the kind's
    block, parameters, description (unless `description` replaces it) and input start values,
    its parameters starting at `defaults` (a preset's), else the block's."""
    spec = KINDS[kind]
    build_fmu3(
        kind,
        out,
        spec.block,
        spec.params,
        spec.description if description is None else description,
        input_starts(kind),
        defaults,
        project_files,
        resources,
    )


def build_fmu3(
    kind: str,
    out: Path,
    block: type,
    params: type,
    description: str,
    starts: Mapping[str, Any] | None = None,
    defaults: Any = None,
    project_files: Iterable[str | Path] = (),
    resources: Mapping[str, str | bytes] | None = None,
    *,
    model: str | None = None,
) -> None:
    """Build the FMI 3 FMU wrapping `block` with `params` (entry module `fmu3_module(kind)`,
    model identifier `model`, else the name of `out` without .fmu), its inputs starting at
    `starts` (port -> values), else 0, its parameters at `defaults`, else the block's defaults;
    `project_files`: folders (or files) copied into resources/, `resources`: more files written
    there (name -> content). The FMU is put at `out` atomically, mode 0644."""
    out = Path(out)
    model = model or out.stem
    module = fmu3_module(kind)
    script_text = entry_script3(model, block, params)
    project = [Path(p) for p in project_files]
    with tempfile.TemporaryDirectory(prefix="hoh-fmu3-") as tmp:
        script = Path(tmp) / "script" / f"{module}.py"
        script.parent.mkdir()
        script.write_text(script_text, encoding="utf-8")
        built = _pythonfmu3_build(script, Path(tmp) / "built", project, block.__name__)
        specs = block_interface(block, params, starts, defaults)
        finished = Path(tmp) / "finished.fmu"
        texts: dict[str, str | bytes] = {
            INPUT_STARTS: json.dumps(
                {
                    str(vr): s.start
                    for vr, s in enumerate(specs)
                    if s.causality == "input" and s.start
                },
                indent=1,
            )
        }
        if defaults is not None:
            texts[PARAMETERS] = json.dumps(_changed_parameters(params, defaults), indent=1)
        if project:
            texts.update(pythonfmu_package())
        texts.update(resources or {})
        with (
            zipfile.ZipFile(built) as src,
            zipfile.ZipFile(finished, "w", zipfile.ZIP_DEFLATED) as dst,
        ):
            written = {f"resources/{name}" for name in texts}
            for item in src.infolist():
                if item.filename in written:
                    continue  # ours replaces the builder's
                data = src.read(item)
                if item.filename == "modelDescription.xml":
                    data = finish_model_description3(
                        data,
                        specs,
                        description,
                        variable_step=variable_step(block),
                        initial_from_parameters=hasattr(block, "initial_outputs"),
                    )
                _write(dst, item, data)
            for name, content in texts.items():
                _write(dst, zipfile.ZipInfo(f"resources/{name}", (1980, 1, 1, 0, 0, 0)), content)
        _replace(finished, out)


def _pythonfmu3_build(script: Path, dest: Path, project: list[Path], name: str) -> Path:
    """pythonfmu3's FMU of `script`, its output kept for the error message only."""
    from pythonfmu3.builder import FmuBuilder

    for path in project:
        if not path.exists():
            raise ConfigError(f"{path}: a project file of the {name} FMU is missing")
    log = io.StringIO()
    try:
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            return Path(FmuBuilder.build_FMU(script, dest=dest, project_files=project))
    except Exception as exc:
        output = " ".join(log.getvalue().split())[-300:]
        raise RunError(
            f"building the FMI 3 {name} FMU failed: {type(exc).__name__}: {exc}"
            + (f" (pythonfmu3 said: {output})" if output else "")
        ) from None


def pythonfmu_package() -> dict[str, bytes]:
    """pythonfmu's Python files, as its own builder puts them into an FMI 2 FMU."""
    import pythonfmu

    root = Path(pythonfmu.__file__).parent
    return {f"pythonfmu/{path.name}": path.read_bytes() for path in sorted(root.glob("*.py"))}


def _write(dst: zipfile.ZipFile, item: zipfile.ZipInfo, data: str | bytes) -> None:
    """An entry deflated and readable by all (pythonfmu3 stores some with mode 0600)."""
    item.compress_type = zipfile.ZIP_DEFLATED
    item.external_attr = (0o100644 if not item.is_dir() else 0o40755) << 16
    dst.writestr(item, data)


def _replace(finished: Path, out: Path) -> None:
    """`finished` copied to `out` through a unique name beside it and one rename: a concurrent
    build or a reader never sees half a file."""
    fd, part = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent)
    os.close(fd)
    try:
        shutil.copyfile(finished, part)
        os.chmod(part, 0o644)  # mkstemp's file is 0600: the FMU is for every tool and user
        os.replace(part, out)
    except BaseException:
        Path(part).unlink(missing_ok=True)
        raise


def _changed_parameters(params_cls: type, defaults: Any) -> dict[str, Any]:
    """The leaves of `defaults` that differ from the class's defaults (`PARAMETERS`)."""
    before = {leaf.name: leaf.value for leaf in leaves(params_cls())}
    return {leaf.name: leaf.value for leaf in leaves(defaults) if before[leaf.name] != leaf.value}


def _set_start(var: ET.Element, spec: VariableSpec) -> None:
    """The build's start value, exact: 17 digits for a Float64 (pythonfmu3 writes 16)."""
    if spec.start is None or spec.causality == "output":
        return
    if spec.type == "String":
        start = var.find("Start")
        if start is not None:
            start.set("value", str(spec.start))
    elif spec.type == "Real":
        var.set("start", repr(float(spec.start)))
    elif spec.type == "Boolean":
        var.set("start", "true" if spec.start else "false")
    else:
        var.set("start", str(int(spec.start)))


def finish_model_description3(
    xml: bytes,
    specs: Sequence[VariableSpec],
    description: str,
    *,
    variable_step: bool = False,
    initial_from_parameters: bool = False,
) -> bytes:
    """The completed FMI 3 model description for an FMU whose variables are `specs` (value
    references 0 … n-1) and then `time` (the module's docstring)."""
    root = ET.fromstring(xml)
    root.set("description", description)
    variables = root.find("ModelVariables")
    if variables is None:
        raise ValueError("modelDescription.xml has no ModelVariables")
    by_name = {s.name: (vr, s) for vr, s in enumerate(specs)}
    units: list[str] = []
    outputs: list[int] = []
    parameters: list[int] = []
    for var in variables:
        name = var.get("name", "")
        if name == TIME:
            var.set("unit", "s")
            units.append("s")
            continue
        vr, spec = by_name[name]
        if var.tag != FMI3_TYPE[spec.type] or int(var.get("valueReference", -1)) != vr:
            raise ValueError(f"{name}: {var.tag} {var.get('valueReference')}, expected {vr}")
        var.set("description", spec.description)
        if spec.causality == "output":
            outputs.append(vr)
        elif spec.causality == "parameter":
            parameters.append(vr)
        if spec.type == "Real" and spec.unit is not None:
            var.set("unit", spec.unit)
            units.append(spec.unit)
        _set_start(var, spec)

    structure = ET.Element("ModelStructure")
    initial = " ".join(map(str, parameters)) if initial_from_parameters else ""
    for tag, dependencies in (("Output", ""), ("InitialUnknown", initial)):
        for vr in outputs:
            ET.SubElement(structure, tag, {"valueReference": str(vr), "dependencies": dependencies})
    cosimulation = root.find("CoSimulation")
    if cosimulation is None:
        raise ValueError("modelDescription.xml has no CoSimulation")
    cosimulation.set("canHandleVariableCommunicationStepSize", str(variable_step).lower())
    cosimulation.set("canGetAndSetFMUState", "true")
    cosimulation.set("canSerializeFMUState", "true")
    unit_definitions = ET.Element("UnitDefinitions")
    for name in sorted(set(units)):
        unit_definitions.append(unit_element(name))
    new = {
        "UnitDefinitions": unit_definitions,
        "DefaultExperiment": ET.Element("DefaultExperiment", DEFAULT_EXPERIMENT),
        "ModelStructure": structure,
    }
    present = {child.tag: child for child in root}
    for child in list(root):
        root.remove(child)
    present.update(new)
    for tag in _ORDER:
        if tag in present:
            root.append(present[tag])
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
