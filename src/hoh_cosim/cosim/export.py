"""`hoh-cosim export SCENARIO.yaml --out DIR`: the scenario's system, ready for another tool.

    DIR/fmus/Hoh*.fmu              the FMUs the scenario uses, each validated by fmpy
    DIR/<name>.ssp                 SSP 1.0: SystemStructure.ssd and resources/Hoh*.fmu
    DIR/OspSystemStructure.xml     the same system for libcosim's own format (FMUs from fmus/)
    DIR/README.md                  the components, their variables and units, and how to run them
    DIR/export.json                what was exported, with the FMUs' SHA-256

The SSP's system structure has one component per scenario component, a connector for every input and
output element, one connection per connected element and the scenario's parameter values (and the
values of unconnected inputs) as an inline parameter set named "scenario" on every component. Step
sizes ride on the annotations libcosim and ecos read (`com.opensimulationplatform`): the base step on
the DefaultExperiment, each component's `every · dt_s` as its StepSizeHint. fmpy's SSP reader checks
the archive against the SSP 1.0 schemas before anything is written.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sys
import sysconfig
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

from hoh_cosim import __version__
from hoh_cosim.cosim.external import (
    PARAMETER_SET,
    System,
    system_of,
    write_osp_system_structure,
    xml_value,
)
from hoh_cosim.cosim.scenario import Scenario, load_scenario
from hoh_cosim.errors import RunError

__all__ = ["ExportResult", "export_scenario", "ssd_xml"]

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations"
# libcosim and ecos match these prefixes literally, not the namespaces behind them
for _prefix, _uri in (("ssd", SSD), ("ssc", SSC), ("ssv", SSV), ("osp", OSP)):
    ET.register_namespace(_prefix, _uri)


def _q(namespace: str, tag: str) -> str:
    return f"{{{namespace}}}{tag}"


def _osp_annotation(parent: ET.Element) -> ET.Element:
    annotations = ET.SubElement(parent, _q(SSD, "Annotations"))
    return ET.SubElement(annotations, _q(SSC, "Annotation"), {"type": "com.opensimulationplatform"})


def ssd_xml(system: System, sources: dict[str, str]) -> bytes:
    """`SystemStructure.ssd` for `system`, the FMU of each component at `sources[component]`."""
    scenario = system.scenario
    root = ET.Element(
        _q(SSD, "SystemStructureDescription"),
        {"version": "1.0", "name": scenario.name, "description": scenario.description},
    )
    system_node = ET.SubElement(root, _q(SSD, "System"), {"name": scenario.name})
    elements = ET.SubElement(system_node, _q(SSD, "Elements"))
    for name, spec in scenario.components.items():
        component = ET.SubElement(
            elements,
            _q(SSD, "Component"),
            {
                "name": name,
                "source": sources[name],
                "type": "application/x-fmu-sharedlibrary",
                "implementation": "CoSimulation",
            },
        )
        connectors = ET.SubElement(component, _q(SSD, "Connectors"))
        for kind, ports in (("input", spec.inputs), ("output", spec.outputs)):
            for port in ports:
                for element in port.element_names:
                    connector = ET.SubElement(
                        connectors, _q(SSD, "Connector"), {"name": element, "kind": kind}
                    )
                    ET.SubElement(connector, _q(SSC, "Real"))
        bindings = ET.SubElement(component, _q(SSD, "ParameterBindings"))
        binding = ET.SubElement(bindings, _q(SSD, "ParameterBinding"))
        values = ET.SubElement(binding, _q(SSD, "ParameterValues"))
        parameter_set = ET.SubElement(
            values, _q(SSV, "ParameterSet"), {"version": "1.0", "name": PARAMETER_SET}
        )
        parameters = ET.SubElement(parameter_set, _q(SSV, "Parameters"))
        for var in system.start[name]:
            parameter = ET.SubElement(parameters, _q(SSV, "Parameter"), {"name": var.name})
            ET.SubElement(parameter, _q(SSV, var.type), {"value": xml_value(var.value)})
        hint = _osp_annotation(component)
        ET.SubElement(hint, _q(OSP, "StepSizeHint"), {"value": repr(system.step_size(name))})
    connections = ET.SubElement(system_node, _q(SSD, "Connections"))
    for src, src_var, dst, dst_var in system.links:
        ET.SubElement(
            connections,
            _q(SSD, "Connection"),
            {
                "startElement": src,
                "startConnector": src_var,
                "endElement": dst,
                "endConnector": dst_var,
            },
        )
    experiment = ET.SubElement(
        root,
        _q(SSD, "DefaultExperiment"),
        {"startTime": "0.0", "stopTime": repr(scenario.duration_s)},
    )
    algorithm = ET.SubElement(_osp_annotation(experiment), _q(OSP, "Algorithm"))
    ET.SubElement(algorithm, _q(OSP, "FixedStepAlgorithm"), {"baseStepSize": repr(scenario.dt_s)})
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _validate_fmu(path: Path) -> None:
    from fmpy.validation import validate_fmu

    problems = validate_fmu(str(path))
    if problems:
        raise RunError(f"{path}: fmpy finds the FMU invalid: {' '.join(str(problems[0]).split())}")


def _check_ssp(path: Path, system: System) -> None:
    """fmpy's SSP reader, schemas included, must read back every component and connection."""
    from fmpy.ssp.ssd import read_ssd

    try:
        ssd = read_ssd(str(path), validate=True)
    except Exception as exc:
        raise RunError(f"{path}: fmpy's SSP reader rejects it: {exc}") from None
    names = [e.name for e in ssd.system.elements]
    if names != list(system.scenario.components):
        raise RunError(
            f"{path}: fmpy reads back the components {names}, expected "
            f"{list(system.scenario.components)}"
        )
    if len(ssd.system.connections) != len(system.links):
        raise RunError(
            f"{path}: fmpy reads back {len(ssd.system.connections)} connections, expected "
            f"{len(system.links)}"
        )


