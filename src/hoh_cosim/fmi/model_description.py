"""Fix what pythonfmu leaves out of `modelDescription.xml`, so the FMU validates with no problem.

pythonfmu 0.7 writes the Outputs without dependencies, no InitialUnknowns, no units and no
DefaultExperiment. We add:
- UnitDefinitions for every unit used, with SI base units where the unit has an integer expansion,
  and the `unit` attribute on every Real variable that has one;
- the variables' descriptions;
- Real start values written to round-trip exactly (pythonfmu writes 16 significant digits, one short
  of a double's 17);
- ModelStructure: every output in Outputs with `dependencies=""` and in InitialUnknowns. Our
  outputs change only in fmi2DoStep, from the inputs held over the step (no direct feedthrough), so
  they depend on no input at the same instant, and importers may connect FMUs in loops without
  algebraic loops. At initialisation a block with `initial_outputs` computes them from its
  parameters (every parameter is listed: a moved joint moves the initial pose), the others start
  at zero whatever the parameters (`dependencies=""`);
- the capability flags: canHandleVariableCommunicationStepSize as the block says
  (`hoh_cosim.control.block`), canGetAndSetFMUstate and canSerializeFMUstate (`BlockSlave`);
- a DefaultExperiment (0 to 10 s in 1 ms steps: the loop's tick).
"""

from __future__ import annotations

from collections.abc import Sequence
from xml.etree import ElementTree as ET

from hoh_cosim.fmi.slave import VariableSpec
from hoh_cosim.fmi.units import base_units

__all__ = ["DEFAULT_EXPERIMENT", "finish_model_description", "unit_element"]

DEFAULT_EXPERIMENT = {"startTime": "0.0", "stopTime": "10.0", "stepSize": "0.001"}
# fmiModelDescription's children, in the order the FMI 2.0 schema requires
_ORDER = (
    "ModelExchange",
    "CoSimulation",
    "UnitDefinitions",
    "TypeDefinitions",
    "LogCategories",
    "DefaultExperiment",
    "VendorAnnotations",
    "ModelVariables",
    "ModelStructure",
)


def unit_element(name: str) -> ET.Element:
    """A Unit, with its SI base units where it has an integer expansion (`hoh_cosim.fmi.units`);
    the same element in FMI 2.0 and 3.0."""
    unit = ET.Element("Unit", {"name": name})
    expansion = base_units(name)
    if expansion is not None and (expansion[0] or expansion[1] != 1.0):
        exponents, factor = expansion
        attrib = {k: str(v) for k, v in exponents.items()}
        if factor != 1.0:
            attrib["factor"] = repr(factor)
        ET.SubElement(unit, "BaseUnit", attrib)
    return unit


def _boolean(value: object) -> str:
    return "true" if value else "false"


def finish_model_description(
    xml: bytes,
    specs: Sequence[VariableSpec],
    description: str,
    *,
    variable_step: bool = False,
    initial_from_parameters: bool = False,
) -> bytes:
    """The completed model description for an FMU whose variables are `specs` (the flags: the
    module's docstring)."""
    root = ET.fromstring(xml)
    root.set("description", description)
    by_name = {s.name: s for s in specs}
    variables = root.find("ModelVariables")
    if variables is None:
        raise ValueError("modelDescription.xml has no ModelVariables")
    units: list[str] = []
    outputs: list[int] = []
    parameters: list[int] = []
    for index, var in enumerate(variables.findall("ScalarVariable"), start=1):
        spec = by_name[var.get("name", "")]
        var.set("description", spec.description)
        if spec.causality == "output":
            outputs.append(index)
        elif spec.causality == "parameter":
            parameters.append(index)
        real = var.find("Real")
        if real is not None and spec.unit is not None:
            real.set("unit", spec.unit)
            if spec.unit not in units:
                units.append(spec.unit)
        if real is not None and real.get("start") is not None and spec.start is not None:
            real.set("start", repr(float(spec.start)))  # 17 digits: the exact default
        for tag, text in (("Integer", str), ("Boolean", _boolean), ("String", str)):
            other = var.find(tag)
            if other is not None and other.get("start") is not None and spec.start is not None:
                other.set("start", text(spec.start))  # the build's defaults (a preset's)

    for tag in ("UnitDefinitions", "DefaultExperiment", "ModelStructure"):
        for old in root.findall(tag):
            root.remove(old)
    unit_definitions = ET.Element("UnitDefinitions")
    for name in sorted(units):
        unit_definitions.append(unit_element(name))
    structure = ET.Element("ModelStructure")
    initial = " ".join(map(str, parameters)) if initial_from_parameters else ""
    for tag, dependencies in (("Outputs", ""), ("InitialUnknowns", initial)):
        node = ET.SubElement(structure, tag)
        for index in outputs:
            ET.SubElement(node, "Unknown", {"index": str(index), "dependencies": dependencies})
    cosimulation = root.find("CoSimulation")
    if cosimulation is not None:
        cosimulation.set("canHandleVariableCommunicationStepSize", str(variable_step).lower())
        cosimulation.set("canGetAndSetFMUstate", "true")
        cosimulation.set("canSerializeFMUstate", "true")
    new = {
        "ModelStructure": structure,
        "DefaultExperiment": ET.Element("DefaultExperiment", DEFAULT_EXPERIMENT),
    }
    if units:  # the schema wants at least one Unit in UnitDefinitions
        new["UnitDefinitions"] = unit_definitions
    children = list(root)
    for child in children:
        root.remove(child)
    present = {child.tag: child for child in children}
    present.update(new)
    for tag in _ORDER:
        if tag in present:
            root.append(present[tag])
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