def _oldest_python(fmu_files: Sequence[Path]) -> str:
    """The newest of the FMUs' oldest Pythons (their requirements' first lines)."""
    oldest = (3, 10)
    for path in fmu_files:
        with zipfile.ZipFile(path) as archive:
            if "resources/requirements.txt" not in archive.namelist():  # not one of ours
                continue
            first = archive.read("resources/requirements.txt").decode().splitlines()[0]
        major, minor = first.rsplit(" ", 1)[-1].split(".")
        oldest = max(oldest, (int(major), int(minor)))
    return f"{oldest[0]}.{oldest[1]}"


def _libpython() -> str:
    name = sysconfig.get_config_var("INSTSONAME") or sysconfig.get_config_var("LDLIBRARY")
    return str(Path(sysconfig.get_config_var("LIBDIR") or "") / (name or "libpython3.so"))


def _readme(
    scenario: Scenario,
    system: System,
    ssp_name: str,
    fmus: dict[str, str],
    command: str,
    fmu_files: Sequence[Path],
    fmi: int = 2,
) -> str:
    from hoh_cosim.fmi.docs import kind_variables
    from hoh_cosim.fmi.hostcheck import declared_requirements

    requirements = declared_requirements(fmu_files, strict=False)
    oldest = _oldest_python(fmu_files)

    components = scenario.components
    dt = scenario.dt_s
    python = f"{sys.version_info.major}.{sys.version_info.minor}"
    needs = ", ".join(requirements)
    lines = [
        f"# {scenario.name}: the co-simulation system, exported",
        "",
        f"**What a host needs**: Linux x86_64 with a GCC 12-era C++ runtime (Debian 12, Ubuntu "
        f"22.04 or newer) and a Python {oldest} or newer with {needs} installed: nothing of "
        "hoh-cosim, whose code each FMU carries in its `resources/` (each FMU's own list is its "
        "`resources/requirements.txt`). A host that lacks one fails to instantiate the FMU with "
        "one line naming it and the `pip install` that fixes it.",
        "",
        "**Check a host** (from this directory, in the host's Python, with fmpy installed):",
        "",
        "```sh",
        'for f in fmus/*.fmu; do fmpy simulate "$f" --stop-time 1 > /dev/null '
        '&& echo "ok $f" || echo "FAILED $f"; done',
        "```",
        "",
        "Where hoh-cosim is installed, `hoh-cosim export SCENARIO --out DIR --check` does it for "
        "you in a clean virtual environment with only these and fmpy, and compares each FMU's run "
        "with the same run in hoh-cosim's own environment.",
        "",
        f"Exported by hoh-cosim {__version__} with `{command}`. {scenario.description}",
        "",
        *(
            [
                f"The estimator's and the controller's parameters start at the preset "
                f"`{scenario.preset.label}` ({scenario.preset.description}): an FMU loaded alone "
                "runs with them, and the parameter set holds every value the scenario gives.",
                "",
            ]
            if scenario.preset is not None
            else []
        ),
        "| file | what |",
        "|---|---|",
        f"| `{ssp_name}` | SSP 1.0 archive: `SystemStructure.ssd` (components, connections, "
        f"parameter values as the inline parameter set `{PARAMETER_SET}`, step sizes as OSP "
        "annotations) and the FMUs in `resources/` |",
        "| `OspSystemStructure.xml` | the same system in libcosim's own format, FMUs from `fmus/` |",
        f"| `fmus/` | the FMI {fmi}.0 co-simulation FMUs, each checked with `fmpy validate` |",
        "| `export.json` | what was exported, and each FMU's SHA-256 |",
        "",
        "## The system",
        "",
        f"The base step is {dt:g} s and the run lasts {scenario.duration_s:g} s. Every component "
        "steps every `step` seconds; a step from t to t + h computes the outputs at t + h from the "
        "inputs held during it (no direct feedthrough), so any coupling order is free of "
        "algebraic loops.",
        "",
        "| component | FMU | step [s] | values set | connected inputs |",
        "|---|---|---:|---:|---:|",
    ]
    for name in components:
        inputs = sum(1 for link in system.links if link[2] == name)
        lines.append(
            f"| `{name}` | `{fmus[name]}` | {system.step_size(name):g} "
            f"| {len(system.start[name])} | {inputs} |"
        )
    lines += [
        "",
        f"{len(system.links)} connections link single Real variables (`port[i]`). hoh-cosim's own "
        "master steps the components in the order above, each seeing the outputs of those before "
        "it from the same tick (Gauss-Seidel); libcosim and ecos step them side by side and pass "
        "every output on after the step (Jacobi), which delays each connection by one step. The "
        "numbers then differ from hoh-cosim's by that delay alone; `hoh-cosim` reproduces either "
        "coupling exactly (`docs/decisions/0023-external-engines-coupling.md` of the project).",
        "",
        "## What a host needs",
        "",
        f"The FMUs run Python: they were built on Linux x86_64 with Python {python} and run in "
        f"Python {oldest} or newer. The host needs:",
        "",
        "- Linux x86_64 with a GCC 12-era C++ runtime (Debian 12, Ubuntu 22.04 or newer);",
        f"- a Python environment with {needs} "
        f"(`python3 -m venv venv && venv/bin/pip install {' '.join(repr(r) for r in requirements)}`); "
        "numba and pinocchio are used when present (compiled kernels, the reference "
        "kinematics), never needed;",
        "- inside that Python the importer (fmpy, libcosimpy, ecospy) and nothing else;",
        "- in a host that is not Python (a C or C++ tool on Linux): the Python library loaded "
        "before the FMUs (`LD_PRELOAD`), or they fail to load (`undefined symbol: "
        "_Py_NoneStruct`), and the environment active (its `bin/` first on `PATH`): the Python "
        "the FMUs start inside the host finds its packages through the `python3` on the `PATH`; "
        "without it ecos's program dies of a segmentation fault.",
        "",
        "## Commands",
        "",
        "Run from this directory, with the environment above active (`. venv/bin/activate`).",
        "",
        "libcosim (`pip install libcosimpy`), from the SSP archive or from "
        "`OspSystemStructure.xml`:",
        "",
        "```sh",
        "python -c 'from libcosimpy.CosimExecution import CosimExecution as E; "
        f'e = E.from_ssp_file("{ssp_name}"); print(e.simulate_until({round(1e9)}))\'',
        "python -c 'from libcosimpy.CosimExecution import CosimExecution as E; "
        f'e = E.from_osp_config_file("."); print(e.simulate_until({round(1e9)}))\'',
        "```",
        "",
        "ecos (`pip install ecospy tbb`; ecospy loads `libtbb.so.12`, which the `tbb` package puts "
        "in the environment's `lib/`, so that directory goes on the loader's path). ecos takes "
        f"the base step from the caller and applies the parameter set only when it is named: "
        f"`{PARAMETER_SET}`.",
        "",
        "```sh",
        'export LD_LIBRARY_PATH="$VIRTUAL_ENV/lib"',
        "python -c 'from ecospy import EcosSimulation as S; "
        f's = S(ssp_path="{ssp_name}", step_size={dt!r}); s.init(parameter_set="{PARAMETER_SET}"); '
        "s.step_until(1.0); print(s.get_time())'",
        "```",
        "",
        "A host that is not Python, here the `ecos` command-line program that ships inside ecospy: "
        "with the environment active, preload the Python library.",
        "",
        "```sh",
        "LIBPYTHON=$(python -c 'import sysconfig, pathlib; "
        'print(pathlib.Path(sysconfig.get_config_var("LIBDIR"), '
        'sysconfig.get_config_var("INSTSONAME")))\')',
        "ECOS=$(python -c 'import ecospy, pathlib; "
        'print(pathlib.Path(ecospy.__file__).parent / "binaries" / "ecos")\')',
        'install -m 755 "$ECOS" ./ecos  # the wheel leaves the program without its execute bit',
        'LD_PRELOAD="$LIBPYTHON" LD_LIBRARY_PATH="$VIRTUAL_ENV/lib" \\',
        f"    ./ecos simulate --path {ssp_name} --stepSize {dt!r} --stopTime 1 "
        f"--parameterSet {PARAMETER_SET} --noCsv",
        "```",
        "",
        "The simulation runs to its end; the program may then die of a segmentation fault as it "
        "unloads the FMUs (pythonfmu 0.7 releases its interpreter state twice), so read its "
        "results rather than its exit status. "
        f"(On the machine that exported this, the Python library is `{_libpython()}`.) Check the FMUs "
        "with `fmpy validate fmus/<FMU>.fmu` and read the archive with "
        f"`python -c 'from fmpy.ssp.ssd import read_ssd; print(read_ssd(\"{ssp_name}\"))'`.",
        "",
        "## The FMUs' variables",
        "",
        "Vector ports are one Real variable per element, `port[1]` … `port[n]`, in SI units; "
        "parameters are named by their path in the parameter tree. The values this scenario sets "
        "are in the SSP's parameter set and in `OspSystemStructure.xml`; the others keep the "
        "defaults below.",
        "",
    ]
    seen: set[str] = set()
    for spec in components.values():
        if fmus[spec.name] in seen:
            continue
        seen.add(fmus[spec.name])
        users = [c for c in components if fmus[c] == fmus[spec.name]]
        lines.append(f"### {fmus[spec.name]} ({', '.join(f'`{u}`' for u in users)})\n")
        lines += kind_variables(spec.kind)
    return "\n".join(lines).rstrip() + "\n"


@dataclass
class ExportResult:
    out: Path
    ssp: Path
    fmus: dict[str, Path]  # component -> its FMU in the export
    scenario: Scenario


def export_scenario(
    path: str | Path,
    out: str | Path,
    *,
    overrides: Sequence[str] = (),
    duration_s: float | None = None,
    seed: int | None = None,
    command: str | None = None,
    preset: str | None = None,
    fmi: int = 2,
) -> ExportResult:
    """Write the scenario's FMUs, SSP archive, OSP system structure and README into `out`; the
    estimator's and the controller's FMUs start from the scenario's preset (`preset`: another);
    `fmi` 3: FMI 3.0 FMUs (else 2.0)."""
    from hoh_cosim.fmi.build import ensure_fmus
    from hoh_cosim.results import check_out_dir, replace_dir

    scenario = load_scenario(path, overrides, duration_s, seed, preset)
    out = Path(out)
    check_out_dir(out, marker="export.json", what="export")
    kinds = sorted({c.kind.name for c in scenario.components.values() if c.fmu is None})
    defaults = {} if scenario.preset is None else dict(scenario.preset.params)
    system = system_of(scenario, ensure_fmus(kinds, defaults=defaults, fmi=fmi))
    for fmu in sorted(set(system.fmus.values())):
        _validate_fmu(fmu)
    file_of = {name: fmu.name for name, fmu in system.fmus.items()}
    by_name: dict[str, Path] = {}
    for fmu in sorted(set(system.fmus.values())):
        if fmu.name in by_name:
            raise RunError(
                f"{scenario.path}: two FMUs have the file name {fmu.name} ({by_name[fmu.name]} "
                f"and {fmu}); the export keeps one folder of FMUs"
            )
        by_name[fmu.name] = fmu
    ssp_name = f"{scenario.name}.ssp"
    command = command or f"hoh-cosim export {path} --out {out}"

    def fill(staging: Path) -> None:
        (staging / "fmus").mkdir()
        for fmu in sorted(set(system.fmus.values())):
            shutil.copyfile(fmu, staging / "fmus" / fmu.name)
        ssd = ssd_xml(system, {c: f"resources/{f}" for c, f in file_of.items()})
        ssp = staging / ssp_name
        with zipfile.ZipFile(ssp, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("SystemStructure.ssd", ssd)
            for name in sorted(set(file_of.values())):
                archive.write(staging / "fmus" / name, f"resources/{name}")
        _check_ssp(ssp, system)
        write_osp_system_structure(
            system, staging, sources={c: f"fmus/{f}" for c, f in file_of.items()}
        )
        (staging / "README.md").write_text(
            _readme(scenario, system, ssp_name, file_of, command, sorted(by_name.values()), fmi),
            encoding="utf-8",
        )
        manifest = {
            "scenario": scenario.name,
            "file": str(scenario.path),
            "seed": scenario.seed,
            "dt_s": scenario.dt_s,
            "duration_s": scenario.duration_s,
            "overrides": list(overrides),
            "preset": None if scenario.preset is None else scenario.preset.label,
            "ssp": ssp_name,
            "parameter_set": PARAMETER_SET,
            "components": {
                c: {
                    "fmu": f"fmus/{file_of[c]}",
                    "step_s": system.step_size(c),
                    "sha256": _sha256(staging / "fmus" / file_of[c]),
                }
                for c in scenario.components
            },
            "hoh_cosim_version": __version__,
            "python": sys.version.split()[0],
        }
        (staging / "export.json").write_text(json.dumps(manifest, indent=2) + "\n")

    replace_dir(out, fill, what="export")
    return ExportResult(
        out,
        out / ssp_name,
        {c: out / "fmus" / f for c, f in file_of.items()},
        scenario,
    )
